r"""The parts of the GGX (Trowbridge–Reitz) microfacet model that do not depend on the dimension.

Both glossy BSDFs, :mod:`flatland.bsdf` (a profile in the plane) and :mod:`sphere3d.bsdf` (a
surface in space), describe a surface whose slopes along any direction of its tangent plane
follow the same law, the 1D marginal of GGX's slope distribution,
$P_2(x) = α^2 / (2 (α^2 + x^2)^{3/2})$ with the roughness α. Smith's masking term depends only on
that marginal (the ratio of a direction's shadowed to its visible length is a 1D integral in its
plane of incidence), so both share it:

- $Λ(θ) = (\sqrt{1 + α^2 \tan^2 θ} - 1) / 2$ for a direction at angle θ from the normal,
  written through the root $r(c) = \sqrt{α^2 + c^2 (1 - α^2)}$ of $c = \cos θ$:
  $Λ = (r / c - 1) / 2$, which is finite at grazing angles and free of cancellation for small α;
- the masking of one direction, $G_1 = 1 / (1 + Λ) = 2c / (c + r)$;
- the height-correlated masking-shadowing of a pair (Heitz 2014, "Understanding the
  Masking-Shadowing Function in Microfacet-Based BRDFs", JCGT 3(2)),
  $G_2 = 1 / (1 + Λ_i + Λ_o) = 2 c_i c_o / (r_i c_o + r_o c_i)$, symmetric in the pair.

The checks of the two scene parameters live here too: the roughness α in (0, :data:`ALPHA_MAX`]
and the albedo (the constant Fresnel reflectance F) in [0, 1]. α = 0 is a perfect mirror, a
delta BSDF: its reflection integral has no integrand to evaluate, only one direction, so there
is nothing for a change of variables to reparameterize (theory/bsdf); it is refused.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flatland.core.dual import detach
from flatland.core.validate import ValidationError

__all__ = [
    "ALPHA_MAX",
    "check_albedo",
    "check_alpha",
    "check_cos_theta",
    "graded_gauss",
    "join_last",
    "smith_g1",
    "smith_g2",
    "smith_root",
]

ALPHA_MAX = 1.0
"""Largest roughness accepted. At α = 1 the GGX surface is, after Heitz's stretch, made of
hemispherical (3D) or semicircular (2D) bumps, the roughest of the usual range; beyond it the
single-scattering model loses more and more energy to the bounces it leaves out."""


def _values(value: Any) -> np.ndarray:
    """The float values of a number, an array or a Dual, for a range check."""
    try:
        return np.asarray(detach(value), dtype=np.float64)
    except (TypeError, ValueError):
        return np.asarray(np.nan)


def _first_bad(values: np.ndarray, good: np.ndarray) -> float:
    return float(values[~good].ravel()[0]) if values.ndim else float(values)


def check_alpha(alpha: Any, field: str = "alpha") -> Any:
    """``alpha`` unchanged (a float, an array or a Dual) if every value lies in (0, :data:`ALPHA_MAX`].

    Raises
    ------
    ValidationError
        Naming ``field`` and the first bad value: α <= 0 is a delta BSDF (a perfect mirror),
        refused because it has no integral to reparameterize; α > ALPHA_MAX is outside the
        model's range; NaN and infinities are refused too.
    """
    values = _values(alpha)
    if values.size == 0:
        raise ValidationError(field, "needs at least one value, got an empty array")
    if np.all(values > 0.0) and np.all(values <= ALPHA_MAX):  # False for NaN
        return alpha
    bad = _first_bad(values, (values > 0.0) & (values <= ALPHA_MAX))
    if bad <= 0.0:
        raise ValidationError(
            field,
            f"must be > 0, got {bad!r}: a roughness of 0 is a perfect mirror, a delta BSDF, whose "
            "reflection is one direction and not an integral, so there is no integral to reparameterize",
        )
    raise ValidationError(field, f"must be a roughness in (0, {ALPHA_MAX:g}], got {bad!r}")


def check_albedo(albedo: Any, field: str = "albedo") -> Any:
    """``albedo`` unchanged (a float, an array or a Dual) if every value lies in [0, 1].

    The albedo is the constant Fresnel reflectance F of the glossy BSDFs; above 1 the surface
    would reflect more than it receives.
    """
    values = _values(albedo)
    good = (values >= 0.0) & (values <= 1.0)
    if values.size == 0 or not np.all(good):
        bad = "an empty array" if values.size == 0 else repr(_first_bad(values, good))
        raise ValidationError(field, f"must be in [0, 1], got {bad}")
    return albedo


def smith_root(cos_theta: Any, alpha: Any) -> Any:
    r"""$r = \sqrt{α^2 + c^2 (1 - α^2)}$ for $c = \cos θ$, the root in Smith's $Λ = (r / c - 1) / 2$.

    Dual-aware in both arguments.
    """
    a2 = alpha * alpha
    return np.sqrt(a2 + cos_theta * cos_theta * (1.0 - a2))


def smith_g1(cos_theta: Any, alpha: Any) -> Any:
    """Smith's masking of one direction, $G_1 = 2c / (c + r)$ (0 at c = 0); Dual-aware, for c >= 0."""
    return 2.0 * cos_theta / (cos_theta + smith_root(cos_theta, alpha))


