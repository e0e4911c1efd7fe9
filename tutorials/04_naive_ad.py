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
# # 4. Why naive automatic differentiation fails
#
# **What you will learn.**
#
# - why naive automatic differentiation of a Monte Carlo estimator misses the moving jump, seen as a
#   staircase in θ
# - the same failure at a silhouette in a flatland image
#
# Forward-mode automatic differentiation of a Monte Carlo estimator is exact for smooth
# integrands (Loubet et al. 2019, Sec. 3.1): the derivative of the estimator is an unbiased estimator of the
# derivative. This notebook shows, on two integrals side by side, what goes wrong when the
# integrand jumps at a place that moves with $\theta$ (Loubet et al. 2019, Sec. 3.2):
#
# - the paper's indicator example, $I(\theta) = \int 1_{x > \theta}\, K(x)\, dx$ with $K$ the
#   standard normal density, so $dI/d\theta = -K(\theta)$;
# - a pixel of a flatland image that sees the edge of an occluder, $I_j(\theta) = \int k_j(t)\,
#   L(t, \theta)\, dt$, where the radiance $L$ jumps at the edge's film coordinate $t_c(\theta)$.
#
# In both, every sample's derivative is zero, so the naive estimate is exactly zero. The
# estimator, seen as a function of $\theta$ with its samples fixed, is a staircase: flat
# almost everywhere, with the whole derivative hidden in its steps. The first cell imports
# the library and fixes the seed.

# %%
# %matplotlib inline
import numpy as np
from scipy import stats

import flatland as fl
from flatland import detach, estimate, get_integral, tangent, variable
from flatland.core.rng import stream
from flatland.core.stats import normal_quantile, sidak
from flatland.plotting import textbook as pt
from flatland.plotting import tutorials as ptu

SEED = 20191117
step = get_integral("step")
theta0 = 0.5
K = stats.norm.pdf  # the standard normal density

# %% [markdown]
# ## The indicator example, one sample at a time
#
# The library's `step` integrand is $f(x, \theta) = 1_{x > \theta} K(x)$; its samples come from
# $p = \mathcal N(0, 1.5^2)$, which does not depend on $\theta$. With $\theta$ a forward-mode
# `Dual` (`variable(theta0)`), the tangent of $f(x_i, \theta)$ is the derivative of one
# sample's contribution. The indicator is evaluated on values, and its derivative is zero
# wherever it exists, which is everywhere except at $x_i = \theta$, a point no sample ever hits.
# The estimator of the whole integral, `estimate(..., method="naive")`, averages those zeros.

# %%
x = step.sample(stream(SEED, "ten samples").random(10))
per_sample = step.f(x, variable(theta0)) / step.pdf(x)
print("x_i       :", np.round(x, 3))
print("f/p       :", np.round(detach(per_sample), 3))
print("d(f/p)/dθ :", tangent(per_sample))
naive = estimate("step", theta0, method="naive", n=200_000, seed=SEED)
print(f"naive: I ≈ {naive.value:.5f} ± {naive.value_stderr:.5f} (closed form {step.value(theta0):.5f})")
print(f"       dI/dθ ≈ {naive.derivative} ± {naive.derivative_stderr} (closed form {-K(theta0):.5f})")

# %%
# check: every sample's derivative is exactly 0, so the naive derivative is exactly 0 with zero variance,
# far from -K(θ0); the value is right (closed form within z = 3.29 standard errors, two-sided 99.9 %)
assert np.all(tangent(per_sample) == 0.0)
assert naive.derivative == 0.0 and naive.derivative_stderr == 0.0
assert step.derivative(theta0) == -K(theta0) < -0.35
assert abs(naive.value - step.value(theta0)) <= normal_quantile(0.999) * naive.value_stderr

# %% [markdown]
# ## The estimator is a staircase in θ
#
# Fix $N$ samples and vary $\theta$: $\hat I_N(\theta) = \frac1N \sum_i 1_{x_i > \theta}\,
# K(x_i)/p(x_i)$ is constant between samples and drops by $K(x_i)/(N p(x_i))$ each time $\theta$
# passes a sample $x_i$. Its derivative is zero at every $\theta$ that is not a sample, which is
# what forward-mode AD returns. Its expectation $1 - \Phi(\theta)$ slopes down, and the slope
# is made entirely of the steps: they are where the samples meet the moving discontinuity.
# We draw $N = 40$ samples and evaluate the staircase on a fine grid of $\theta$.

