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
# # 3. Samples that depend on θ
#
# **What you will learn.**
#
# - what changes when the samples themselves depend on θ (a sampler that follows the parameter)
# - where the jump of the estimator then sits in the random numbers u, and which samplers follow it
# - how to differentiate through the density p
#
# Tutorial 2 differentiated an estimator whose samples $x_i \sim p$ did not depend on $\theta$. Renderers
# often sample in a way that does: a light sampled by its current position, a direction sampled by
# the current roughness. The samples are then made from $\theta$-independent random numbers $u_i$ by a
# map $x_i(\theta) = T(u_i, \theta)$, and their density $p(x, \theta)$ depends on $\theta$ too (Loubet et al.
# 2019, Sec. 3.1). The per-sample estimate is
#
# $$
# h(u, \theta) = \frac{f\bigl(T(u, \theta), \theta\bigr)}{p\bigl(T(u, \theta), \theta\bigr)}
#   = f\bigl(T(u, \theta), \theta\bigr)\, \partial_u T(u, \theta),
# $$
#
# since for $u$ uniform on $[0, 1]$ and $T$ increasing in $u$ the density of $x$ is $1/\partial_u T$.
# So $I(\theta) = \int_0^1 h(u, \theta)\,du$ for *every* such sampler: a change of variables, and the
# estimator is an ordinary Monte Carlo estimator in $u$, whose random numbers do not depend on $\theta$.
# This notebook teaches three consequences:
#
# 1. differentiating the estimator sample by sample differentiates $h$ in $\theta$ at fixed $u$, which
#    is unbiased exactly when $h(\cdot, \theta)$ has no discontinuity that moves with $\theta$. A jump of
#    $f$ at $c(\theta)$ sits, in $u$, at $u_c(\theta) = T^{-1}(c(\theta), \theta)$; by the Leibniz rule
#    (tutorial 1) in $u$, the term sample-by-sample differentiation misses is
#
#    $$
#    \bigl[f(c^-) - f(c^+)\bigr]\,\bigl(c'(\theta) - \partial_\theta T(u_c, \theta)\bigr),
#    $$
#
#    the jump times the speed of the discontinuity *relative to the samples*;
# 2. a sampler that moves its samples with the discontinuity ($\partial_\theta T = c'$ at $u_c$) makes
#    the naive derivative correct: this is reparameterization (Sec. 3.2, tutorial 6), while a fixed
#    sampler (tutorial 4) or one moving the samples at another speed leaves a boundary term out;
# 3. the density must be differentiated too: $1/p(x(\theta), \theta) = \partial_u T$ changes with $\theta$
#    when the sampler stretches, and detaching $p$ drops that *sample-weight* term.
#
# The integrand is the paper's step $f(x, \theta) = 1_{x > \theta} K(x)$, $K$ the standard normal
# density, with $I = 1 - \Phi(\theta)$, $dI/d\theta = -K(\theta)$, one jump at $c(\theta) = \theta$ of size
# $f(c^-) - f(c^+) = -K(\theta)$. The first cell imports the library and fixes the seed.

# %%
# %matplotlib inline
import numpy as np
from scipy import special, stats

from flatland import detach, estimate, get_integral, tangent, variable
from flatland.core.dual import Dual
from flatland.core.rng import stream
from flatland.core.stats import normal_quantile, sidak, summarize
from flatland.plotting import textbook as pt
from flatland.plotting import tutorials as ptu
from flatland.sampling import TWO_PI, log_pdf_gaussian

SEED = 20191117
step = get_integral("step")
theta0 = 0.5
s = step.proposal_std  # the library's proposal for `step` is N(0, 1.5²)
K = stats.norm.pdf  # the standard normal density, on plain arrays
jump = step.discontinuities(variable(theta0))[0]  # location c(θ) as a Dual (tangent c' = 1), jump -K(θ)

