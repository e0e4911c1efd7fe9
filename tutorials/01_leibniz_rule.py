# ---
# jupyter:
#   jupytext:
#     cell_metadata_filter: -all
#     formats: ipynb,py:percent
#     notebook_metadata_filter: kernelspec,jupytext,-jupytext.text_representation.jupytext_version
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
#   kernelspec:
#     display_name: Python 3 (ipykernel)
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 1. The Leibniz rule: moving limits and moving discontinuities
#
# **What you will learn.**
#
# - why the derivative of an integral has a term for every jump that moves with θ (the Leibniz
#   rule), checked on every textbook integral
# - forward-mode dual numbers (`Dual`, `variable`, `tangent`, `detach`): how the library computes
#   derivatives, used by every later notebook
# - why a Monte Carlo estimator differentiated sample by sample sees no jump
#
# A rendered pixel is an integral $I(\theta) = \int_X f(x, \theta)\, dx$, and inverse rendering
# needs its derivative with respect to a scene parameter $\theta$. The integral depends on $\theta$
# in three ways: through the values of $f$, through the limits of integration, and through the
# places where $f$ jumps (a silhouette, a shadow edge). The Leibniz rule (`docs/theory/leibniz.md`) adds one
# term for each:
#
# $$
# \frac{d}{d\theta}\int_{a(\theta)}^{b(\theta)} f(x,\theta)\,dx
# = \underbrace{\int_a^b \frac{\partial f}{\partial\theta}\,dx}_{\text{interior}}
# + \underbrace{f(b,\theta)\,b'(\theta) - f(a,\theta)\,a'(\theta)}_{\text{moving limits}}
# + \underbrace{\sum_i \bigl[f(c_i^-,\theta) - f(c_i^+,\theta)\bigr]\,c_i'(\theta)}_{
#     \text{moving discontinuities}} .
# $$
#
# This notebook derives the rule, works the seed example by hand and by code, and checks the
# decomposition on every textbook integral of the library against its closed-form derivative.
#
# The first cell imports what we need and fixes the seed of every random number used below.

# %%
# %matplotlib inline
import itertools

import numpy as np
from scipy import integrate

from flatland import INTEGRALS, detach, estimate, get_integral, tangent, variable
from flatland.integrals import Circle
from flatland.plotting import textbook as pt

SEED = 20191117

# %% [markdown]
# ## Derivatives by dual numbers
#
# Every derivative in this course is computed by *forward-mode automatic differentiation*. A
# `Dual` is an array carrying two numbers per entry: a value and a *tangent*, the derivative of
# that value with respect to the one scalar parameter $\theta$. Arithmetic on Duals applies the
# chain rule entry by entry, so code written like plain numpy computes a function and its
# derivative at once: $(u v)' = u' v + u v'$, $\sin(u)' = \cos(u)\, u'$, and so on.
#
# - `variable(theta0)` is $\theta$ itself at $\theta_0$: value $\theta_0$, tangent 1.
# - `tangent(y)` reads $dy/d\theta$; `detach(y)` the value alone, as a plain number or array
#   (its derivative dropped).
# - `y - detach(y)` has value 0 and tangent $dy/d\theta$: a quantity that is zero *now* but
#   moves like $y$. Tutorial 6 builds its translations from exactly this.
# - Comparisons act on values and return plain booleans, so an indicator such as
#   $1_{x > \theta}$ has derivative 0 wherever it is evaluated: the jump's motion is invisible to
#   it. That is the term the Leibniz rule below adds back, and the term naive differentiation
#   misses (tutorial 4).

# %%
theta_dual = variable(0.5)
y = np.sin(theta_dual) * theta_dual**2
grid01 = np.linspace(0.0, 1.0, 5)
decay = np.exp(-grid01 * theta_dual)  # an array: one value and one tangent per entry
indicator = np.where(grid01 > theta_dual, 1.0, 0.0)  # compared on values: a plain array
moving_zero = theta_dual - detach(theta_dual)
print(f"y = sin(θ) θ² at θ = 0.5: value {detach(y):.6f}, dy/dθ {tangent(y):.6f}")
print("d/dθ exp(-x θ) on the grid:", np.round(tangent(decay), 6))
print("indicator 1[x > θ]:", indicator, "(a plain array, no tangent)")
print(f"θ - detach(θ): value {detach(moving_zero)}, derivative {tangent(moving_zero)}")

# %%
# check: the tangents are the hand-derived derivatives (rounding tolerance 1e-12): (sin θ θ²)' =
# cos θ θ² + 2 θ sin θ, (e^(-xθ))' = -x e^(-xθ); the indicator carries no tangent; θ - detach(θ) is 0
# moving at speed 1
assert abs(tangent(y) - (np.cos(0.5) * 0.25 + 2 * 0.5 * np.sin(0.5))) < 1e-12
assert np.allclose(tangent(decay), -grid01 * np.exp(-grid01 * 0.5), rtol=0, atol=1e-12)
assert isinstance(indicator, np.ndarray) and indicator.tolist() == [0.0, 0.0, 0.0, 1.0, 1.0]
assert detach(moving_zero) == 0.0 and tangent(moving_zero) == 1.0

