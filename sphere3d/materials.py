r"""A shape's material keys, checked: albedo, emission, border fade, smooth shading and roughness.

A shape is diffuse (Lambertian, reflectance ``albedo``, BRDF $ρ/π$) unless it carries ``roughness``
α > 0: then it is a rough conductor, the GGX microfacet BSDF of :mod:`sphere3d.bsdf` with Fresnel
reflectance F = ``albedo`` at every angle (theory/bsdf). α = 0, a perfect mirror, is a delta BSDF:
it has no integral for MIS to sample or for a method to reparameterize, and is refused.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from flatland.core.microfacet import ALPHA_MAX
from flatland.core.validate import ValidationError, check_bool, check_finite, check_positive
from sphere3d import shapes as shp

__all__ = ["check_roughness", "check_unit_interval", "materials"]


def check_unit_interval(field: str, value: Any) -> float:
    """``value`` as a finite float in [0, 1]; one ValidationError naming ``field`` otherwise."""
    out = check_finite(field, value)
    if not 0.0 <= out <= 1.0:
        raise ValidationError(field, f"must lie in [0, 1], got {value!r}")
    return out


def check_roughness(field: str, value: Any) -> float | None:
    """A glossy shape's GGX α in (0, ALPHA_MAX] as a float (None: no roughness, a diffuse shape); one
    ValidationError naming ``field`` otherwise, saying why 0 (a perfect mirror) is refused."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not 0.0 < value <= ALPHA_MAX:
        raise ValidationError(
            field,
            f"must be a number in (0, {ALPHA_MAX}] (a glossy surface's GGX alpha; 0 is a perfect mirror, "
            f"a delta BSDF with no integral to sample by MIS or to reparameterize: not supported), "
            f"got {value!r}",
        )
    return float(value)


def materials(field: str, d: Mapping[str, Any], mesh: shp.LocalMesh) -> dict[str, Any]:
    """The checked material keys of shape ``field`` (``d`` with the defaults filled in) as
    :class:`~sphere3d.scene.Shape` keyword arguments."""
    fade = check_unit_interval(f"{field}.fade", d["fade"])
    if fade > 0.0 and mesh.fade_kind == shp.FADE_NONE:
        raise ValidationError(
            f"{field}.fade", f"is only defined for rectangle and disk emitters, got {fade!r}"
        )
    if fade >= 1.0 and mesh.fade_kind != shp.FADE_NONE:
        raise ValidationError(f"{field}.fade", f"must be < 1, got {fade!r}")
    return {
        "albedo": check_unit_interval(f"{field}.albedo", d["albedo"]),
        "emission": check_positive(f"{field}.emission", d["emission"], allow_zero=True),
        "fade": fade,
        "smooth": check_bool(f"{field}.smooth", d["smooth"]),
        "roughness": check_roughness(f"{field}.roughness", d.get("roughness")),
    }
