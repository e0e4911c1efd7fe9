"""World-space geometry the float tracer and the normals can represent: :func:`check_world`.

Shapes are validated in their local coordinates (:mod:`sphere3d.scene`); a scene state
(:func:`sphere3d.state.build_state`) places them in world space, where translate, rotate and scale
can still push a vertex beyond Embree's float32 range or collapse a triangle.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flatland.core.dual import detach
from flatland.core.validate import ValidationError
from sphere3d.scene import Scene
from sphere3d.vector import cross, norm

__all__ = ["COORD_MAX", "check_world"]

COORD_MAX = 1e18
"""Largest |coordinate| of a world-space vertex or ray origin. Embree traces in float32, and
its ray–triangle test multiplies two coordinate differences, which must stay below float32's
3.4e38: |x| < 1.8e19; a factor 18 of margin (1e18² · 4 = 4e36)."""


def check_world(
    scene: Scene,
    param: str | None,
    theta: Any,
    triangles: np.ndarray,
    shape_of: np.ndarray,
    origin: np.ndarray,
) -> None:
    """Refuse world-space geometry the float tracer and normals cannot represent (one ValidationError).

    Shapes are validated in their local coordinates; translate, rotate and scale can
    still make a triangle collapse in world space: scaled by 1e-13 and placed at
    x = 600, where float64 coordinates are 1.1e-13 apart, its vertices round to one
    point, and its unit normal would be 0/0. Every world triangle must have a nonzero
    $|e_1 × e_2|$ (the very expression its normal is divided by), and every vertex and
    the camera must lie within ±:data:`COORD_MAX`.

    Parameters
    ----------
    triangles : ndarray, shape (T, 3, 3)
        Detached world-space vertices; ``shape_of`` (T,) their shapes.
    origin : ndarray, shape (3,)
        The detached camera position.
    """
    names = param if isinstance(param, tuple) else (param,)
    offsets = theta if isinstance(theta, tuple | list) else (theta,) * len(names)
    # nonzero only for finite differences' θ = ±h
    moved = [(p, float(np.asarray(detach(t)))) for p, t in zip(names, offsets, strict=True) if p]
    where = ", ".join(f"{p} offset by {t!r}" for p, t in moved if t != 0.0)
    where = f" (with {where})" if where else ""
    reach = np.max(np.abs(triangles), axis=(1, 2))
    far = ~(reach <= COORD_MAX)  # also catches non-finite coordinates
    if far.any():
        i = int(shape_of[np.argmax(far)])
        top = float(np.max(reach[shape_of == i]))
        raise ValidationError(
            f"shapes[{i}]",
            f"{scene.shapes[i].name!r} reaches |coordinate| {top:.3g} in world space{where}; "
            f"coordinates must lie within ±{COORD_MAX:g} (rays are traced in float32)",
        )
    if not np.all(np.abs(origin) <= COORD_MAX):
        raise ValidationError(
            "camera.position",
            f"is {list(map(float, origin))} in world space{where}; "
            f"coordinates must lie within ±{COORD_MAX:g} (rays are traced in float32)",
        )
    area2 = norm(cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]))
    flat = ~(area2 > 0.0)
    if flat.any():
        t = int(np.argmax(flat))
        i = int(shape_of[t])
        s, k = scene.shapes[i], t - int(np.argmax(shape_of == i))
        raise ValidationError(
            f"shapes[{i}]",
            f"triangle {k} of {s.name!r} has zero area in world space{where}: "
            f"its vertices round together (or its size squared underflows) at scale {s.scale!r} and "
            f"translate {list(s.translate)}; "
            "enlarge the shape or move it nearer the origin",
        )
