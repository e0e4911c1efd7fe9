"""Reparameterization by translation, with optional convolution kernel and paired samples.

Loubet et al. 2019, Sec. 3.2 (change of variables), 4.1 (one transform per integral,
here a translation), 4.2 (convolution kernels) and the paired-sample control variate
of the authors' implementation (theory/kernels).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flatland.core.contract import Estimate, Option
from flatland.core.dual import Dual, detach, variable
from flatland.core.rng import stream
from flatland.core.translation import paired_combine, translation_offset, unit_weight
from flatland.core.validate import ValidationError, check_bool, check_positive
from flatland.integrals import Circle, Discontinuity, Integrand
from flatland.sampling import TWO_PI
from flatland.textbook._common import METHODS, primary_samples, to_estimate

__all__ = ["follow_nearest", "reparam", "translation_bias"]


def follow_nearest(domain: Any, discontinuities: tuple[Discontinuity, ...], points: np.ndarray) -> Dual:
    r"""Per point, the translation $Δ = c(θ) - \mathrm{detach}(c(θ))$ of the discontinuity nearest to it.

    Δ has value 0 (so $T(y, θ_0) = y + Δ$ is the identity, Loubet et al. 2019, Sec. 3.2) and derivative
    $c'(θ)$ of the chosen discontinuity. With no discontinuity the translation is the
    identity ($Δ = 0$, $Δ' = 0$).
    """
    points = np.asarray(points, dtype=np.float64)
    if not discontinuities:
        return Dual(np.zeros_like(points))
    locations = np.stack([d.location for d in discontinuities])  # Dual, shape (m,)
    distance = domain.distance(points[None, :], detach(locations)[:, None])  # (m, n)
    chosen = locations[np.argmin(distance, axis=0)]  # gather: Dual, shape (n,)
    # T(y, θ) = y + c(θ) - c(θ0): value 0, tangent c'(θ)   (Loubet et al. 2019, Sec. 3.2)
    return translation_offset(chosen)


def translation_bias(integrand: Integrand, theta: float) -> float:
    r"""The expected bias of :func:`reparam` without a kernel: $Σ_m (c_{left}' - c_{right}') f(m)$.

    Each sample follows the discontinuity nearest to it, so the samples between two
    neighbouring discontinuities $c_{left} < c_{right}$ are split at their midpoint m (the
    boundary of their Voronoi cells): left of m they move with $c_{left}'$, right of it with
    $c_{right}'$. The estimator differentiates $∫_{R_k} f(x + Δ_k(θ), θ) dx$ over each
    fixed cell $R_k$, i.e. the integral over the moved cell $R_k + Δ_k$, whose ends pick up
    $± f(m) c_k'$ (Leibniz rule, theory/leibniz); summed over the cells, every midpoint m
    contributes $(c_{left}' - c_{right}') f(m)$, 0 when both move at the same speed (Loubet
    et al. 2019, Sec. 4.2: one transform cannot follow discontinuities that move
    differently). On the line the outermost cells reach to ±∞, where f vanishes; on the
    circle the last and first discontinuities are neighbours across 2π.
    """
    theta_d = variable(theta)
    found = integrand.discontinuities(theta_d)
    if len(found) < 2:
        return 0.0
    circle = integrand.domain is Circle
    at = np.array([float(detach(d.location)) for d in found])
    speed = np.array([float(d.location.tangent) for d in found])
    if circle:
        at = np.remainder(at, TWO_PI)
    order = np.argsort(at, kind="stable")
    at, speed = at[order], speed[order]
    left, right = at[:-1], at[1:]
    dl, dr = speed[:-1], speed[1:]
    if circle:  # the pair across 2π: the last one and the first one, one turn on
        left, right = np.append(left, at[-1]), np.append(right, at[0] + TWO_PI)
        dl, dr = np.append(dl, speed[-1]), np.append(dr, speed[0])
    middle = 0.5 * (left + right)
    f = np.asarray(detach(integrand.f(middle, theta)), dtype=np.float64)
    return float(np.sum((dl - dr) * f))


@METHODS.register(
    "reparam",
    Option("kappa", None, check_positive),
    Option("paired", False, check_bool),
)
def reparam(
    integrand: Integrand, theta: float, n: int, seed: int, kappa: float | None, paired: bool
) -> Estimate:
    r"""Reparameterize each sample by the translation that follows the nearest discontinuity.

    Without a kernel (``kappa=None``), sample $x_i \sim p$ is evaluated at
    $T_i(x_i, θ) = x_i + c_k(θ) - c_k(θ_0)$ with $c_k$ the discontinuity nearest $x_i$
    (Sec. 3.2 and 4.1; $|\det J| = 1$). The primal estimate is bit-identical to the
    naive one. Unbiased when one translation follows every discontinuity that can
    affect a sample; where discontinuities moving at different speeds meet (their
    Voronoi boundary m), it is biased by $Σ_m (c_{left}' - c_{right}') f(m)$.

    With a kernel of concentration ``kappa`` (Sec. 4.2) the integral is written as
    $∫∫ f(μ) k(μ, ω) dμ dω$. Here $μ = x_i$ is the naive sample and the kernel centre
    $ω_i \sim k(·, x_i)$ is drawn around it (the same joint density as the paper's
    "$ω \sim p, μ \sim k(·, ω)$" read the other way, because k is symmetric and integrates to
    1 in each argument), which keeps the primal estimate bit-identical to the naive
    one. The translation follows the discontinuity nearest $ω_i$, and the weight
    $k(T μ, ω) / \mathrm{detach}(k(T μ, ω))$ (value 1) carries the kernel's derivative.
    Bias: a discontinuity the translation does not follow still contributes where
    the kernel reaches it, a tail mass that falls as κ grows; variance grows with κ
    through the derivative of $\log k$ (about $\sqrt{κ}$ per sample).

    ``paired=True`` (needs ``kappa``) uses the paper's order instead: $ω_i \sim p$,
    two kernel samples $μ_{i0}, μ_{i1} \sim k(·, ω_i)$ share one translation, and each one's
    zero-mean weight derivative serves as the other's control variate:
    $0.5 (e0 - e1 / w1 (w0 - \mathrm{detach}(w0))) + 0.5 (e1 - e0 / w0 (w1 - \mathrm{detach}(w1)))$
    (theory/kernels). ``n`` counts integrand evaluations, so n // 2 pairs; the primal
    is then a different (still unbiased) estimate than the naive one.
    """
    theta_d = variable(theta)
    domain = integrand.domain
    discontinuities = integrand.discontinuities(theta_d)
    options = {"kappa": kappa, "paired": paired}

    if paired:
        if kappa is None:
            raise ValidationError("paired", "needs a convolution kernel: pass kappa > 0 as well")
        if n < 2:
            raise ValidationError("n", f"must be >= 2 with paired=True (two samples per pair), got {n}")
        pairs = n // 2
        s = primary_samples(integrand, pairs, seed)  # the outer samples ω_i ~ p
        u = stream(seed, "kernel").random((2, pairs))
        shift = follow_nearest(domain, discontinuities, s.x)  # one translation per pair
        e, w = [], []
        for j in range(2):  # the two members of each pair (not a loop over samples)
            mu = domain.sample_kernel(u[j], s.x, kappa)
            y = mu + shift
            w.append(unit_weight(domain.log_kernel(y, s.x, kappa)))  # k / detach(k), value 1 (Sec. 4.2)
            e.append(integrand.f(y, theta_d) * w[j] / s.pdf)
        # each weight's derivative has zero mean given ω and is independent of the other sample:
        # a control variate scaled by the other sample's estimate   (paired samples, theory/kernels)
        pair = paired_combine(e[0], e[1], w[0], w[1])
        return to_estimate(pair, 2 * pairs, "reparam", options)

    s = primary_samples(integrand, n, seed)
    if kappa is None:
        shift = follow_nearest(domain, discontinuities, s.x)
        return to_estimate(integrand.f(s.x + shift, theta_d) / s.pdf, n, "reparam", options)

    # kernel centre ω_i ~ k(·, x_i) from its own stream: the primary samples stay the naive ones
    center = domain.sample_kernel(stream(seed, "kernel").random(n), s.x, kappa)
    y = s.x + follow_nearest(domain, discontinuities, center)
    w = unit_weight(domain.log_kernel(y, center, kappa))  # k / detach(k), value 1 (Sec. 4.2)
    # f(T x) k(T x, ω) / (p(x) k(x, ω)): value f(x) / p(x), derivative with the kernel factor   (Sec. 4.2)
    return to_estimate(integrand.f(y, theta_d) * w / s.pdf, n, "reparam", options)