# %% [markdown]
# ## Where the terms come from
#
# **Moving limits.** If $f$ does not depend on $\theta$ and $F' = f$, then
# $\int_{a(\theta)}^{b(\theta)} f\,dx = F(b(\theta)) - F(a(\theta))$, and the chain rule gives
# $f(b)\,b' - f(a)\,a'$. When $f$ depends on $\theta$ as well, its own change adds the interior
# term $\int \partial_\theta f\,dx$.
#
# **Moving discontinuities.** If $f$ jumps at $c(\theta)$ inside $[a, b]$, split the integral
# there: $\int_a^{c} f\,dx + \int_{c}^{b} f\,dx$. The point $c$ is the *upper* limit of the
# first piece, which contributes $f(c^-)\,c'$, and the *lower* limit of the second, which
# contributes $-f(c^+)\,c'$. Together: $[f(c^-) - f(c^+)]\,c'$. Where $f$ is continuous the two
# cancel, which is why only jumps appear in the sum.
#
# **Limits are jumps.** On the whole line, $\int_a^b f\,dx = \int 1_{a < x < b}\, f\,dx$. The
# indicator makes $f$ jump from $f(b)$ to $0$ at $b$ (jump $+f(b)$, velocity $b'$) and from $0$ to
# $f(a)$ at $a$ (jump $-f(a)$, velocity $a'$): the moving-limit terms are discontinuity terms. The
# library writes every textbook integrand on its whole domain this way, and each
# `Integrand.discontinuities(theta)` lists its jumps: the location $c(\theta)$ as a `Dual` whose
# tangent is $c'(\theta)$, and the jump $f(c^-) - f(c^+)$.
#
# ## The seed example
#
# $f(x, \theta) = 0$ for $x < 2\theta$ and $1$ for $x > 2\theta$, integrated over $[0, 4\theta]$, so
# $I(\theta) = 4\theta - 2\theta = 2\theta$ and $dI/d\theta = 2$. By the rule: the interior term is
# $0$ ($f$ is locally constant), the moving upper limit gives $f(4\theta)\cdot 4 = 4$, the lower
# limit $0$ does not move, and the step at $2\theta$ gives $(0 - 1)\cdot 2 = -2$. Total: $2$.
#
# The library's `leibniz_seed` is $1_{2\theta < x < 4\theta}$ on the whole line (the lower limit
# $0$ lies outside the support for $\theta > 0$). We list its jumps at $\theta_0 = 1$.

# %%
seed_integral = get_integral("leibniz_seed")
theta0 = 1.0
jumps = seed_integral.discontinuities(variable(theta0))
terms = [(float(detach(d.location)), d.jump, float(tangent(d.location))) for d in jumps]
for location, jump, velocity in terms:
    print(f"c = {location:4.1f}   f(c-) - f(c+) = {jump:+.1f}   c'(theta) = {velocity:.1f}")
discontinuity_term = sum(jump * velocity for _, jump, velocity in terms)
print("discontinuity term:", discontinuity_term, "  closed form dI/dtheta:", seed_integral.derivative(theta0))

# %%
# check: the listed jumps are the hand-derived ones, and with a zero interior term they add up to dI/dθ = 2
assert terms == [(2.0, -1.0, 2.0), (4.0, 1.0, 4.0)]
assert discontinuity_term == seed_integral.derivative(theta0) == 2.0

# %% [markdown]
# The picture: at a slightly larger $\theta$ the step at $2\theta$ moves right at speed 2 (the
# integral loses mass there) and the end at $4\theta$ moves right at speed 4 (it gains mass
# there). The dotted lines mark each jump with its size and velocity.

# %%
x = np.linspace(-0.5, 6.0, 2001)
fig = pt.plot_integrand(
    x,
    detach(seed_integral.f(x, theta0)),
    seed_integral.discontinuities(variable(theta0)),
    label="θ = 1",
    title="seed example: f = 1 on (2θ, 4θ)",
)
pt.plot_integrand(
    x,
    detach(seed_integral.f(x, 1.25)),
    seed_integral.discontinuities(variable(1.25)),
    label="θ = 1.25",
    annotate=False,
    ax=fig.axes[0],
)

# %% [markdown]
# Trusting a formula is not checking it. Quadrature gives $I(\theta)$ independently of the rule:
# integrate $f$ piecewise between its jumps (an adaptive rule is accurate on each smooth piece,
# not across a jump). The central difference $[I(\theta+h) - I(\theta-h)]/2h$ of the quadrature
# must then agree with the rule's $2$.


