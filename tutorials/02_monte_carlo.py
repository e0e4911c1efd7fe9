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
# # 2. Monte Carlo, importance sampling and control variates
#
# Renderers estimate integrals by Monte Carlo, and every gradient estimator in this project is a
# Monte Carlo estimator too; its variance decides how many samples a trustworthy answer costs.
# This notebook measures the three facts of `docs/theory/monte_carlo.md`:
#
# 1. the plain estimator $\hat I = \frac1N \sum_i f(x_i)/p(x_i)$, $x_i \sim p$, is unbiased with
#    variance $\operatorname{Var}_p[f/p]/N$;
# 2. importance sampling, drawing from a density $q$ shaped like $f$, lowers $\operatorname{Var}_q[f/q]$;
# 3. a control variate $g$ with known integral lowers it again, by the factor $1 - \rho^2$.
#
# Every variance below is measured and compared with a closed form or a quadrature, within a
# stated statistical tolerance. The running example is the paper's step (Loubet et al. 2019,
# Sec. 3.2): $f(x) = 1_{x > \theta}\, K(x)$ with $K$ the standard normal density, so
# $I(\theta) = 1 - \Phi(\theta)$. The first cell imports the library and fixes the seed.

# %%
# %matplotlib inline
import numpy as np
from scipy import integrate, special, stats

from flatland import detach, estimate, get_integral
from flatland.core.rng import stream
from flatland.core.stats import normal_quantile, sidak
from flatland.plotting import textbook as pt
from flatland.sampling import pdf_gaussian, pdf_tabulated, sample_gaussian, sample_tabulated

SEED = 20191117
step = get_integral("step")
theta = 0.5
exact = step.value(theta)  # 1 - Φ(0.5)
K = stats.norm.pdf  # the standard normal density


# %% [markdown]
# ## The plain estimator
#
# With $x_i \sim p$ independent, $\mathbb E[f(x_i)/p(x_i)] = \int p\,(f/p)\,dx = I$, so $\hat I$ is
# unbiased, and its variance is $\sigma^2/N$ with $\sigma^2 = \operatorname{Var}_p[f/p]$. By the
# central limit theorem $\hat I$ is nearly normal for large $N$, so the standard error
# $\hat\sigma/\sqrt N$ turns into a confidence interval: $|\hat I - I| \le z\,\hat\sigma/\sqrt N$
# with probability about $0.999$ for $z = 3.29$.
#
# The library's `step` draws $x$ from $p = \mathcal N(0, 1.5^2)$, and `estimate` returns $\hat I$
# with its standard error.

# %%
plain = estimate("step", theta, method="naive", n=10_000, seed=SEED)
z = normal_quantile(0.999)
print(f"I ≈ {plain.value:.5f} ± {plain.value_stderr:.5f}   closed form {exact:.5f}")
print(f"z-score {plain.z_score(exact, of='value'):+.2f}")

# %%
# check: the closed form lies within z = 3.29 standard errors (two-sided 99.9 %)
assert abs(plain.value - exact) <= z * plain.value_stderr

# %% [markdown]
# ## The variance falls like $1/N$
#
# For the Gaussian proposal the variance has a closed form. With $p$ of standard deviation $s$,
# $K(x)^2/p(x) = \frac{s}{\sqrt{2\pi}}\, e^{-a x^2}$ with $a = 1 - \frac{1}{2s^2}$, and
# $\int_\theta^\infty e^{-a x^2} dx = \sqrt{\pi/a}\;\Phi(-\theta\sqrt{2a})$, so
#
# $$
# \sigma^2 = \int \frac{f^2}{p}\,dx - I^2 = \frac{s}{\sqrt{2a}}\,\Phi\!\left(-\theta\sqrt{2a}\right) - I^2 .
# $$
#
# (If $s^2 \le 1/2$ then $a \le 0$ and the integral diverges: a proposal whose tails fall as fast
# as $f^2$ or faster gives infinite variance, however good its estimates look.) We measure the variance of
# $\hat I$ directly: $T = 400$ independent estimates (seeds `SEED + k`) for each of three sample
# counts $N$.

# %%
s = 1.5
a = 1.0 - 1.0 / (2 * s * s)
sigma2 = s / np.sqrt(2 * a) * special.ndtr(-theta * np.sqrt(2 * a)) - exact**2
ns = np.array([100, 1_000, 10_000])
trials = 400
measured = np.array(
    [
        np.var(
            [estimate("step", theta, "naive", n=int(n), seed=SEED + k).value for k in range(trials)], ddof=1
        )
        for n in ns
    ]
)
for n, v in zip(ns, measured, strict=True):
    print(
        f"N = {n:6d}: measured Var = {v:.3e}, predicted σ²/N = {sigma2 / n:.3e}, ratio {v * n / sigma2:.3f}"
    )

# %%
# check: (T - 1) v̂ / (σ²/N) follows χ²(T - 1) for normal estimates; each ratio lies inside the
# two-sided interval at family-wise level 1e-3 (Šidák-corrected over the three N)
alpha = sidak(1e-3, len(ns))
low, high = stats.chi2.ppf([alpha / 2, 1 - alpha / 2], trials - 1) / (trials - 1)
for n, v in zip(ns, measured, strict=True):
    assert low <= v * n / sigma2 <= high, (n, v * n / sigma2, low, high)