# %% [markdown]
# ## Three samplers, as functions of u and θ
#
# Each sampler maps uniforms $u$ and a parameter $\theta$ (a float or a forward-mode `Dual`) to samples
# $x$ and their density $p(x, \theta)$, both computed with $\theta$ so that their derivatives follow:
#
# - **translated at speed $v$**: $T(u, \theta) = s\,\Phi^{-1}(u) + v\,(\theta - \theta_0)$, the
#   library's
#   proposal $\mathcal N(0, s^2)$ shifted by $v(\theta - \theta_0)$, with density $\mathcal N(x; v(\theta -
#   \theta_0), s^2)$. $v = 0$ is the fixed sampler of tutorials 2 and 4; $v = 1$ moves the samples with
#   the jump;
# - **truncated at θ**: the ideal proposal of tutorial 2, $p(x, \theta) = K(x)/(1 - \Phi(\theta))$
#   on
#   $x > \theta$, sampled by $T(u, \theta) = \Phi^{-1}\bigl(\Phi(\theta) + u\,(1 - \Phi(\theta))\bigr)$. Its
#   breakpoint $u = 0$ is mapped to $c(\theta) = \theta$ for every $\theta$.
#
# scipy's $\Phi$ and $\Phi^{-1}$ have no `Dual` rule, so two helpers apply the chain rule by hand:
# $\Phi(z)' = K(z)\,z'$ and $(\Phi^{-1}(q))' = q'/K(\Phi^{-1}(q))$.
#
# As functions of $u$, the per-sample estimates $h(u, \theta)$ of the translated samplers jump where
# $T(u, \theta) = \theta$, at $u_c(\theta) = \Phi\bigl((\theta - v(\theta - \theta_0))/s\bigr)$, which
# stays put when $v = 1$. We evaluate $h$ at the midpoints of $10^5$ cells of $[0, 1]$, at $\theta_0$ and
# $\theta_1 = 0.8$, and find where it jumps. Then, with $N = 2 \cdot 10^5$ uniforms, we check that every
# sampler estimates $I(\theta_1)$ without bias: all are importance samplers of the same integral.


# %%
def normal_density(x):
    """K(x) for a Dual or an array."""
    return np.exp(-0.5 * x * x) / np.sqrt(TWO_PI)


def cdf(z):
    """Φ(z) with its tangent K(z) z' (z a float or a Dual)."""
    return Dual(special.ndtr(detach(z)), K(detach(z)) * tangent(z))


def cdf_inverse(q):
    """Φ⁻¹(q) with its tangent q' / K(Φ⁻¹(q))."""
    x = special.ndtri(detach(q))
    return Dual(x, tangent(q) / K(x))


def translated(v):
    """The sampler T(u, θ) = s Φ⁻¹(u) + v (θ - θ0) with its density N(x; v (θ - θ0), s²)."""

    def sampler(u, theta):
        shift = v * (theta - theta0)
        x = step.sample(u) + shift
        return x, np.exp(log_pdf_gaussian(x - shift, 0.0, s))

    return sampler


def truncated(u, theta):
    """The sampler of K restricted to x > θ, with its density K(x) / (1 - Φ(θ))."""
    tail = 1.0 - cdf(theta)
    x = cdf_inverse(cdf(theta) + u * tail)  # T(0, θ) = θ: the breakpoint follows the jump
    return x, normal_density(x) / tail


def per_sample(sampler, u, theta, detach_p=False):
    """h(u, θ) = f(x, θ) / p(x, θ) of every uniform u, with x = T(u, θ); optionally with p detached."""
    x, p = sampler(u, theta)
    return step.f(x, theta) / (detach(p) if detach_p else p)


theta1 = 0.8
samplers = {f"v = {v:g}": translated(v) for v in (0.0, 1.0, 2.0)} | {"truncated": truncated}
cells = 100_000
grid = (np.arange(cells) + 0.5) / cells  # midpoints of the cells of [0, 1]
first_nonzero, predicted_uc = {}, {}
for v in (0.0, 1.0, 2.0):
    for theta in (theta0, theta1):
        h = detach(per_sample(translated(v), grid, theta))
        first_nonzero[v, theta] = np.argmax(h > 0.0)  # h = 0 below the jump, > 0 above (T increases in u)
        predicted_uc[v, theta] = special.ndtr((theta - v * (theta - theta0)) / s)
        cell = grid[first_nonzero[v, theta] - 1 : first_nonzero[v, theta] + 1]
        print(f"v = {v:g}, θ = {theta}: jump between u = {cell[0]:.6f} and {cell[1]:.6f}, "
              f"predicted u_c = {predicted_uc[v, theta]:.6f}")  # fmt: skip
