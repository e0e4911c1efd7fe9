r"""The BSDF strategy's kernel at glossy points: a concentration per point that follows the lobe's width.

The convolution of Loubet et al. 2019, Sec. 4.2 holds for any kernel whose concentration does not
depend on the sample: $∫ f(μ) dμ = ∫∫ f(μ) k_x(μ, ω) dμ dω$ for every $κ_x$ fixed at the point x (its
incidence and roughness at θ0), so each point may have its own. In the default order the sample μ
is drawn from the BSDF's density p and the kernel's centre ω from $k_x(·, μ)$; given ω, the samples
that the rotation $R_ω$ must carry lie where $p(μ) k_x(μ, ω)$ is large. In small angles, for a
lobe of angular standard deviation $σ_l$ about its centre m and a kernel of $σ_k = 1/\sqrt{κ}$,
that product is a Gaussian of standard deviation $σ_k σ_l / \sqrt{σ_k^2 + σ_l^2}$ about
$m + σ_l^2 (ω - m) / (σ_k^2 + σ_l^2)$. The probes look on a ring of ``spread`` $σ_k$ about ω
(:func:`~sphere3d.reparam.probes.vmf_spread_angle`): where $σ_k ≫ σ_l$ the product is the lobe, a
disc of radius $σ_l$ up to ``spread`` $σ_k$ away from ω, and the ring's few probes, about
``spread`` $σ_k$ apart, follow discontinuities the lobe's samples never reach while missing the
ones inside it: the rotation is then chosen for the wrong region, a bias. Where $σ_k ≤ σ_l$ the
product is the kernel (centred within $σ_k^2 / (σ_k^2 + σ_l^2)$ of the way to m) and the ring
covers it. Hence the rule (:func:`lobe_kappa`): the ring's radius at most ``fraction`` times the
lobe's radius $r_l$,

$κ_x = \min(κ_{max}, \max(κ, \mathrm{spread}^2 / (2 (1 - \cos(\mathrm{fraction}\; r_l)))))$

with κ the user's concentration (diffuse points, and wide lobes: a lower bound). The second term
is the κ whose ring lies exactly at angle $\mathrm{fraction}\; r_l$: the ring's
$1 - \cos r = -\mathrm{log1p}(P\, \mathrm{expm1}(-2κ)) / κ = \mathrm{spread}^2 / (2κ)$
for $e^{-2κ} ≪ 1$ (κ ≥ 1000 here).

**The lobe's radius** (GGX, :mod:`sphere3d.bsdf`). The microfacet slopes $(a, b)$ of GGX are distributed
with $P(|(a, b)| ≤ t) = t^2 / (α^2 + t^2)$: their median length is α (heavy tails: no standard
deviation), the median tilt $θ_h = \arctan α$. At normal incidence the reflection deviates from the
normal by exactly $2 θ_h$ (the visible normals are then the normals' projected distribution), median
$2 \arctan α$. At incidence $θ_i$, a normal tilted by slopes (a, b) (a in the plane of incidence)
reflects $w_i$ to the mirror direction plus $(2a, 2b \cos θ_i)$ to first order: the lobe is $\cos θ_i$
times narrower across the plane of incidence. The rule takes the narrower axis,
$r_l = 2 \arctan(α) \cos θ_i$, so the ring stays inside the lobe's median ellipse along both axes
("never beyond ``fraction`` of the lobe"). Assumptions and where it is biased: small α (first order in
the slopes; the rule binds only where $r_l$ is below the user's ring, $α < 0.048 / \cos θ_i$ at κ =
1000, spread 3 and fraction 1, elsewhere κ is the user's); the lobe's core about its centre (its heavy
tails reach beyond the ring: samples there, a fraction $1/(1 + (r/r_l)^2)$ of the lobe beyond radius r,
still get a rotation chosen near their kernel's centre, which is theirs, and there the lobe varies
slowly: the product is the kernel, which the ring covers as at a diffuse point); a narrower kernel's
weight has a larger derivative (variance of order κ, the cost of the rule). Grazing incidence
($\cos θ_i → 0$) asks for a very narrow kernel: κ is capped at $κ_{max}$
(:data:`~sphere3d.methods.reparam.KAPPA_MAX`). α is the point's roughness at θ0 (detached): a kernel's
concentration must be θ-free, as its samples' density.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flatland.core.validate import check_positive

__all__ = ["KAPPA_CAP", "LOBE", "check_lobe", "lobe_kappa", "lobe_radius"]

LOBE = 1.0
"""Default of the ``reparam`` option ``lobe``: the probe ring's radius at most the lobe's median
radius across the plane of incidence (fraction 1)."""
KAPPA_CAP = 1e15
"""Largest per-point concentration (:data:`~sphere3d.methods.reparam.KAPPA_MAX`, float64's resolution
of $1 - \\cos σ$)."""


def check_lobe(name: str, value: Any) -> float | None:
    """The option ``lobe``: a fraction > 0, or None (every point the user's κ)."""
    return None if value is None else check_positive(name, value)


def lobe_radius(wi: np.ndarray, n: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    r"""The GGX lobe's median angular radius across the plane of incidence, $r_l = 2 \arctan(α) \cos θ_i$
    (radians; module docstring), per row of unit ``wi`` and ``n`` (m, 3) and roughness ``alpha`` (m,); 0 where
    $w_i$ lies on or below the surface (no lobe: the integrand is 0 there)."""
    cos_i = np.einsum("ij,ij->i", np.asarray(wi, dtype=np.float64), np.asarray(n, dtype=np.float64))
    return 2.0 * np.arctan(np.asarray(alpha, dtype=np.float64)) * np.maximum(cos_i, 0.0)


def lobe_kappa(kappa: float, spread: float, fraction: float, radius: np.ndarray) -> np.ndarray:
    r"""Per-point vMF concentrations $κ_x = \min(κ_{max}, \max(κ, s^2 / (2 (1 - \cos(λ r_l)))))$.

    s = ``spread``, λ = ``fraction``, $r_l$ = ``radius`` (module docstring): the ring of ``spread``
    standard deviations at angle λ $r_l$ where that is narrower than the user's ``kappa`` ring,
    ``kappa`` elsewhere. ``radius`` (m,): the lobes' radii (:func:`lobe_radius`). A radius of 0 gives
    $κ_{max}$ (a point without a lobe: its integrand is 0 whatever the kernel). ``spread`` 0 (no
    ring) gives ``kappa``.
    """
    half = 0.5 * np.minimum(fraction * np.asarray(radius, dtype=np.float64), np.pi)
    one_minus_cos = 2.0 * np.sin(half) ** 2  # 1 - cos r without cancellation for small r
    with np.errstate(divide="ignore"):
        ring = np.where(one_minus_cos > 0.0, spread * spread / (2.0 * one_minus_cos), np.inf)
    if spread == 0.0:
        ring = np.zeros_like(ring)
    return np.minimum(KAPPA_CAP, np.maximum(kappa, ring))