# %%
x40 = step.sample(stream(SEED, "staircase").random(40))
w40 = K(x40) / step.pdf(x40)  # each sample's weight f/p where the indicator is 1
grid = np.linspace(-1.5, 2.5, 4001)
staircase = np.mean((x40[None, :] > grid[:, None]) * w40[None, :], axis=1)
inside = (x40 > grid[0]) & (x40 <= grid[-1])
drops = np.diff(staircase)
print(f"{inside.sum()} samples in the window; the staircase moves at {np.count_nonzero(drops)} grid steps")
total_drop, predicted_drop = staircase[-1] - staircase[0], -w40[inside].sum() / 40
print(f"total drop {total_drop:.6f} = -Σ w_i/N over those samples: {predicted_drop:.6f}")

# %%
# check: the staircase moves only at grid steps that contain a sample (one step per sample here, the
# grid being finer than the gaps), each time by -w_i/N of that sample: it is flat everywhere else,
# and its total drop over the window is the sum of those steps (exact up to rounding, 1e-12)
steps_at = np.flatnonzero(drops)
owners = np.searchsorted(grid, x40[inside])  # the grid step (k-1, k] that contains each sample
assert np.array_equal(np.sort(owners - 1), steps_at)
assert np.allclose(np.sort(drops[steps_at]), np.sort(-w40[inside] / 40), atol=1e-12)
assert abs(total_drop - predicted_drop) < 1e-12

# %% [markdown]
# ## Where the slope went
#
# Average the staircase's slope over a window $[\theta_0 - h, \theta_0 + h]$: that is the central
# difference with common random numbers, `method="finite_difference"`. Its expectation is
# $[I(\theta_0 + h) - I(\theta_0 - h)]/2h$, close to $-K(\theta_0)$ for small $h$, but only the
# samples inside the window contribute, a fraction of about $2h\,p(\theta_0)$ of them. The
# standard error therefore grows like $h^{-1/2}$: as $h \to 0$ the window holds no sample, and the
# difference quotient becomes the naive derivative, exactly zero. With $N = 200\,000$:

# %%
hs = np.array([0.1, 0.01, 0.001])
fd = [estimate("step", theta0, method="finite_difference", n=200_000, seed=SEED, h=h) for h in hs]
expected = [(step.value(theta0 + h) - step.value(theta0 - h)) / (2 * h) for h in hs]
for h, e, m in zip(hs, fd, expected, strict=True):
    print(f"h = {h:6.3f}: {e.derivative:+.4f} ± {e.derivative_stderr:.4f}   expected {m:+.4f}")
se_ratio = fd[-1].derivative_stderr / fd[0].derivative_stderr
print(f"stderr ratio h = 0.001 vs 0.1: {se_ratio:.2f} (h^(-1/2) predicts {np.sqrt(hs[0] / hs[-1]):.1f})")

# %%
# check: each difference quotient matches its expectation within z standard errors (z two-sided,
# family-wise level 1e-3 Šidák-corrected over the 3 windows); the standard error grows like h^(-1/2):
# the ratio over a factor 100 in h is 10 within 25 % (about 140 samples fall into the narrowest window,
# so its standard error is itself known only to about 6 %, and 25 % is 4 of those)
z3 = normal_quantile(1 - sidak(1e-3, 3))
for e, m in zip(fd, expected, strict=True):
    assert abs(e.derivative - m) <= z3 * e.derivative_stderr
assert 7.5 <= se_ratio <= 12.5

# %% [markdown]
# ## The same thing at a silhouette in flatland
#
# A flatland scene with a closed form: a camera at $(0, -2.5)$ looking up ($+y$), a backdrop
# emitting radiance 1 across the whole view, and between them a black bar (albedo 0) from
# $x = -0.3$ to $0.5$ at height $y = -0.5$. The parameter `bar.translate.x` moves the bar. The
# camera's film coordinate of a point $p$ is $t = (p_x - 0)/(p_y + 2.5)$ (right $= +x$, forward
# $= +y$), so the bar's ends sit at $t_a = (-0.3 + \theta)/2$ and $t_b = (0.5 + \theta)/2$ and move at
# $t' = 1/2$. The radiance along the film is $L(t) = 1$ outside $[t_a, t_b]$ and $0$ inside, and
# pixel $j$ with tent filter $k_j$ (radius one pixel) integrates
#
# $$
# I_j(\theta) = \int k_j(t)\, L(t, \theta)\, dt = 1 - \int_{t_a(\theta)}^{t_b(\theta)} k_j(t)\, dt,
# \qquad
# \frac{dI_j}{d\theta} = k_j(t_a)\, t_a' - k_j(t_b)\, t_b' ,
# $$
#
# the textbook integral with two moving limits. The renderer estimates $I_j$ with film samples
# $t \sim k_j$, so each sample contributes $L(t)$: 0 or 1, with no derivative at all.