# %%
def quadrature(g, integrand, theta):
    """∫ g(x) dx over the integrand's domain, split at the integrand's jumps at theta."""
    cuts = sorted(float(detach(d.location)) for d in integrand.discontinuities(variable(theta)))
    if integrand.domain is Circle:  # one period starting at the first jump, jumps wrapped into it
        start = cuts[0] if cuts else -np.pi
        inner = sorted(start + np.remainder(c - start, 2 * np.pi) for c in cuts[1:])
        edges = [start, *inner, start + 2 * np.pi]
    else:  # the Gaussian factor K(x) of the line integrands is below 1e-30 beyond |x| = 12
        edges = [-12.0, *cuts, 12.0]
    pieces = [
        integrate.quad(lambda s: float(g(np.array([s]))[0]), a, b, epsabs=1e-13, epsrel=1e-12, limit=200)[0]
        for a, b in itertools.pairwise(edges)
        if b > a
    ]
    return float(np.sum(pieces))


h = 1e-3
value_plus = quadrature(lambda s: detach(seed_integral.f(s, theta0 + h)), seed_integral, theta0 + h)
value_minus = quadrature(lambda s: detach(seed_integral.f(s, theta0 - h)), seed_integral, theta0 - h)
central_difference = (value_plus - value_minus) / (2 * h)
print(f"I(θ0 ± h) = {value_plus:.9f}, {value_minus:.9f};  central difference = {central_difference:.9f}")

# %%
# check: quadrature reproduces I = 2θ at θ0 ± h, and its central difference the rule's 2 (I is linear, so
# the difference has no truncation error; 1e-9 covers the quadrature's rounding)
assert abs(value_plus - 2 * (theta0 + h)) < 1e-9 and abs(value_minus - 2 * (theta0 - h)) < 1e-9
assert abs(central_difference - 2.0) < 1e-6

# %% [markdown]
# ## Every textbook integral
#
# The library's six textbook integrals cover the cases: a smooth integrand with no jump
# (`smooth`, interior term only), the paper's step $1_{x>\theta} K(x)$ (`step`), jumps moving at
# different speeds (`leibniz_seed`, `two_steps`) and arcs on the circle (`arc`,
# `arc_stretch`). For each we compute the interior term by quadrature of $\partial f/\partial\theta$
# (the tangent of $f$ evaluated at the `Dual` $\theta$) and the discontinuity term from the list
# of jumps, and compare their sum with the closed-form $dI/d\theta$.

# %%
rows = {}
for name, integrand in INTEGRALS.items():
    th = integrand.default_theta
    interior = quadrature(lambda s, ig=integrand, t=th: tangent(ig.f(s, variable(t))), integrand, th)
    rows[name] = (interior, integrand.discontinuity_term(th), integrand.derivative(th))
print(f"{'integral':>13} {'interior':>10} {'jumps':>10} {'sum':>10} {'closed form':>12}")
for name, (interior, jump_term, closed) in rows.items():
    print(f"{name:>13} {interior:10.6f} {jump_term:10.6f} {interior + jump_term:10.6f} {closed:12.6f}")

# %%
# check: interior + discontinuity term = closed-form dI/dθ for every integral (quadrature tolerance 1e-8)
for name, (interior, jump_term, closed) in rows.items():
    assert abs(interior + jump_term - closed) < 1e-8, name
assert abs(rows["smooth"][1]) == 0.0 and abs(rows["step"][0]) < 1e-12  # one term only in each

# %% [markdown]
# Drawn as bars, the terms per integral and the closed-form derivative they add up to. Only
# `smooth` has an interior term; every other integrand is piecewise constant in $\theta$ at
# fixed $x$, so its whole derivative lives at its jumps.

# %%
pt.plot_terms(
    list(rows),
    {
        "interior ∫ ∂f/∂θ dx": [r[0] for r in rows.values()],
        "discontinuities Σ [f(c⁻) − f(c⁺)] c'": [r[1] for r in rows.values()],
    },
    totals=[r[2] for r in rows.values()],
    title="Leibniz terms at each integral's default θ",
)

# %% [markdown]
# ## What a Monte Carlo estimator sees
#
# A Monte Carlo estimate of $I$ evaluates $f$ at random points $x_i$. Differentiating it sample
# by sample recovers only the interior term: almost surely no sample sits on a jump, and at
# every other point the jump term is invisible. The library's `naive` estimator does exactly
# that; its `boundary` estimator adds the discontinuity term computed from the list of jumps, as
# above. On the seed example the first returns $0$ and the second $2$, both with zero variance:
# every sample's derivative is $0$. Tutorial 4 takes this failure apart.

# %%
naive = estimate("leibniz_seed", theta0, method="naive", n=10_000, seed=SEED)
boundary = estimate("leibniz_seed", theta0, method="boundary", n=10_000, seed=SEED)
print(f"naive:    {naive.derivative} ± {naive.derivative_stderr}")
print(f"boundary: {boundary.derivative} ± {boundary.derivative_stderr}")

# %%
# check: naive AD returns the interior term 0 and boundary the full derivative 2, both exactly (no variance)
assert naive.derivative == 0.0 and naive.derivative_stderr == 0.0
assert boundary.derivative == 2.0 and boundary.derivative_stderr == 0.0