# %% [markdown]
# On log-log axes $\sigma^2/N$ is a line of slope $-1$: ten times the samples, a tenth of the
# variance, a factor $\sqrt{10}$ in the error.

# %%
pt.plot_variance(
    ns,
    {"measured over 400 seeds": measured},
    predicted={"σ²/N": sigma2 / ns},
    title="plain Monte Carlo, step integral",
)

# %% [markdown]
# ## Importance sampling
#
# For any density $q > 0$ wherever $f \ne 0$,
# $I = \int q\,\frac{f}{q}\,dx = \mathbb E_q[f/q]$: sampling from $q$ and weighting by $1/q$ is
# still unbiased, with variance $\operatorname{Var}_q[f/q] = \int f^2/q\,dx - I^2$. The variance is
# zero for $q = f/I$ (every weight equals $I$), so the closer $q$ follows the shape of $f$, the
# better. Four proposals, all from the library's `sample_*`/`pdf_*` pairs or, for the ideal one,
# by inverting the CDF of $f/I$:
#
# - $\mathcal N(0, 1.5^2)$, the library's default for `step`;
# - $\mathcal N(0, 1)$, i.e. $K$ itself: the weight $f/q = 1_{x>\theta}$ is a coin flip, variance
#   $I(1-I)$;
# - a piecewise-constant $q$ on 16 bins of $[\theta, \theta + 8]$ with weights $K$(bin centre)
#   (`sample_tabulated`); $q = 0$ beyond $\theta + 8$, where $f$ holds a mass below $10^{-14}$;
# - the ideal $q = f/I$: $x = \Phi^{-1}\bigl(\Phi(\theta) + u\,(1 - \Phi(\theta))\bigr)$.
#
# For each, $N = 10^5$ samples give the estimate and the measured per-sample variance, and
# quadrature of $\int f^2/q\,dx$ gives the predicted variance.

# %%
edges = np.linspace(theta, theta + 8.0, 17)
weights = K(0.5 * (edges[1:] + edges[:-1]))
proposals = {
    "N(0, 1.5²)": (lambda u: sample_gaussian(u, 0.0, 1.5), lambda x: pdf_gaussian(x, 0.0, 1.5), (-12, 12)),
    "N(0, 1) = K": (lambda u: sample_gaussian(u, 0.0, 1.0), lambda x: pdf_gaussian(x, 0.0, 1.0), (-12, 12)),
    "16 bins ∝ K": (
        lambda u: sample_tabulated(u, edges, weights),
        lambda x: pdf_tabulated(x, edges, weights),
        (theta, theta + 8.0),
    ),
    "ideal f / I": (
        lambda u: special.ndtri(special.ndtr(theta) + u * exact),
        lambda x: K(x) / exact,
        (theta, 12),
    ),
}
n = 100_000
results = {}
for k, (name, (sample, pdf, support)) in enumerate(proposals.items()):
    x = sample(stream(SEED, "importance", k).random(n))
    w = detach(step.f(x, theta)) / pdf(x)  # the weight f/q of each sample
    v = w.var(ddof=1)
    se_v = np.sqrt((np.mean((w - w.mean()) ** 4) - v * v) / n)  # standard error of a sample variance
    breaks = edges[1:-1] if "bins" in name else None
    f2_over_q = integrate.quad(
        lambda t, pdf=pdf: K(t) ** 2 / pdf(np.array([t]))[0], theta, support[1], points=breaks, limit=200
    )[0]
    results[name] = {
        "mean": w.mean(),
        "stderr": np.sqrt(v / n),
        "var": v,
        "var_se": se_v,
        "predicted": f2_over_q - exact**2,
        "spread": np.ptp(w),
    }
for name, r in results.items():
    print(
        f"{name:>12}: I ≈ {r['mean']:.6f} ± {r['stderr']:.1e}   Var[f/q] = {r['var']:.3e} "
        f"(± {r['var_se']:.1e}), predicted {r['predicted']:.3e}"
    )

# %%
# check: every estimate is unbiased and every measured variance matches its prediction, both within
# z standard errors (z Šidák-corrected over the 2 × 4 comparisons, family-wise level 1e-3); the ideal
# proposal's weights are all equal to I up to rounding, so its variance is zero; the binned proposal
# beats K itself by more than a factor 50 (measured 67, each variance known to better than 1 %)
z8 = normal_quantile(1 - sidak(1e-3, 8))
for name, r in results.items():
    if name == "ideal f / I":
        assert r["spread"] < 1e-12 and abs(r["mean"] - exact) < 1e-12
        continue
    assert abs(r["mean"] - exact) <= z8 * r["stderr"], name
    assert abs(r["var"] - r["predicted"]) <= z8 * r["var_se"], name
assert results["16 bins ∝ K"]["var"] < results["N(0, 1) = K"]["var"] / 50