u = stream(SEED, "values").random(200_000)
values = {name: summarize(detach(per_sample(sampler, u, theta1))) for name, sampler in samplers.items()}
for name, m in values.items():
    print(f"{name:>9}: I(θ1) ≈ {m.mean:.5f} ± {m.stderr:.5f}   closed form {step.value(theta1):.5f}")

# %%
# check: each jump of h lies in the grid cell that contains the predicted u_c (exact: a grid cell is
# 1e-5 wide), and u_c moves from θ0 to θ1 unless v = 1; every sampler estimates I(θ1) within z standard
# errors (z two-sided, Šidák-corrected over the 3 random estimates at family-wise level 1e-3; Šidák's
# inequality holds for correlated normal estimates too, and these share their uniforms); the truncated
# sampler's h is the constant 1 - Φ(θ1) at every u, equal to I up to rounding (1e-12)
for key, j in first_nonzero.items():
    assert grid[j - 1] < predicted_uc[key] <= grid[j], key
assert first_nonzero[1.0, theta0] == first_nonzero[1.0, theta1]
assert first_nonzero[0.0, theta0] != first_nonzero[0.0, theta1]
assert first_nonzero[2.0, theta0] != first_nonzero[2.0, theta1]
z3 = normal_quantile(1 - sidak(1e-3, 3))
for name, m in values.items():
    if name == "truncated":
        assert m.stderr == 0.0 and abs(m.mean - step.value(theta1)) <= 1e-12
    else:
        assert abs(m.mean - step.value(theta1)) <= z3 * m.stderr, name

# %% [markdown]
# $h(u, \theta)$ over $u$ at the two parameters. Left, the fixed sampler: the jump moves from
# $u_c(\theta_0)$ to $u_c(\theta_1)$, and the mass between them is what the estimator gains or loses by
# the jump alone, invisible to a derivative taken at fixed $u$. Middle, the samples translated with
# the jump: the jump stays at $u_c = \Phi(\theta_0/s)$ and only the smooth part changes. Right, the
# truncated sampler: $h$ is flat, $1 - \Phi(\theta)$, and merely moves down as $\theta$ grows.

# %%
fig = ptu.plot_grid(3, titles=["fixed sampler (v = 0)", "translated with the jump (v = 1)", "truncated at θ"])
panels = [(0.0, translated(0.0)), (1.0, translated(1.0)), (None, truncated)]
for ax, (v, sampler) in zip(fig.axes, panels, strict=True):
    pt.plot_curves(
        grid[::50],
        {f"θ = {t}": detach(per_sample(sampler, grid[::50], t)) for t in (theta0, theta1)},
        marks=[] if v is None else sorted({predicted_uc[v, theta0], predicted_uc[v, theta1]}),
        xlabel="u",
        ylabel="h(u, θ) = f / p",
        ax=ax,
    )
fig

# %% [markdown]
# ## Differentiating sample by sample
#
# With $\theta$ a `Dual`, the tangent of $h(u_i, \theta)$ is each sample's derivative at fixed $u_i$, and
# its mean is the naive estimate. For the translated samplers $p$ is constant along a sample's path
# ($x - v(\theta - \theta_0)$ does not change), so $dh/d\theta = v\,K'(x)/p$ above the jump: the naive
# estimate converges to $v \int_\theta^\infty K'\,dx = -v\,K(\theta)$. The boundary formula above says the
# same: $dI/d\theta$ minus the missing $[f(c^-) - f(c^+)](c' - v) = -K(\theta)(1 - v)$.
#
# We take the uniforms of the library's `"samples"` stream, so that $v = 0$ is exactly the library's
# `naive` estimator and $v = 1$ exactly its `reparam` (Sec. 3.2: translate each sample with the
# nearest discontinuity), with $N = 2\cdot 10^5$.