# %%
def bar_scene(offset=0.0, pixels=32):
    """The black-bar scene with the bar moved right by ``offset``."""
    return {
        "name": "black_bar",
        "camera": {"position": [0.0, -2.5], "direction": [0.0, 1.0], "fov": 0.9, "pixels": pixels},
        "sky": 0.0,
        "shapes": [
            {"name": "backdrop", "type": "segment", "points": [[-4.0, 2.0], [4.0, 2.0]], "emission": 1.0},
            {"name": "bar", "type": "segment", "points": [[-0.3 + offset, -0.5], [0.5 + offset, -0.5]]},
        ],
        "parameters": ["bar.translate.x"],
    }


camera = fl.load_scene(bar_scene()).camera
centres, width = camera.pixel_centers(), camera.pixel_width


def tent(t):
    """k_j(t) for every pixel j (tent of radius one pixel)."""
    return np.maximum(1.0 - np.abs(t - centres) / width, 0.0) / width


def tent_cdf(t):
    """∫ k_j up to t for every pixel j."""
    s = np.clip((t - centres) / width, -1.0, 1.0)
    return np.where(s < 0.0, 0.5 * (1.0 + s) ** 2, 1.0 - 0.5 * (1.0 - s) ** 2)


def closed_form(offset=0.0):
    """(I_j, dI_j/dθ) of every pixel with the bar moved by ``offset``."""
    t_a, t_b = (-0.3 + offset) / 2.0, (0.5 + offset) / 2.0
    return 1.0 - (tent_cdf(t_b) - tent_cdf(t_a)), 0.5 * tent(t_a) - 0.5 * tent(t_b)


value_cf, derivative_cf = closed_form()
naive_image = fl.render_gradient(bar_scene(), "bar.translate.x", method="naive", spp=256, seed=SEED)
boundary_image = fl.render_gradient(bar_scene(), "bar.translate.x", method="boundary", spp=256, seed=SEED)
edge_pixels = np.flatnonzero(derivative_cf)
print("pixels the bar's ends fall into:", edge_pixels)
print("closed-form dI/dθ there:", np.round(derivative_cf[edge_pixels], 3))
print("naive there:            ", naive_image.derivative[edge_pixels])
print("boundary there:         ", np.round(boundary_image.derivative[edge_pixels], 3))

# %%
# check: the image is right (closed form within t standard errors at every pixel: the standard errors come
# from 16 batches, so t has 15 degrees of freedom; two-sided, family-wise 1e-3 Šidák-corrected over the
# 32 pixels; pixels whose samples all agree have a zero standard error and must match exactly), the naive
# derivative is exactly 0 at every pixel although four pixels have a derivative of 3.6 to 12.9, and the
# boundary method (tutorial 5) recovers the closed form up to rounding
t32 = stats.t.ppf(1 - sidak(1e-3, 32) / 2, naive_image.batches - 1)
assert np.all(np.abs(naive_image.value - value_cf) <= t32 * naive_image.value_stderr + 1e-12)
assert np.all(naive_image.derivative == 0.0)
assert len(edge_pixels) == 4 and np.min(np.abs(derivative_cf[edge_pixels])) > 3.0
assert np.allclose(boundary_image.derivative, derivative_cf, rtol=0.0, atol=1e-9)

# %% [markdown]
# ## Two staircases side by side
#
# The pixel's estimate, as a function of $\theta$ with its samples fixed, is a staircase too:
# render the scene with the bar moved by offsets on a fine grid, each time with the same seed
# (the same 16 film samples per pixel), and follow the pixel that contains the bar's left end.
# It jumps by $1/16$ each time the bar's edge passes one of its samples (upward here: the bar moves
# right and uncovers the backdrop). Next to it, the textbook staircase from above.

# %%
pixel = edge_pixels[0]
offsets = np.linspace(-0.04, 0.04, 161)
pixel_staircase = np.array([fl.render(bar_scene(o), spp=16, seed=SEED).value[pixel] for o in offsets])
pixel_closed = np.array([closed_form(o)[0][pixel] for o in offsets])
jumps = np.diff(pixel_staircase)
print(f"pixel {pixel}: {np.count_nonzero(jumps)} steps over the grid, sizes {np.unique(np.round(jumps, 6))}")

