r"""The glossy BSDF: a rough conductor with GGX (Trowbridge–Reitz) microfacets, as eval / sample / pdf.

Directions are unit vectors (..., 3) pointing away from the surface: ``wi`` the given one (in a
path, the direction back towards the camera or the previous vertex), ``wo`` the one sampled or
evaluated; ``n`` is the unit shading normal (one (3,) or one per row). The BSDF only reflects:

$f(w_i, w_o) = F D(h) G_2(w_i, w_o) / (4 (n·w_i)(n·w_o))$ with $h = (w_i + w_o) / |w_i + w_o|$

where both directions lie above the surface ($n·w_i > 0$, $n·w_o > 0$), and 0 elsewhere, with

- D the isotropic GGX distribution of normals of roughness α,
  $D(h) = α^2 / (π ((n·h)^2 (α^2 - 1) + 1)^2)$, normalized as $∫ D(h) (n·h) dω_h = 1$;
- $G_2$ Smith's height-correlated masking-shadowing (:func:`~flatland.core.microfacet.smith_g2`);
- $F$ = ``albedo``, a constant Fresnel reflectance: a conductor whose reflectance does not depend
  on the angle (F = 1 reflects all the light the microfacets see; no Schlick term).

:func:`eval_ggx` returns f itself, without the cosine: the reflected radiance is
$∫ L(w_o) f(w_i, w_o) (n·w_o) dω_o$. Densities are per steradian. Reciprocity
$f(w_i, w_o) = f(w_o, w_i)$ holds bit for bit. The directional albedo $∫ f (n·w_o) dω_o$ is at most
F, and below it by the energy of the light that meets a second microfacet, which a
single-scattering model drops (:func:`albedo_ggx`). Theory and the reason a perfect mirror
(α = 0, a delta BSDF) is refused: theory/bsdf.

α and ``albedo`` may be Duals (scene parameters), and so may the directions and the normal in
:func:`eval_ggx`, :func:`pdf_ggx` and :func:`weight_ggx`; :func:`sample_ggx` draws plain
directions from detached values, a θ-free density as every sampler of the renderer.
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
from sphere3d.vector import dot, frame

__all__ = ["albedo_ggx", "eval_ggx", "pdf_ggx", "sample_ggx", "weight_ggx"]


def _ndf(wi: Any, wo: Any, n: Any, alpha: Any) -> tuple[Any, Any, Any, Any]:
    r"""$(c_i, c_o, n·H, D(h))$ with $H = w_i + w_o$ unnormalized.

    $D = α^2 |H|^4 / (π (t^2 + α^2 (n·H)^2)^2)$ where $t^2 = |H - (n·H) n|^2$ is H's tangential part:
    the textbook form divided through by $|H|^4$, with the sine of h's angle taken from the
    tangential part (no $1 - \cos^2$ cancellation for small α). Where $n·H <= 0$ D is returned
    at a safe denominator; callers mask it.
    """
    ci, co = dot(wi, n), dot(wo, n)
    h = wi + wo
    nh = ci + co  # = n·H, symmetric in the pair
    tangential = h - nh[..., None] * n
    t2, h2 = dot(tangential, tangential), dot(h, h)
    a2 = alpha * alpha
    den = t2 + a2 * nh * nh
    den = np.where(detach(den) > 0.0, den, 1.0)
    return ci, co, nh, a2 * (h2 * h2) / (np.pi * (den * den))


def eval_ggx(wi: Any, wo: Any, n: Any, alpha: Any, albedo: Any) -> Any:
    r"""The BSDF $f(w_i, w_o)$ per steradian, without the cosine factor (module docstring).

    Written as $F D / (2 (r_i c_o + r_o c_i))$ ($G_2 / (4 c_i c_o)$ simplified, with Smith's roots
    r), finite up to grazing angles; symmetric in ``wi`` and ``wo`` bit for bit. 0 where either
    direction lies on or below the surface.
    """
    alpha, albedo = check_alpha(alpha), check_albedo(albedo)
    ci, co, _, d = _ndf(wi, wo, n, alpha)
    valid = (detach(ci) > 0.0) & (detach(co) > 0.0)
    den = smith_root(ci, alpha) * co + smith_root(co, alpha) * ci
    den = np.where(valid, den, 1.0)
    return np.where(valid, albedo * d / (2.0 * den), 0.0)


def pdf_ggx(wo: Any, wi: Any, n: Any, alpha: Any) -> Any:
    r"""Density per steradian of :func:`sample_ggx`'s ``wo`` given ``wi``: $D_{w_i}(h) / (4 |w_i·h|)$.

    The visible normals' density is $D_{w_i}(h) = G_1(w_i) \max(0, w_i·h) D(h) / (n·w_i)$ (Heitz
    2018), and reflecting about h maps $dω_h$ to $dω_o = 4 |w_i·h| dω_h$. The two $w_i·h$
    cancel and, with $G_1 = 2 c_i / (c_i + r_i)$, the density is $D(h) / (2 (c_i + r_i))$. It is
    a density on the whole sphere: a sample below the surface (f = 0 there) has its density too.
    0 where ``wi`` lies on or below the surface or h does ($n·(w_i + w_o) <= 0$).
    """
    alpha = check_alpha(alpha)
    ci, _, nh, d = _ndf(wi, wo, n, alpha)
    valid = (detach(ci) > 0.0) & (detach(nh) > 0.0)
    ci_safe = np.where(valid, ci, 1.0)
    return np.where(valid, d / (2.0 * (ci_safe + smith_root(ci_safe, alpha))), 0.0)


def weight_ggx(wi: Any, wo: Any, n: Any, alpha: Any, albedo: Any) -> Any:
    r"""The sample weight $f(w_i, w_o) (n·w_o) / p(w_o)$ of :func:`sample_ggx`, in closed form.

    $F G_2 / G_1(w_i) = F c_o (c_i + r_i) / (r_i c_o + r_o c_i)$: D cancels, so the weight is
    smooth, at most F, and never 0/0. 0 where either direction lies on or below the surface.
    """
    alpha, albedo = check_alpha(alpha), check_albedo(albedo)
    ci, co = dot(wi, n), dot(wo, n)
    valid = (detach(ci) > 0.0) & (detach(co) > 0.0)
    ri, ro = smith_root(ci, alpha), smith_root(co, alpha)
    den = np.where(valid, ri * co + ro * ci, 1.0)
    return np.where(valid, albedo * co * (ci + ri) / den, 0.0)


def sample_ggx(u: np.ndarray, wi: Any, n: Any, alpha: Any) -> np.ndarray:
    r"""Directions ``wo`` reflected about visible GGX normals (Heitz 2018), from uniforms ``u`` (..., 2).

    Heitz 2018 ("Sampling the GGX Distribution of Visible Normals", JCGT 7(4)): stretching the
    surface by 1/α maps it to α = 1, whose visible normals seen from the stretched $w_i$ are
    sampled, then unstretched ($h ∝ (α x, α y, z)$). At α = 1 they are drawn by the spherical
    cap of Dupuy and Benyoub 2023 ("Sampling Visible GGX Normals with Spherical Caps", HPG 2023):
    a direction c uniform on the cap $z >= -v_z$ of the unit sphere, $h ∝ c + v$. Then
    $w_o = 2 (w_i·h) h - w_i$; its density is :func:`pdf_ggx`. Plain arrays from detached
    inputs. Rows with ``wi`` on or below the surface sample as at normal incidence (their
    f and density are 0).
    """
    alpha = np.asarray(detach(check_alpha(alpha)), dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    wi, n = np.asarray(detach(wi), dtype=np.float64), np.asarray(detach(n), dtype=np.float64)
    t, b = frame(n)
    above = dot(wi, n) > 0.0
    # wi in the frame (t, b, n), stretched to α = 1: v ∝ (α x, α y, z)
    vx = np.where(above, alpha * dot(wi, t), 0.0)
    vy = np.where(above, alpha * dot(wi, b), 0.0)
    vz = np.where(above, dot(wi, n), 1.0)
    length = np.sqrt(vx * vx + vy * vy + vz * vz)
    vx, vy, vz = vx / length, vy / length, vz / length
    # c uniform on the cap z >= -v_z: z uniform in (-v_z, 1], azimuth uniform
    z = (1.0 - u[..., 0]) * (1.0 + vz) - vz
    s = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    phi = 2.0 * np.pi * u[..., 1]
    # unstretch the normal c + v: tangential components times α
    hx, hy, hz = alpha * (s * np.cos(phi) + vx), alpha * (s * np.sin(phi) + vy), np.maximum(z + vz, 0.0)
    length = np.sqrt(hx * hx + hy * hy + hz * hz)
    flat = length == 0.0  # c = -v exactly: only when u rounds to the cap's rim; take h = n
    length = np.where(flat, 1.0, length)
    hz = np.where(flat, 1.0, hz)
    h = (hx / length)[..., None] * t + (hy / length)[..., None] * b + (hz / length)[..., None] * n
    return 2.0 * dot(wi, h)[..., None] * h - wi


def albedo_ggx(cos_theta: Any, alpha: Any, albedo: Any = 1.0, nodes: int = 12) -> np.ndarray:
    r"""Directional albedo $A(θ_i) = ∫ f(w_i, w_o) (n·w_o) dω_o$ by Gauss–Legendre quadrature in h.

    In the half vector, $dω_o = 4 (w_i·h) dω_h$ and $A = ∫ F G_2 (w_i·h) / (c_i \cos θ_h) D \cos θ_h dω_h$.
    For the azimuth φ of h (from $w_i$'s), $n·w_o = R \cos(2 θ_h - δ)$ with $\tan δ = \tan θ_i \cos φ$:
    the reflection lies above the surface exactly for $θ_h < θ_{max} = (δ + π/2) / 2$, so each φ
    integrates a smooth function up to its own horizon. $[0, θ_{max}]$ is split at its middle: the
    lower half in ψ with $\tan θ_h = α \tan ψ$, where $D \cos θ_h dω_h = \sin 2ψ dψ dφ / 2π$ (the
    nodes follow D for every α), the upper half in $θ_h$. Near grazing incidence two features
    have the scale $c_i$: $G_2 / c_i ≈ 2 c_o / (α c_o + r_o c_i)$ rises within $c_o ≲ c_i$ of the
    horizon, and $θ_{max}$ turns from π/2 to 0 within $|φ - π/2| ≲ c_i / s_i$; for small α, $θ_h(ψ)$
    turns within α of $ψ = π/2$. Each half's panels are graded towards its upper end and φ's towards
    π/2, $\log_2(1 / \min(c_i, α)) + 4$ levels, so the rule converges geometrically in ``nodes``
    (per panel) at every incidence and roughness. φ runs over [0, π] (the
    mirror half doubles it). Plain floats, broadcast over ``cos_theta`` in (0, 1], ``alpha`` and
    ``albedo``.
    """
    alpha = np.asarray(detach(check_alpha(alpha)), dtype=np.float64)
    albedo = np.asarray(detach(check_albedo(albedo)), dtype=np.float64)
    nodes = check_int("nodes", nodes, minimum=2)
    c = check_cos_theta(cos_theta)
    levels = int(np.ceil(np.log2(1.0 / min(np.min(c), np.min(alpha))))) + 4
    c, alpha, albedo = (v[..., None, None] for v in np.broadcast_arrays(c, alpha, albedo))
    s = np.sqrt(np.maximum(1.0 - c * c, 0.0))
    left, w_left = graded_gauss(0.0, 0.5 * np.pi, nodes, levels)
    phi = np.concatenate([left, np.pi - left])[:, None]  # (φ nodes, 1)
    w_phi = np.concatenate([w_left, w_left])
    top = 0.5 * (np.arctan2(s * np.cos(phi), c) + 0.5 * np.pi)  # θ_max for each φ
    # lower half: ψ in (0, ψ_1), ξ = sin² ψ, dξ = sin 2ψ dψ
    psi_1 = np.arctan(np.tan(0.5 * top) / alpha)
    psi, dpsi = graded_gauss(0.0, psi_1[..., 0], nodes, levels)
    theta_low = np.arctan(alpha * np.tan(psi))
    mass_low = np.sin(2.0 * psi) * dpsi
    # upper half: θ_h in (θ_max / 2, θ_max),
    # dξ = 2π D cos θ sin θ dθ = 2 α² cos θ sin θ / (α² cos² θ + sin² θ)² dθ
    theta_high, dtheta = graded_gauss(0.5 * top[..., 0], top[..., 0], nodes, levels)
    ch, sh = np.cos(theta_high), np.sin(theta_high)
    a2 = alpha * alpha
    mass_high = 2.0 * a2 * ch * sh / (a2 * ch * ch + sh * sh) ** 2 * dtheta
    theta, mass = join_last(theta_low, theta_high), join_last(mass_low, mass_high)
    cos_h, sin_h = np.cos(theta), np.sin(theta)
    wih = s * sin_h * np.cos(phi) + c * cos_h  # w_i·h with w_i = (s, 0, c)
    co = np.maximum(2.0 * wih * cos_h - c, 0.0)  # n·w_o, w_o = 2 (w_i·h) h - w_i
    g2_over_ci = 2.0 * co / (smith_root(c, alpha) * co + smith_root(co, alpha) * c)
    inner = np.sum(albedo * g2_over_ci * wih / cos_h * mass, axis=-1)  # ∫ ... dξ at each φ
    # over the half [0, π], doubled by the mirror half, over 2π
    return (inner @ w_phi) / np.pi
