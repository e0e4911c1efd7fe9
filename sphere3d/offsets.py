"""A scene's parameter offsets: checked on load, added to by :func:`sphere3d.state.moved_scene`.

A scene's ``offsets`` (:mod:`sphere3d.scene`) are applied where its state is built
(:func:`sphere3d.state.build_state`): the scene as rendered is the scene as written moved by
them. A parameter that the scene offsets and that is also differentiated gets the sum of both in
one slot, so a gradient at a moved scene is the gradient at those offsets, for every parameter.
The scene is a :class:`sphere3d.scene.Scene` (which imports this module to check its offsets).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from flatland.core.validate import ValidationError, check_finite

__all__ = ["check_offsets"]


def check_offsets(scene: Any, offsets: Any, field: str = "offsets") -> tuple[tuple[str, float], ...]:
    """A mapping (or pairs) from parameter names to finite offsets, checked against ``scene``: one
    ValidationError naming ``field`` when a name is unknown, or the offsets leave an albedo outside
    [0, 1], an emission (or the sky) below 0, a roughness at or below 0 or a scale factor $1 + θ$ at or
    below 0."""
    pairs = list(offsets.items()) if isinstance(offsets, Mapping) else offsets
    if not isinstance(pairs, list | tuple) or not all(
        isinstance(p, list | tuple) and len(p) == 2 for p in pairs
    ):
        raise ValidationError(field, f"must map parameter names to offsets, got {offsets!r}")
    out = []
    for name, value in pairs:
        if not isinstance(name, str) or name not in scene.parameters:
            raise ValidationError(
                field, f"unknown parameter {name!r}; see `python -m sphere3d gradient SCENE`"
            )
        theta = check_finite(f"{field}[{name!r}]", value)
        owner, _, kind = name.partition(".")
        base = scene.sky if owner == "sky" else None
        if owner not in ("sky", "camera"):
            base = scene.shapes[scene.shape_index(owner)]
        if kind == "albedo" and not 0.0 <= base.albedo + theta <= 1.0:
            raise ValidationError(
                field, f"{name} = {theta!r} leaves the albedo {base.albedo + theta!r}, not in [0, 1]"
            )
        if kind == "emission" and (base if owner == "sky" else base.emission) + theta < 0.0:
            raise ValidationError(field, f"{name} = {theta!r} leaves the emission below 0")
        if kind == "roughness" and not base.roughness + theta > 0.0:
            raise ValidationError(
                field, f"{name} = {theta!r} leaves the roughness {base.roughness + theta!r} <= 0 (a mirror)"
            )
        if kind == "scale" and not 1.0 + theta > 0.0:
            raise ValidationError(field, f"{name} = {theta!r} makes the scale factor 1 + θ <= 0")
        out.append((name, theta))
    names = [n for n, _ in out]
    if len(set(names)) != len(names):
        raise ValidationError(field, f"names each parameter once, got {names}")
    return tuple(out)
