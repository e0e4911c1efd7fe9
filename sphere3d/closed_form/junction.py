r"""The camera image of a moving black triangle across the edge of a static one: two T-junctions.

A black triangle M (albedo 0, emission 0) moves in front of a static black triangle S under a
constant sky L; on the film M's slanted edges cross S's top edge, so each of those crossings
is a junction of a moving and a static discontinuity (:mod:`sphere3d.reparam.junctions`). A camera ray
sees radiance 0 on either triangle and L elsewhere, so the pixel integral is

    $I(p) = L (1 - ∫_{M ∪ S} k(x - c_p) dx) = L (1 - ∫_M k - ∫_S k + ∫_{M ∩ S} k)$,

and, S being static, $dI/dθ = -L (d/dθ ∫_M k - d/dθ ∫_{M ∩ S} k)$. M ∩ S is M clipped by the
convex S (Sutherland–Hodgman) on Duals: a vertex where an edge of M crosses an edge of S is
$p + t (q - p)$, $t = e(p) / (e(p) - e(q))$ with e the signed distance to S's edge line,
so its tangent is the crossing's motion along S's edge, exactly. The clipped polygon's edges
on S's boundary then carry velocities along themselves (no flux), those on M's boundary M's own
(Reynolds transport, :func:`~sphere3d.closed_form.film.polygon_filter_derivative`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flatland.core.dual import Dual, detach, tangent, variable
from flatland.core.validate import ValidationError
from sphere3d.closed_form.film import (
    TriangleImage,
    polygon_filter_derivative,
    polygon_filter_integral,
    project,
    triangle_vertices,
)
from sphere3d.scene import load_scene

__all__ = ["clip_convex", "junction_image"]


def clip_convex(points: list[tuple[Any, Any]], clip: np.ndarray) -> list[tuple[Any, Any]]:
    """The polygon ``points`` (film (x, y) pairs, floats or Duals) clipped by the static convex polygon
    ``clip`` (W, 2): Sutherland–Hodgman, each crossing on Duals (module docstring); [] if disjoint."""
    clip = np.asarray(clip, dtype=np.float64)
    a, b = clip, np.roll(clip, -1, axis=0)
    area = np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1])
    orient = 1.0 if area > 0.0 else -1.0  # inside: e > 0 for either orientation
    out = list(points)
    for (ax, ay), (bx, by) in zip(a, b, strict=True):
        if not out:
            break

        def e(p: tuple[Any, Any], ax: float = ax, ay: float = ay, bx: float = bx, by: float = by) -> Any:
            return orient * ((bx - ax) * (p[1] - ay) - (by - ay) * (p[0] - ax))

        src, out = out, []
        for k, q in enumerate(src):
            p = src[k - 1]
            ep, eq = e(p), e(q)
            if (float(detach(ep)) >= 0.0) != (float(detach(eq)) >= 0.0):  # the edge p -> q crosses the line
                t = ep / (ep - eq)
                out.append((p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])))
            if float(detach(eq)) >= 0.0:
                out.append(q)
    return out


def _shape_scene(scene: Any, name: str) -> Any:
    """``scene`` with only its shape ``name`` (for :func:`~sphere3d.closed_form.film.triangle_vertices`)."""
    d = scene.to_dict()
    d["shapes"] = [s for s in d["shapes"] if s["name"] == name]
    return load_scene(d)


def junction_image(scene: Any, param: str | None = None) -> TriangleImage:
    """The exact image and dI/dθ of :func:`~sphere3d.closed_form.scenes.junction_scene` (module docstring).

    ``param`` moves the front triangle ``tri``; the static one is ``wall``. ``coverage`` is
    $∫_{M ∪ S} k$, ``vertices`` M's projected vertices.
    """
    scene = load_scene(scene)
    names = sorted(s.name for s in scene.shapes)
    if names != ["tri", "wall"]:
        raise ValidationError("scene.shapes", f"must be the triangles 'tri' and 'wall', got {names}")
    dual = variable(0.0) if param is not None else 0.0
    mx, my = project(scene.camera, triangle_vertices(_shape_scene(scene, "tri"), param, dual))
    sx, sy = project(scene.camera, triangle_vertices(_shape_scene(scene, "wall")))
    mx, my = (v if isinstance(v, Dual) else Dual(np.asarray(v, dtype=np.float64)) for v in (mx, my))
    wall = np.stack([np.asarray(detach(sx)), np.asarray(detach(sy))], axis=-1)
    front = [(mx[k], my[k]) for k in range(3)]
    both = clip_convex(front, wall)
    cam = scene.camera
    rows, cols = np.divmod(np.arange(cam.width * cam.height), cam.width)
    centres = np.stack([cols + 0.5, rows + 0.5], axis=-1)

    def film(polygon: list[tuple[Any, Any]]) -> tuple[np.ndarray, np.ndarray]:
        value = np.array([[float(detach(x)), float(detach(y))] for x, y in polygon])
        velocity = np.array([[float(tangent(x)), float(tangent(y))] for x, y in polygon])
        return value, velocity

    (m, m_dot), kind = film(front), cam.filter
    coverage = polygon_filter_integral(m, centres, kind) + polygon_filter_integral(wall, centres, kind)
    derivative = polygon_filter_derivative(m, m_dot, centres, kind)
    if len(both) >= 3:
        b, b_dot = film(both)
        coverage = coverage - polygon_filter_integral(b, centres, kind)
        derivative = derivative - polygon_filter_derivative(b, b_dot, centres, kind)
    shape = (cam.height, cam.width)
    return TriangleImage(
        value=scene.sky * (1.0 - coverage.reshape(shape)),
        derivative=-scene.sky * derivative.reshape(shape) + 0.0,
        coverage=coverage.reshape(shape),
        vertices=m,
    )