# %%
n = 200_000
u = stream(SEED, "samples").random(n)
speeds = (0.0, 0.5, 1.0, 2.0)
tangents = {v: tangent(per_sample(translated(v), u, variable(theta0))) for v in speeds}
naive = {v: summarize(t) for v, t in tangents.items()}
missing = {v: jump.jump * (float(tangent(jump.location)) - v) for v in speeds}  # [f(c⁻) - f(c⁺)](c' - v)
library = {
    0.0: estimate("step", theta0, method="naive", n=n, seed=SEED),
    1.0: estimate("step", theta0, method="reparam", n=n, seed=SEED),
}
for v, m in naive.items():
    print(f"v = {v:g}: naive dI/dθ ≈ {m.mean:+.5f} ± {m.stderr:.5f}   "
          f"predicted dI/dθ - missing = {step.derivative(theta0) - missing[v]:+.5f}")  # fmt: skip
print(f"library naive {library[0.0].derivative:+.5f}, reparam {library[1.0].derivative:+.5f}")

# %%
# check: every sample's derivative at speed v is v times its derivative at v = 1 (up to rounding, 1e-12
# relative), so the four estimates are one measurement, not four; it agrees with its prediction -K(θ0)
# within z = 3.29 standard errors (two-sided 99.9 %); hence the estimate at speed v is -v K(θ0), biased
# by the missing term for every v ≠ 1. The samplers v = 0 and v = 1 are the library's naive and reparam
# estimators (same numbers up to rounding, 1e-12)
scale = np.abs(tangents[1.0]).max()
for v in speeds:
    assert np.allclose(tangents[v], v * tangents[1.0], rtol=0.0, atol=1e-12 * scale)
    predicted = step.derivative(theta0) - missing[v]
    assert abs(predicted + v * K(theta0)) <= 1e-12
assert abs(naive[1.0].mean - step.derivative(theta0)) <= normal_quantile(0.999) * naive[1.0].stderr
assert (
    naive[0.0].mean == 0.0
    and abs(missing[0.0] + K(theta0)) <= 1e-12
    and abs(missing[2.0] - K(theta0)) <= 1e-12
)
for v, est in library.items():
    assert (
        abs(est.derivative - naive[v].mean) <= 1e-12 and abs(est.derivative_stderr - naive[v].stderr) <= 1e-12
    )

# %% [markdown]
# The naive estimates with their 99 % intervals against $dI/d\theta = -K(\theta_0)$: only the sampler
# whose samples move at the speed of the jump is right.

# %%
pt.plot_estimates(
    {f"naive, v = {v:g}": (m.mean, m.stderr) for v, m in naive.items()},
    step.derivative(theta0),
    of="derivative",
    title="translated samplers: naive derivative against the closed form",
)

# %% [markdown]
# ## Differentiating through p
#
# The truncated sampler follows the jump as well (its breakpoint $u = 0$ is mapped to $\theta$), but it
# does not translate: as $\theta$ grows its samples bunch up towards $\theta$, and $p$ changes along each
# sample's path. Here $h(u, \theta) = 1 - \Phi(\theta)$ for every $u$, so the naive derivative is
# $-K(\theta)$ at every single sample: an exact, zero-variance gradient estimator. By the product rule,
#
# $$
# \frac{dh}{d\theta} = \underbrace{\frac{1}{p}\,\frac{d}{d\theta} f\bigl(x(\theta), \theta\bigr)}_{
#   \text{samples move}}
#   + \underbrace{f\,\frac{d}{d\theta}\frac{1}{p\bigl(x(\theta), \theta\bigr)}}_{\text{sample weight}} ,
# \qquad \frac1p = \partial_u T ,
# $$
#
# and the sample weight $\partial_u T$ is the Jacobian determinant of reparameterization (Sec. 3.2).
# Detaching $p$, treating the density as a constant, keeps only the first term. With
# $\partial_\theta x = K(\theta)(1 - u)/K(x)$ (differentiate $\Phi(x) = \Phi(\theta) + u(1 - \Phi(\theta))$)
# and $\frac{d}{d\theta}K(x) = -x K(x)\,\partial_\theta x$, its expectation is
#
# $$
# -\frac{K(\theta)}{1 - \Phi(\theta)} \int_\theta^\infty x\,\bigl(1 - \Phi(x)\bigr)\,dx
# = -\frac{K(\theta)}{2\,(1 - \Phi(\theta))}
#   \Bigl[(1 - \theta^2)\bigl(1 - \Phi(\theta)\bigr) + \theta K(\theta)\Bigr]
# $$
#
# (integrate by parts, then $\int_\theta^\infty x^2 K\,dx = \theta K(\theta) + 1 - \Phi(\theta)$), and the
# sample-weight term it drops is $-K(\theta)$ minus that. For the translated samplers $\partial_u T = s\,/
# K(\Phi^{-1}(u))$ does not depend on $\theta$, so there detaching $p$ changes nothing.

