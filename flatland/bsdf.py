r"""The glossy BSDF of flatland: GGX microfacets on a profile in the plane, as eval / sample / pdf.

The 2D counterpart of :mod:`sphere3d.bsdf`: a rough conductor whose surface is a profile with
slopes distributed as $P_2(x) = α^2 / (2 (α^2 + x^2)^{3/2})$, the slopes 3D GGX has along any one
direction of its tangent plane, so the roughness α means the same in both packages and Smith's
masking term is the same function (:mod:`flatland.core.microfacet`). At α = 1 the profile is
made of semicircles, as the 3D surface is made of hemispheres.

Directions are angles (radians), as everywhere in flatland: ``phi_i`` the given direction (in a
path, back towards the camera or the previous vertex), ``phi_o`` the one sampled or evaluated,
both pointing away from the surface, and ``normal_angle`` the normal's. With
$a = φ_i - φ_n$, $b = φ_o - φ_n$ (wrapped to [-π, π)) the half direction is at $θ_h = (a + b) / 2$
from the normal, exactly, and

$f(a, b) = F D(θ_h) G_2(a, b) \cos((a - b) / 2) / (2 \cos a \cos b)$

for $|a|, |b| < π/2$, 0 elsewhere, with

- the distribution of normals $D(θ) = α^2 / (2 (α^2 \cos^2 θ + \sin^2 θ)^{3/2})$ (per radian,
  $∫ D(θ) \cos θ dθ = 1$: $P_2$ in the angle of its slope);
- Smith's height-correlated $G_2$ (:func:`~flatland.core.microfacet.smith_g2`);
- F = ``albedo``, a constant Fresnel reflectance.

The form follows from reflecting each visible microfacet as a mirror: the visible normals have
density $D_a(θ_h) = G_1(a) \max(0, \cos(a - θ_h)) D(θ_h) / \cos a$, and $b = 2 θ_h - a$ doubles
angles ($db = 2 dθ_h$, where 3D has $dω_o = 4 |w_i·h| dω_h$), so the sampled density is
$D_a(θ_h) / 2$ and a fraction $G_2 / G_1$ of it leaves unshadowed. :func:`eval_ggx` returns f
itself, without the cosine: the reflected radiance is $∫ L(b) f(a, b) \cos b\, db$. Densities are
per radian. Reciprocity holds bit for bit, the albedo is at most F (:func:`albedo_ggx`).
α and ``albedo`` may be Duals, and so may the angles in :func:`eval_ggx`, :func:`pdf_ggx` and
:func:`weight_ggx`; :func:`sample_ggx` draws plain angles from detached values (theory/bsdf).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flatland.core.dual import detach
from flatland.core.microfacet import (
    check_albedo,
    check_alpha,
    check_cos_theta,
    graded_gauss,
    join_last,
    smith_root,
)
from flatland.core.validate import check_int
from flatland.sampling import wrap_angle

__all__ = ["albedo_ggx", "eval_ggx", "pdf_ggx", "sample_ggx", "weight_ggx"]


def _ndf(theta: Any, alpha: Any) -> Any:
    r"""$D(θ) = α^2 / (2 (α^2 \cos^2 θ + \sin^2 θ)^{3/2})$; the caller keeps $|θ| < π/2$."""
    c, s, a2 = np.cos(theta), np.sin(theta), alpha * alpha
    den = a2 * c * c + s * s
    return a2 / (2.0 * den * np.sqrt(den))


def eval_ggx(phi_i: Any, phi_o: Any, normal_angle: Any, alpha: Any, albedo: Any) -> Any:
    r"""The BSDF $f(a, b)$ per radian, without the cosine factor (module docstring).

    Written as $F D(θ_h) \cos(|a - b| / 2) / (r_a \cos b + r_b \cos a)$ ($G_2 / (2 \cos a \cos b)$
    simplified, with Smith's roots r), finite up to grazing angles; symmetric in ``phi_i`` and
    ``phi_o`` bit for bit. 0 where either direction lies on or below the surface.
    """
    alpha, albedo = check_alpha(alpha), check_albedo(albedo)
    a, b = wrap_angle(phi_i - normal_angle), wrap_angle(phi_o - normal_angle)
    ca, cb = np.cos(a), np.cos(b)
    valid = (detach(ca) > 0.0) & (detach(cb) > 0.0)
    a_, b_ = np.where(valid, a, 0.0), np.where(valid, b, 0.0)  # keeps θ_h in (-π/2, π/2)
    den = np.where(valid, smith_root(ca, alpha) * cb + smith_root(cb, alpha) * ca, 1.0)
    f = albedo * _ndf(0.5 * (a_ + b_), alpha) * np.cos(0.5 * np.abs(a_ - b_)) / den
    return np.where(valid, f, 0.0)


def pdf_ggx(phi_o: Any, phi_i: Any, normal_angle: Any, alpha: Any) -> Any:
    r"""Density per radian of :func:`sample_ggx`'s ``phi_o`` given ``phi_i``: $D_a(θ_h) / 2$.

    With $G_1 = 2 \cos a / (\cos a + r_a)$ this is $\cos((a - b) / 2) D(θ_h) / (\cos a + r_a)$, for
    visible normals above the surface ($|θ_h| < π/2$, $|a - θ_h| < π/2$) and $|a| < π/2$, else 0.
    A density on the whole circle: a sample below the surface (f = 0 there) has its density too.
    """
    alpha = check_alpha(alpha)
    a, b = wrap_angle(phi_i - normal_angle), wrap_angle(phi_o - normal_angle)
    ca = np.cos(a)
    da, db = detach(a), detach(b)
    valid = (detach(ca) > 0.0) & (np.abs(da + db) < np.pi) & (np.abs(da - db) < np.pi)
    a_, b_ = np.where(valid, a, 0.0), np.where(valid, b, 0.0)
    ca = np.where(valid, ca, 1.0)
    p = np.cos(0.5 * np.abs(a_ - b_)) * _ndf(0.5 * (a_ + b_), alpha) / (ca + smith_root(ca, alpha))
    return np.where(valid, p, 0.0)


def weight_ggx(phi_i: Any, phi_o: Any, normal_angle: Any, alpha: Any, albedo: Any) -> Any:
    r"""The sample weight $f(a, b) \cos b / p(b)$ of :func:`sample_ggx`, in closed form.

    $F G_2 / G_1(a) = F \cos b (\cos a + r_a) / (r_a \cos b + r_b \cos a)$: D cancels, so the weight
    is smooth, at most F, and never 0/0. 0 where either direction lies on or below the surface.
    """
    alpha, albedo = check_alpha(alpha), check_albedo(albedo)
    ca, cb = np.cos(wrap_angle(phi_i - normal_angle)), np.cos(wrap_angle(phi_o - normal_angle))
    valid = (detach(ca) > 0.0) & (detach(cb) > 0.0)
    ra, rb = smith_root(ca, alpha), smith_root(cb, alpha)
    den = np.where(valid, ra * cb + rb * ca, 1.0)
    return np.where(valid, albedo * cb * (ca + ra) / den, 0.0)


def sample_ggx(u: np.ndarray, phi_i: Any, normal_angle: Any, alpha: Any) -> np.ndarray:
    r"""Angles ``phi_o`` reflected about visible microfacet normals, by the inverse CDF of ``u`` in [0, 1).

    Heitz 2018's stretch ("Sampling the GGX Distribution of Visible Normals", JCGT 7(4)) in the
    plane: scaling the profile's height by 1/α maps it to α = 1, directions as
    $(\sin a, \cos a) → (α \sin a, \cos a)$ and normals back as $(\sin θ, \cos θ) → (α \sin θ, \cos θ)$
    (normalized). At α = 1, D = 1/2 is constant and the visible normals from the stretched
    angle a' have density $∝ \cos(θ - a')$ on $|θ| < π/2$, $|θ - a'| < π/2$: uniform in
    $p = \sin(θ - a')$ between -1 and $\cos a'$ (a' >= 0; mirrored for a' < 0), so
    $θ = a' + \arcsin(p)$. Then $b = 2 θ_h - a$; the density is :func:`pdf_ggx`. Returns
    $φ_n + b$, plain. Rows with ``phi_i`` on or below the surface sample as at grazing incidence
    (their f and density are 0).
    """
    alpha = np.asarray(detach(check_alpha(alpha)), dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    normal_angle = np.asarray(detach(normal_angle), dtype=np.float64)
    a = np.clip(
        wrap_angle(np.asarray(detach(phi_i), dtype=np.float64) - normal_angle), -0.5 * np.pi, 0.5 * np.pi
    )
    a_std = np.arctan2(alpha * np.sin(a), np.cos(a))  # stretched to α = 1
    lo = np.where(a_std >= 0.0, -1.0, -np.cos(a_std))
    hi = np.where(a_std >= 0.0, np.cos(a_std), 1.0)
    theta_std = a_std + np.arcsin(np.clip(lo + u * (hi - lo), -1.0, 1.0))
    theta_h = np.arctan2(alpha * np.sin(theta_std), np.cos(theta_std))  # unstretched normal
    return normal_angle + (2.0 * theta_h - a)


def albedo_ggx(cos_theta: Any, alpha: Any, albedo: Any = 1.0, nodes: int = 12) -> np.ndarray:
    r"""Directional albedo $A(a) = ∫ f(a, b) \cos b\, db$ by Gauss–Legendre quadrature in $θ_h$.

    With $db = 2 dθ_h$, $A = ∫ F G_2 \cos(a - θ_h) / (\cos a \cos θ_h) D(θ_h) \cos θ_h dθ_h$ over
    $θ_h ∈ ((a - π/2) / 2, (a + π/2) / 2)$, where the reflection lies above the surface. The
    middle halves of that interval are integrated in ψ with $\tan θ_h = α \tan ψ$, where
    $D \cos θ_h dθ_h = \cos ψ dψ / 2$ (the nodes follow D for every α), the outer quarters in
    $θ_h$; each piece's panels are graded towards its outer end,
    $\log_2(1 / \min(\cos a, α)) + 4$ levels (the features there have the scales $\cos a$ and α,
    as in :func:`sphere3d.bsdf.albedo_ggx`), so the rule converges geometrically in ``nodes``
    per panel. A depends on $|a|$ only: plain floats, broadcast over ``cos_theta`` in (0, 1],
    ``alpha`` and ``albedo``.
    """
    alpha = np.asarray(detach(check_alpha(alpha)), dtype=np.float64)
    albedo = np.asarray(detach(check_albedo(albedo)), dtype=np.float64)
    nodes = check_int("nodes", nodes, minimum=2)
    ca = check_cos_theta(cos_theta)
    levels = int(np.ceil(np.log2(1.0 / min(np.min(ca), np.min(alpha))))) + 4
    ca, alpha, albedo = (v[..., None] for v in np.broadcast_arrays(ca, alpha, albedo))
    a = np.arccos(ca)
    ends = (0.5 * (a - 0.5 * np.pi), 0.5 * (a + 0.5 * np.pi))  # θ_h at b = -π/2 and b = π/2
    thetas, masses = [], []
    for end in ends:
        # middle: ψ from 0 to ψ(end / 2), D cos θ dθ = cos ψ dψ / 2
        psi, dpsi = graded_gauss(0.0, np.arctan(np.tan(0.5 * end[..., 0]) / alpha[..., 0]), nodes, levels)
        thetas.append(np.arctan(alpha * np.tan(psi)))
        masses.append(0.5 * np.cos(psi) * dpsi)
        # outer: θ_h from end / 2 to end
        theta, dtheta = graded_gauss(0.5 * end[..., 0], end[..., 0], nodes, levels)
        thetas.append(theta)
        masses.append(_ndf(theta, alpha) * np.cos(theta) * dtheta)
    theta, mass = thetas[0], masses[0]
    for t, m in zip(thetas[1:], masses[1:], strict=True):
        theta, mass = join_last(theta, t), join_last(mass, m)
    cb = np.maximum(np.cos(2.0 * theta - a), 0.0)
    g2_over_ca = 2.0 * cb / (smith_root(ca, alpha) * cb + smith_root(cb, alpha) * ca)
    return np.sum(albedo * g2_over_ca * np.cos(a - theta) / np.cos(theta) * mass, axis=-1)