# %% [markdown]
# The densities against $f/I$, the shape they try to follow: the Gaussians waste most samples
# left of $\theta$, where $f = 0$; the binned one follows $f$ closely.

# %%
xs = np.linspace(-4, 6, 1001)
pt.plot_curves(
    xs,
    {"f / I (ideal)": detach(step.f(xs, theta)) / exact}
    | {name: pdf(xs) for name, (_, pdf, _) in proposals.items() if name != "ideal f / I"},
    styles={"f / I (ideal)": {"color": pt.REFERENCE_STYLE["color"], "linewidth": 2}},
    marks=[theta],
    xlabel="x",
    ylabel="density",
    title="proposals for ∫ 1[x > θ] K(x) dx",
)

# %% [markdown]
# The estimates with their 99 % intervals ($N = 10^5$ each) against $1 - \Phi(\theta)$: same
# mean, very different widths.

# %%
pt.plot_estimates(
    {name: (r["mean"], r["stderr"]) for name, r in results.items()},
    exact,
    of="value",
    title="importance sampling, N = 100 000",
)

# %% [markdown]
# ## Control variates
#
# Let $g$ be a function whose integral $G = \int g$ is known. For any constant $c$,
#
# $$
# \hat I_c = \frac1N \sum_i \frac{f(x_i) - c\,\bigl(g(x_i) - G\,p(x_i)\bigr)}{p(x_i)}
# $$
#
# has the same mean as $\hat I$, and per-sample variance
# $\operatorname{Var}[F] - 2c\operatorname{Cov}[F, \Gamma] + c^2 \operatorname{Var}[\Gamma]$ with
# $F = f/p$ and $\Gamma = g/p$. The best constant is
# $c^\ast = \operatorname{Cov}[F,\Gamma]/\operatorname{Var}[\Gamma]$, which leaves
# $\operatorname{Var}[F]\,(1 - \rho^2)$, $\rho$ the correlation of $F$ and $\Gamma$.
#
# A good $g$ looks like $f$ but is integrable in closed form. Smooth the step:
# $g(x) = \Phi(\beta(x - \theta))\,K(x)$. With $X, Z$ independent standard normals,
#
# $$
# G = \Pr[Z \le \beta(X - \theta)] = \Pr[Z - \beta X \le -\beta\theta]
#   = \Phi\bigl(-\beta\theta/\sqrt{1+\beta^2}\bigr) .
# $$
#
# We take $\beta = 4$ and estimate $c^\ast$ on a separate pilot batch (its own random stream), so
# that $c$ is independent of the main samples and $\hat I_c$ stays exactly unbiased.

# %%
beta = 4.0
G_exact = special.ndtr(-beta * theta / np.sqrt(1 + beta * beta))


def weights_f_and_g(n, name):
    """F = f/p and Γ = g/p at n samples of the library's proposal N(0, 1.5²), from stream ``name``."""
    x = sample_gaussian(stream(SEED, name).random(n), 0.0, 1.5)
    p = pdf_gaussian(x, 0.0, 1.5)
    return detach(step.f(x, theta)) / p, special.ndtr(beta * (x - theta)) * K(x) / p


F_pilot, g_pilot = weights_f_and_g(2_000, "pilot")
c = np.cov(F_pilot, g_pilot)[0, 1] / np.var(g_pilot, ddof=1)
F, g = weights_f_and_g(100_000, "samples")
controlled = F - c * (g - G_exact)
plain_se, cv_se = F.std(ddof=1) / np.sqrt(F.size), controlled.std(ddof=1) / np.sqrt(F.size)
ratio = controlled.var(ddof=1) / F.var(ddof=1)
print(f"c = {c:.3f}   plain: {F.mean():.5f} ± {plain_se:.5f}")
print(f"with control variate: {controlled.mean():.5f} ± {cv_se:.5f}")
print(f"variance ratio {ratio:.3f}   (1 - ρ² on these samples: {1 - np.corrcoef(F, g)[0, 1] ** 2:.3f})")

# %%
# check: both estimates lie within z = 3.29 standard errors of the closed form; the control variate
# removes more than 80 % of the variance (measured ratio 0.12, each variance known to about 1 %)
assert abs(F.mean() - exact) <= z * plain_se and abs(controlled.mean() - exact) <= z * cv_se
assert ratio < 0.2

# %% [markdown]
# Side by side, at the same $N = 10^5$: the control variate buys what about eight times as many
# plain samples would.

# %%
pt.plot_estimates(
    {"plain": (F.mean(), plain_se), "control variate β = 4": (controlled.mean(), cv_se)},
    exact,
    of="value",
    title="control variate, N = 100 000",
)

# %% [markdown]
# ## Where this returns
#
# The same two tools reappear in the gradient estimators. Reparameterization (tutorial 6) is
# importance sampling with a proposal that moves with $\theta$: the samples
# $x_i(\theta) = y_i + \theta - \theta_0$ follow the discontinuity. The authors' paired samples
# (`docs/theory/kernels.md`, tutorial 7) are a control variate: the derivative of a kernel weight
# $w = k/\operatorname{detach}(k)$ has zero mean, so subtracting a multiple of it changes the
# variance and not the expectation.