# %%
through_p = per_sample(truncated, u, variable(theta0))
detached = summarize(tangent(per_sample(truncated, u, variable(theta0), detach_p=True)))
tail0 = 1.0 - special.ndtr(theta0)
samples_move = -K(theta0) / (2 * tail0) * ((1 - theta0**2) * tail0 + theta0 * K(theta0))
weight_term = step.derivative(theta0) - samples_move
translated_detached = tangent(per_sample(translated(2.0), u, variable(theta0), detach_p=True))
low, high = tangent(through_p).min(), tangent(through_p).max()
print(f"through p: every sample's derivative in [{low:.6f}, {high:.6f}], -K(θ0) = {-K(theta0):.6f}")
print(f"p detached: {detached.mean:.5f} ± {detached.stderr:.5f}   predicted {samples_move:.5f}")
print(f"the sample-weight term it drops: {weight_term:.5f}")

# %%
# check: through p, every sample's value is 1 - Φ(θ0) and every derivative -K(θ0) (up to rounding,
# 1e-12); with p detached the estimate matches the closed form of the "samples move" term within
# z = 3.29 standard errors (two-sided 99.9 %) and misses -K(θ0) by the sample-weight term, more than
# 100 standard errors; for a translated sampler detaching p changes no sample's derivative (1e-12)
assert np.allclose(detach(through_p), tail0, rtol=0.0, atol=1e-12)
assert np.allclose(tangent(through_p), -K(theta0), rtol=0.0, atol=1e-12)
assert abs(detached.mean - samples_move) <= normal_quantile(0.999) * detached.stderr
assert abs(detached.mean - step.derivative(theta0)) > 100 * detached.stderr
assert np.allclose(translated_detached, tangents[2.0], rtol=0.0, atol=1e-12 * scale)

# %% [markdown]
# ## Summary: what each sampler's naive derivative misses
#
# For every sampler the naive derivative (measured) plus what it misses (closed forms: the boundary
# term $[f(c^-) - f(c^+)](c' - \partial_\theta T)$, and the sample-weight term when $p$ is detached) adds
# up to $dI/d\theta = -K(\theta_0)$, the black diamonds. Positive terms stack upwards from zero and
# negative ones downwards: at $v = 2$ the naive $-2K(\theta_0)$ overshoots and the missing $+K(\theta_0)$
# brings it back. Only the samplers that move their samples with the jump, and differentiate their
# density, miss nothing.

# %%
cases = [f"translated, v = {v:g}" for v in speeds] + ["truncated", "truncated, p detached"]
fig = ptu.plot_grid(1, panel_size=(8.0, 4.5))
pt.plot_terms(
    cases,
    {
        "naive: what AD returns (measured)": [naive[v].mean for v in speeds]
        + [float(np.mean(tangent(through_p))), detached.mean],
        "boundary term it misses": [missing[v] for v in speeds] + [0.0, 0.0],
        "sample-weight term it misses": [0.0] * len(speeds) + [0.0, weight_term],
    },
    totals=[step.derivative(theta0)] * len(cases),
    title="∫ 1[x > θ] K(x) dx at θ = 0.5: naive derivative and missing terms",
    ax=fig.axes[0],
)
fig

# %% [markdown]
# ## Where this returns
#
# Reparameterization (tutorial 6) is the second half of this notebook made systematic: instead of
# designing a sampler that follows the discontinuities, keep any $\theta$-independent sampler and
# compose it with a transform $T(\cdot, \theta)$ that moves the samples with them, multiplying by
# $|\det J_T|$, the sample weight; tutorial 4 shows the fixed sampler's failure on a rendered image.