def smith_g2(cos_i: Any, cos_o: Any, alpha: Any) -> Any:
    r"""Height-correlated masking-shadowing $G_2 = 2 c_i c_o / (r_i c_o + r_o c_i)$, for $c_i, c_o > 0$.

    Dual-aware. The same numbers with the pair swapped, bit for bit (each product and the sum
    are commutative).
    """
    return 2.0 * (cos_i * cos_o) / (smith_root(cos_i, alpha) * cos_o + smith_root(cos_o, alpha) * cos_i)


def check_cos_theta(cos_theta: Any, field: str = "cos_theta") -> np.ndarray:
    """The plain values of ``cos_theta`` if all lie in (0, 1]: an incidence strictly above the surface."""
    values = _values(cos_theta)
    good = (values > 0.0) & (values <= 1.0)
    if values.size == 0 or not np.all(good):
        bad = "an empty array" if values.size == 0 else repr(_first_bad(values, good))
        raise ValidationError(field, f"must be in (0, 1], got {bad}")
    return values


def graded_gauss(lo: Any, hi: Any, nodes: int, levels: int) -> tuple[np.ndarray, np.ndarray]:
    r"""Gauss–Legendre nodes and weights from ``lo`` to ``hi``, in panels graded towards ``hi``.

    Panel edges $lo + (hi - lo)(1 - 2^{-k})$, k = 0..levels, then hi; ``nodes`` points per panel.
    A function analytic but for a near singularity at distance d beyond ``hi`` is integrated
    with geometric convergence in ``nodes`` once $2^{-levels} |hi - lo| ≲ d$, where one rule over
    the whole interval would converge only as fast as d allows. ``lo`` may exceed ``hi`` (the
    weights are positive either way); ``lo``, ``hi`` broadcast, and the panels times their nodes
    form a new last axis of both results.
    """
    x, w = np.polynomial.legendre.leggauss(nodes)
    unit, w = 0.5 * (x + 1.0), 0.5 * w  # a rule on (0, 1)
    lo, hi = np.asarray(lo, dtype=np.float64)[..., None], np.asarray(hi, dtype=np.float64)[..., None]
    edges = lo + (hi - lo) * np.append(1.0 - 0.5 ** np.arange(levels + 1), 1.0)
    width = np.diff(edges, axis=-1)[..., None]
    points = edges[..., :-1, None] + width * unit
    weights = np.abs(width) * w
    return points.reshape(*points.shape[:-2], -1), weights.reshape(*weights.shape[:-2], -1)


def join_last(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a`` and ``b`` side by side on the last axis, their other axes broadcast (two quadrature pieces)."""
    lead = np.broadcast_shapes(a.shape[:-1], b.shape[:-1])
    return np.concatenate(
        [np.broadcast_to(a, (*lead, a.shape[-1])), np.broadcast_to(b, (*lead, b.shape[-1]))], -1
    )
