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
# **What you will learn.**
#
# - Monte Carlo integration, importance sampling and control variates, with variances measured
#   against their predictions
# - the statistics every check cell of the course relies on: standard errors, z and t quantiles, and
#   the Šidák correction for several comparisons
# - why differentiating the estimator is correct when the integrand is smooth
#
# Renderers estimate integrals by Monte Carlo, and every gradient estimator in this project is a
# Monte Carlo estimator too; its variance decides how many samples a trustworthy answer costs.
# This notebook measures the three facts of `docs/theory/monte_carlo.md`:
#
# 1. the plain estimator $\hat I = \frac1N \sum_i f(x_i)/p(x_i)$, $x_i \sim p$, is unbiased with
#    variance $\operatorname{Var}_p[f/p]/N$;
# 2. importance sampling, drawing from a density $q$ shaped like $f$, lowers $\operatorname{Var}_q[f/q]$;
# 3. a control variate $g$ with known integral lowers it again, by the factor $1 - \rho^2$;
#
# and, on the way, two facts the later notebooks lean on: repeated estimates are spread like the normal
# law the central limit theorem predicts, and for a smooth integrand the derivative of the estimator,
# taken sample by sample, is an unbiased estimator of the derivative.
#
# Every variance below is measured and compared with a closed form or a quadrature, within a
# stated statistical tolerance. The running example is the paper's step (Loubet et al. 2019,
# Sec. 3.2): $f(x) = 1_{x > \theta}\, K(x)$ with $K$ the standard normal density, so
# $I(\theta) = 1 - \Phi(\theta)$. The first cell imports the library and fixes the seed.

# %%
# %matplotlib inline
import numpy as np
from scipy import integrate, special, stats

from flatland import detach, estimate, get_integral, tangent, variable
from flatland.core.rng import stream
from flatland.core.stats import chi2_gof_counts, normal_quantile, sidak
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
# ## How the check cells decide: standard errors, z, t and the Šidák correction
#
# Every check cell of the course compares a Monte Carlo number with a closed form (or with
# another measurement) and must pass when the code is right, however the random numbers fall,
# except with a small, stated probability. The recipe, used from here on:
#
# - **Standard error.** An estimate $\hat I$ from $N$ independent samples has standard error
#   $\mathrm{se} = \hat\sigma/\sqrt N$, $\hat\sigma$ the samples' standard deviation.
# - **z-score.** $z = (\hat I - I)/\mathrm{se}$ is nearly standard normal when the estimator is
#   unbiased (central limit theorem). The check passes when $|z| \le z_\alpha$, the two-sided
#   normal quantile of level $1 - \alpha$: 3.29 for $\alpha = 10^{-3}$ (99.9 %), 2.58 for 1 %.
#   A correct estimator then fails with probability $\alpha$; a biased one fails more often as
#   $N$ grows, since its $|z|$ grows like $\sqrt N$.
# - **Student's t.** The renderers estimate se from $B$ independent *batches* (16 by default),
#   not from the samples; se is then itself uncertain, and the quantile is Student's t with
#   $B - 1$ degrees of freedom (larger than the normal one: 4.07 instead of 3.29 at 99.9 % for 15).
# - **Šidák correction.** A cell that makes $m$ comparisons (one per pixel, per method, per
#   sample count) tests each at level $\alpha_1 = 1 - (1 - \alpha)^{1/m}$, so that the whole cell
#   fails by chance with probability $\alpha$ (for independent comparisons; fewer otherwise).
#   With $\alpha = 10^{-3}$ and $m = 64$ pixels each comparison uses $|z| \le 4.4$.
# - **Variances** are compared with a chi-square interval instead (below).
#
# The tolerance of every check is derived this way and stated in its first line; none is tuned
# until the check passes. The intervals the figures and command lines *print* use one level
# throughout, 99 % two-sided (`flatland.core.stats.LEVEL`). The quantiles, computed:

# %%
z999 = normal_quantile(0.999)
alpha64 = sidak(1e-3, 64)
z64 = normal_quantile(1 - alpha64)
t999 = stats.t.ppf(1 - 0.001 / 2, 15)
print(f"z at 99.9 %: {z999:.3f};  t (15 degrees of freedom): {t999:.3f}")
print(f"Šidák over 64 comparisons: each at α1 = {alpha64:.3e}, z = {z64:.3f}")