# %%
# check: the pixel's estimate changes only in steps of one sample's share, ±1/16 (up to rounding,
# 1e-12), and between steps it is flat: the naive derivative 0 is the slope of every flat piece
nonzero = jumps[jumps != 0.0]
assert nonzero.size > 0 and np.allclose(np.abs(nonzero) * 16, np.round(np.abs(nonzero) * 16), atol=1e-12)
assert np.all(np.round(np.abs(nonzero) * 16) >= 1)

# %% [markdown]
# Left, the textbook estimator with 40 samples; right, one pixel with 16 film samples. Each
# dashed curve is the expectation, the solid one the estimator with its samples fixed. The
# expectations slope; the estimators are flat wherever automatic differentiation looks.

# %%
fig = ptu.plot_grid(2, titles=["∫ 1[x > θ] K(x) dx, N = 40", f"pixel {pixel} of the black bar, 16 samples"])
pt.plot_curves(
    grid,
    {"estimator, samples fixed": staircase, "I(θ) = 1 − Φ(θ)": stats.norm.sf(grid)},
    styles={"I(θ) = 1 − Φ(θ)": pt.REFERENCE_STYLE},
    xlabel="θ",
    ylabel="I",
    ax=fig.axes[0],
)
pt.plot_curves(
    offsets,
    {"estimator, samples fixed": pixel_staircase, "closed form I_j(θ)": pixel_closed},
    styles={"estimator, samples fixed": {"drawstyle": "steps-mid"}, "closed form I_j(θ)": pt.REFERENCE_STYLE},
    xlabel="θ (bar offset)",
    ylabel="I_j",
    ax=fig.axes[1],
)
fig

# %% [markdown]
# ## A shaded scene: the built-in `silhouette`
#
# The built-in `silhouette` scene has a grey polygon and a ball in front of an emissive backdrop;
# their only light is the backdrop behind them, so the sides the camera sees are dark, with
# shading that varies along the film. Moving the polygon (`occluder.translate.x`) moves its
# silhouette and its shading points with it. At 64
# pixels we compare the naive derivative with the boundary method and with central finite
# differences (`h = 0.01`, common random numbers, more samples because they are noisier).

# %%
silhouette = fl.load_scene("silhouette")
param = "occluder.translate.x"
image = fl.render(silhouette, spp=256, seed=SEED)
methods = {
    "naive": fl.render_gradient(silhouette, param, method="naive", spp=256, seed=SEED),
    "boundary": fl.render_gradient(silhouette, param, method="boundary", spp=256, seed=SEED),
    "finite differences": fl.render_gradient(
        silhouette, param, method="finite_difference", spp=2048, seed=SEED + 1, h=0.01
    ),
}
reference = methods["boundary"]
for name, g in methods.items():
    error, peak = g.error_vs(reference), np.abs(g.derivative).max()
    print(f"{name:>18}: relative error vs boundary {error:.3f}, max |dI/dθ| {peak:.2f}")

# %%
# check: naive is exactly 0 at every pixel (translating the polygon leaves every sample's radiance
# unchanged), while boundary and finite differences agree pixel by pixel within t standard errors
# (15 degrees of freedom, two-sided, family-wise 1e-3 Šidák-corrected over 64 pixels) plus the 1 %
# resolution of finite differences with common random numbers (tests/flatland/test_methods.py)
fd_image = methods["finite differences"]
t64 = stats.t.ppf(1 - sidak(1e-3, 64) / 2, reference.batches - 1)
tolerance = t64 * np.hypot(reference.derivative_stderr, fd_image.derivative_stderr)
tolerance += 0.01 * np.abs(reference.derivative).max()
assert np.all(methods["naive"].derivative == 0.0)
assert np.all(np.abs(reference.derivative - fd_image.derivative) <= tolerance)
assert np.abs(reference.derivative).max() > 5.0

# %% [markdown]
# The scene on the left (the moving polygon haloed in green, its motion as arrows), then the
# primal strip and the three derivatives on one colour scale; below, the same derivatives
# as curves with 99 % bands. The naive strip is blank: both silhouettes of the polygon are
# missing.

# %%
ptu.plot_gradient_panel(image, methods, title=f"silhouette: d/d {param}", scene=silhouette, param=param)

# %% [markdown]
# ## Summary
#
# Differentiating an estimator sample by sample gives the derivative of a function that is flat
# between samples. When a discontinuity moves with $\theta$, the derivative of the expectation is
# made of the estimator's steps, which sit where samples meet the discontinuity; no sample sits
# there, so naive AD returns the interior term of the Leibniz rule (tutorial 1) and drops the rest,
# here all of it. Finite differences see the steps only inside their window and trade bias for
# variance. The two remedies: add the missing boundary term explicitly (tutorial 5), or change
# variables so that the discontinuity no longer moves (tutorial 6).