# %%
# check: the quantiles are the normal and Student-t laws' (exact up to rounding), and 64 comparisons at
# α1 fail together with probability α = 1e-3 when independent: 1 - (1 - α1)^64 = α
assert abs(z999 - 3.2905) < 1e-4 and abs(t999 - 4.0728) < 1e-4
assert abs((1 - (1 - alpha64) ** 64) - 1e-3) < 1e-12 and 4.31 < z64 < 4.33

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
# ## The central limit theorem, seen
#
# "Nearly normal" can be looked at. We draw $R = 2000$ independent estimates, each from $N = 1000$
# samples, as one $(R, N)$ array: row $r$ holds the samples of estimate $r$, and the row means are the
# estimates. The central limit theorem predicts that they follow $\mathcal N(I, \sigma^2/N)$, with $I$
# and $\sigma^2$ the closed forms above: nothing is fitted to the 2000 numbers.
#
# To test the prediction we cut the line into $k = 15$ bins of equal probability $1/k$ under
# $\mathcal N(I, \sigma^2/N)$, with edges $I + (\sigma/\sqrt N)\,\Phi^{-1}(j/k)$, and compare the counts
# with their expectation $R/k$ by Pearson's statistic $X^2 = \sum_j (O_j - R/k)^2/(R/k)$, which is
# $\chi^2(k - 1)$-distributed when the prediction holds. The normal law is itself an approximation at
# finite $N$: the mean of $N$ terms of skewness $\gamma_1$ has skewness $\gamma_1/\sqrt N$, and the first
# Edgeworth correction $-\frac{\gamma_1}{6\sqrt N}(z^2 - 1)\varphi(z)$ to its distribution function moves
# the bin probabilities by $\Delta p_j$. Those shifts make $X^2$ non-central with
# $\lambda = R\sum_j \Delta p_j^2/(1/k)$; we compute $\lambda$, with the third moment
# $\int f^3/p^2\,dx$ of one term by quadrature.

# %%
R, N = 2000, 1000
x = step.sample(stream(SEED, "clt").random((R, N)))
clt_estimates = (detach(step.f(x, theta)) / step.pdf(x)).mean(axis=1)  # one estimate per row
clt_se = np.sqrt(sigma2 / N)  # the predicted standard error
k = 15
inner = special.ndtri(np.arange(1, k) / k)  # standard-normal edges of k equiprobable bins
counts = np.bincount(np.searchsorted(exact + clt_se * inner, clt_estimates), minlength=k)
gof = chi2_gof_counts(counts, np.full(k, R / k))
third = integrate.quad(lambda t: K(t) ** 3 / step.pdf(np.array([t]))[0] ** 2, theta, 12)[0]
skew = (third - 3 * exact * (sigma2 + exact**2) + 2 * exact**3) / sigma2**1.5  # skewness of one term f/p
edgeworth = np.concatenate([[0.0], -skew / (6 * np.sqrt(N)) * (inner**2 - 1) * stats.norm.pdf(inner), [0.0]])
noncentrality = R * np.sum(np.diff(edgeworth) ** 2 * k)
print(f"mean of the {R} estimates {clt_estimates.mean():.5f} (I = {exact:.5f})")
print(f"their standard deviation {clt_estimates.std(ddof=1):.5f} (σ/√N = {clt_se:.5f})")
print(f"counts per bin: {counts} (expected {R / k:.1f} each)")
print(f"X² = {gof.statistic:.1f} on {gof.dof} degrees of freedom, p = {gof.p_value:.2f}")
print(f"skewness of one term {skew:.2f}, of the mean {skew / np.sqrt(N):.3f}")
print(f"non-centrality of X² from that skewness: λ = {noncentrality:.2f}")

# %%
# check: X² stays below the 99.9 % quantile of χ²(14) (level 1e-3). The test is valid here: the 2000
# estimates are independent (disjoint rows of one stream); the bins come from the prediction, not from
# the data, and no parameter is fitted, so X² has k - 1 = 14 degrees of freedom; every bin expects
# R/k = 133 estimates, far above the rule of thumb of 5 per bin; an odd k puts no edge on the mean, the
# axis of symmetry. The normal law is close enough at N = 1000 for the test's level to be its nominal
# one: the skewness shifts E[X²] by λ < 1, small against the spread √(2 · 14) = 5.3 of X² itself
assert R / k >= 5 and k % 2 == 1
assert gof.dof == k - 1 and gof.statistic <= stats.chi2.ppf(1 - 1e-3, k - 1)
assert noncentrality < 1.0

# %% [markdown]
# The 2000 estimates against the predicted normal density; the dotted lines hold 99 % of it. The
# histogram has 41 equal-width bins, for the eye; the test above used its own 15 equiprobable ones.

# %%
pt.plot_histogram_vs_normal(
    clt_estimates,
    exact,
    clt_se,
    label=f"plain estimates, N = {N}",
    title="central limit theorem: 2000 estimates of ∫ 1[x > θ] K(x) dx",
    xlabel="Î",
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
# that $c$ is independent of the main samples and $\hat I_c$ stays exactly unbiased: given $c$, the
# main terms $F_i - c\,(\Gamma_i - G)$ are i.i.d. with mean $I$.
#
# How much variance is left? For the $c$ actually used, completing the square in $c$ gives
#
# $$
# \operatorname{Var}[F - c\,\Gamma]
#   = \operatorname{Var}[F]\,(1 - \rho^2) + (c - c^\ast)^2 \operatorname{Var}[\Gamma] ,
# $$
#
# so the predicted variance ratio is $1 - \rho^2$ plus the excess
# $(c - c^\ast)^2 \operatorname{Var}[\Gamma]/\operatorname{Var}[F]$ that the pilot's error in $c$ costs.
# A slope fitted on $n_\text{pilot}$ points has variance about
# $\operatorname{Var}[F]\,(1 - \rho^2)/(n_\text{pilot} \operatorname{Var}[\Gamma])$, so the excess is
# expected near $(1 - \rho^2)/n_\text{pilot}$: small, but we account for it rather than assume it away.
# $\rho$ and $c^\ast$ come from neither batch: the moments $\int f g/p\,dx$ and $\int g^2/p\,dx$ are
# integrated by quadrature, and $\operatorname{Var}[F] = \sigma^2$ is the closed form from above.

# %%
beta = 4.0
G_exact = special.ndtr(-beta * theta / np.sqrt(1 + beta * beta))


def g_of(t):
    """The control variate g(x) = Φ(β(x - θ)) K(x)."""
    return special.ndtr(beta * (t - theta)) * K(t)


def p_of(t):
    """The proposal density N(0, 1.5²) at a scalar t, for quadrature."""
    return pdf_gaussian(np.array([t]), 0.0, 1.5)[0]


fg = integrate.quad(lambda t: K(t) * g_of(t) / p_of(t), theta, 12)[0]  # E[F Γ] = ∫ f g / p dx
gg = integrate.quad(lambda t: g_of(t) ** 2 / p_of(t), -12, 12, points=[theta])[0]  # E[Γ²]
var_g, cov_fg = gg - G_exact**2, fg - exact * G_exact
rho = cov_fg / np.sqrt(sigma2 * var_g)
c_star = cov_fg / var_g


def weights_f_and_g(n, name):
    """F = f/p and Γ = g/p at n samples of the library's proposal N(0, 1.5²), from stream ``name``."""
    x = sample_gaussian(stream(SEED, name).random(n), 0.0, 1.5)
    p = pdf_gaussian(x, 0.0, 1.5)
    return detach(step.f(x, theta)) / p, special.ndtr(beta * (x - theta)) * K(x) / p


n_pilot = 2_000
F_pilot, g_pilot = weights_f_and_g(n_pilot, "pilot")
c = np.cov(F_pilot, g_pilot)[0, 1] / np.var(g_pilot, ddof=1)
F, g = weights_f_and_g(100_000, "samples")
controlled = F - c * (g - G_exact)
plain_se, cv_se = F.std(ddof=1) / np.sqrt(F.size), controlled.std(ddof=1) / np.sqrt(F.size)
ratio = controlled.var(ddof=1) / F.var(ddof=1)
excess = (c - c_star) ** 2 * var_g / sigma2
predicted_ratio = 1 - rho**2 + excess
# delta method: the ratio of two sample variances moves with the mean of ψ_i, ψ_i = (A_i² - r F_i²)/Var[F]
# for the centred terms A = F - cΓ and F
psi = ((controlled - controlled.mean()) ** 2 - ratio * (F - F.mean()) ** 2) / F.var(ddof=1)
ratio_se = psi.std(ddof=1) / np.sqrt(F.size)
print(f"c = {c:.4f} (pilot), c* = {c_star:.4f} (quadrature)   plain: {F.mean():.5f} ± {plain_se:.5f}")
print(f"with control variate: {controlled.mean():.5f} ± {cv_se:.5f}")
print(f"variance ratio {ratio:.4f} ± {ratio_se:.4f}")
print(f"predicted 1 - ρ² + excess = {1 - rho**2:.4f} + {excess:.1e} = {predicted_ratio:.4f}")
print(f"(expected excess about (1 - ρ²)/n_pilot = {(1 - rho**2) / n_pilot:.0e})")

# %%
# check: both estimates lie within z standard errors of the closed form, and the measured variance ratio
# lies within z standard errors (delta method) of its prediction 1 - ρ² + (c - c*)² Var[Γ]/Var[F]; z is
# two-sided, Šidák-corrected over the 3 comparisons at family-wise level 1e-3. The excess term is
# accounted for, not neglected (here it is about 2 % of the standard error of the ratio)
z3 = normal_quantile(1 - sidak(1e-3, 3))
assert abs(F.mean() - exact) <= z3 * plain_se and abs(controlled.mean() - exact) <= z3 * cv_se
assert abs(ratio - predicted_ratio) <= z3 * ratio_se

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
# ## Differentiating the estimator: the smooth case
#
# If the samples $x_i$ do not depend on $\theta$ and $f$ is continuously differentiable in $\theta$,
# the derivative of the estimator is the estimator of the derivative (Loubet et al. 2019, Sec. 3.1):
#
# $$
# \frac{d\hat I}{d\theta} = \frac1N \sum_i \frac{\partial_\theta f(x_i, \theta)}{p(x_i)}, \qquad
# \mathbb E\!\left[\frac{d\hat I}{d\theta}\right] = \int \partial_\theta f\,dx = \frac{dI}{d\theta} .
# $$
#
# Forward-mode automatic differentiation computes it sample by sample: with $\theta$ a `Dual`
# (`variable(theta)`, tangent 1), the tangent of each $f(x_i, \theta)/p(x_i)$ is that sample's
# derivative, which is what the library's `naive` method averages. The textbook integral `smooth`,
# $f = K(x - \theta)(1 + x^2)$ with $I = 2 + \theta^2$ and $dI/d\theta = 2\theta$, is continuous; its proposal
# is $p = \mathcal N(0, 2^2)$. As for the central limit theorem, $R = 1000$ derivative estimates of
# $N = 1000$ samples each, one row each; the per-sample variance
# $\sigma_d^2 = \int (\partial_\theta f)^2/p\,dx - (2\theta)^2$ comes from quadrature.

# %%
smooth = get_integral("smooth")
theta_s = 0.7
R_d, N_d = 1000, 1000
xs = smooth.sample(stream(SEED, "smooth").random((R_d, N_d)))
per_sample = tangent(smooth.f(xs, variable(theta_s)) / smooth.pdf(xs))  # d/dθ of each sample's f/p
derivative_estimates = per_sample.mean(axis=1)
grand, grand_se = per_sample.mean(), per_sample.std(ddof=1) / np.sqrt(per_sample.size)


def df_dtheta(t):
    """∂f/∂θ = (x - θ) K(x - θ)(1 + x²) at a scalar x = t."""
    return (t - theta_s) * K(t - theta_s) * (1 + t * t)


sigma2_d = integrate.quad(lambda t: df_dtheta(t) ** 2 / smooth.pdf(np.array([t]))[0], -15, 15, limit=200)[0]
sigma2_d -= (2 * theta_s) ** 2
library = estimate("smooth", theta_s, method="naive", n=100_000, seed=SEED)
spread_ratio = derivative_estimates.var(ddof=1) / (sigma2_d / N_d)
print(f"all {per_sample.size} samples: dI/dθ ≈ {grand:.4f} ± {grand_se:.4f}   closed form 2θ = {2 * theta_s}")
print(f"library, naive: {library.derivative:.4f} ± {library.derivative_stderr:.4f}")
print(f"variance of the {R_d} estimates / (σ_d²/N) = {spread_ratio:.3f}")

# %%
# check: the derivative from all 10⁶ samples and the library's naive estimate lie within z standard
# errors of 2θ, and the spread of the 1000 estimates matches σ_d²/N: (R - 1) v̂/(σ_d²/N) lies inside the
# two-sided χ²(R - 1) interval; family-wise level 1e-3, Šidák-corrected over the 3 comparisons (the z3
# of the control-variate check)
alpha3 = sidak(1e-3, 3)
low_d, high_d = stats.chi2.ppf([alpha3 / 2, 1 - alpha3 / 2], R_d - 1) / (R_d - 1)
assert abs(grand - smooth.derivative(theta_s)) <= z3 * grand_se
assert abs(library.derivative - smooth.derivative(theta_s)) <= z3 * library.derivative_stderr
assert low_d <= spread_ratio <= high_d

# %% [markdown]
# The 1000 derivative estimates against $\mathcal N(2\theta, \sigma_d^2/N)$, in the colour of the naive
# method: centred on the closed form. For the step the same recipe returns exactly 0 (tutorial 4); when
# the samples themselves move with $\theta$, tutorial 3.

# %%
pt.plot_histogram_vs_normal(
    derivative_estimates,
    smooth.derivative(theta_s),
    np.sqrt(sigma2_d / N_d),
    label=f"naive dÎ/dθ, N = {N_d}",
    title="sample-by-sample derivative of ∫ K(x − θ)(1 + x²) dx",
    xlabel="dÎ/dθ",
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
