"""The test scenes the closed forms are stated for, and the share of an exact derivative an
estimator misses."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core.validate import ValidationError

__all__ = [
    "PIXEL",
    "TRIANGLE_SHAPE",
    "ShareLost",
    "corner_junction_scene",
    "icosphere_scene",
    "junction_scene",
    "pinhole_triangle_scene",
    "share_lost",
    "sky_triangle_scene",
]

# ------------------------------------------------------------------ test scenes
PIXEL = 0.1
"""World size of one pixel at the depth of :func:`pinhole_triangle_scene`'s triangle (distance 4)."""
TRIANGLE_SHAPE = ((-0.5, -0.4, 0.0), (0.55, -0.3, 0.0), (0.05, 0.5, 0.0))
"""Local vertices of the test triangle, in units of its size: 1.05 × 0.9 across, no right angle."""


def pinhole_triangle_scene(size: float, width: int = 16, filter: str = "gaussian", sky: float = 1.0) -> dict:
    r"""A black triangle about ``size`` px across, centred in a ``width`` × ``width`` image, under the sky.

    The camera sits at (0, 0, -4) looking at the origin (up +y, so ``translate.x`` moves the
    triangle sideways, ``translate.z`` away from the camera); its fov makes a pixel
    :data:`PIXEL` = 0.1 wide at the triangle's depth whatever ``width``
    ($\tan(fov/2) = width · PIXEL / (2 · 4)$). The triangle's centre is offset by (0.13, -0.21)
    px from the optical axis, so no edge or vertex lines up with the pixel grid.
    """
    tan_half = width * PIXEL / 8.0
    local = np.array(TRIANGLE_SHAPE) * size * PIXEL
    return {
        "name": f"triangle_{size:g}px",
        "camera": {
            "position": [0.0, 0.0, -4.0],
            "look_at": [0.0, 0.0, 0.0],
            "up": [0.0, 1.0, 0.0],
            "fov": 2.0 * math.atan(tan_half),
            "width": width,
            "height": width,
            "filter": filter,
        },
        "sky": sky,
        "shapes": [
            {
                "name": "tri",
                "type": "mesh",
                "vertices": local.tolist(),
                "faces": [[0, 1, 2]],
                "albedo": 0.0,
                "translate": [0.013, -0.021, 0.0],
            }
        ],
    }


def junction_scene(size: float = 6.0, width: int = 16, filter: str = "gaussian", sky: float = 1.0) -> dict:
    r""":func:`pinhole_triangle_scene`'s triangle ``tri`` in front of a static black triangle ``wall``.

    The wall lies 0.5 behind the triangle (depth 4.5) and covers the lower part of the film below
    an edge a few degrees off the horizontal, 0.4 px below the optical axis: the triangle's two
    slanted edges cross it near the film's centre, two T-junctions of a moving and a static edge
    (:func:`~sphere3d.closed_form.junction.junction_image`); its lower edge lies on the wall, in
    front of black, no discontinuity at all.
    """
    scene = pinhole_triangle_scene(size, width, filter, sky)
    scene["name"] = f"junction_{size:g}px"
    edge = -0.4 * PIXEL * 4.5 / 4.0  # 0.4 px below the axis at the wall's depth
    scene["shapes"].append(
        {
            "name": "wall",
            "type": "mesh",
            "vertices": [[-3.0, edge + 0.1, 0.5], [3.0, edge - 0.1, 0.5], [0.1, -6.0, 0.5]],
            "faces": [[0, 1, 2]],
            "albedo": 0.0,
        }
    )
    return scene


def corner_junction_scene(below: float = 0.1, size: float = 6.0, width: int = 16) -> dict:
    """:func:`junction_scene` with the triangle moved up until its lower left vertex's image lies
    ``below`` px under the wall's edge (in y at that vertex's x): the two T-junctions meet at a corner
    of the moving silhouette, as where a box's corner lies on the ground's far edge."""
    scene = junction_scene(size, width)
    tri = scene["shapes"][0]
    vertex = np.array(TRIANGLE_SHAPE[0][:2]) * size * PIXEL + np.array(tri["translate"][:2])
    edge = -0.4 * PIXEL * 4.5 / 4.0  # the wall's edge at x = 0 (depth 4.5), as in junction_scene
    # the edge's line y = edge - x / 30 at depth 4.5, seen at the triangle's depth 4: scaled by 4 / 4.5
    line = edge * 4.0 / 4.5 - vertex[0] / 30.0
    tri["translate"][1] += line - below * PIXEL - vertex[1]
    scene["name"] = f"corner_junction_{size:g}px"
    return scene


def sliver_scene(gap: float = 0.3, angle: float = 1.0, size: float = 40.0, width: int = 16) -> dict:
    """:func:`junction_scene` with a triangle ``size`` px across turned until its lower edge runs ``angle``
    degrees off the wall's edge, ``gap`` px above it at the film's centre column: a thin sliver of sky
    between a moving silhouette and a static edge, the triangle's corners off the film. Lines that
    nearly meet outside the film, no T-junction in sight (:mod:`sphere3d.reparam.junctions`)."""
    scene = junction_scene(size, width)
    tri = scene["shapes"][0]
    a, b = (np.array(v[:2]) * size * PIXEL for v in TRIANGLE_SHAPE[:2])
    # the wall's edge has world slope -1/30 (film slope +1/30); the lower edge's world angle after a
    # turn phi about z: its own angle + phi, set to the wall's minus ``angle``
    phi = np.arctan(-1.0 / 30.0) - np.radians(angle) - np.arctan2(*(b - a)[::-1])
    turn = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
    a, b = turn @ a, turn @ b
    # at world x = 0 (the film's centre column) the wall's edge is 0.4 px below the axis: the lower
    # edge there ``gap`` px above it, in world units at the triangle's depth
    x = tri["translate"][0]
    y_at_centre = a[1] + (-x - a[0]) * (b[1] - a[1]) / (b[0] - a[0])
    tri["translate"][1] = (gap - 0.4) * PIXEL - y_at_centre
    tri["rotate"] = [0.0, 0.0, float(phi)]
    scene["name"] = f"sliver_{gap:g}px_{angle:g}deg"
    return scene


def sky_triangle_scene(vertices: Any, sky: float = 1.0) -> dict:
    """A black triangle with world ``vertices`` (3, 3) under a constant sky, centred on their centroid.

    Rotate and scale parameters act about the centroid. The camera is a placeholder (the
    irradiance at a point does not use it).
    """
    v = np.asarray(vertices, dtype=np.float64)
    centre = v.mean(axis=0)
    return {
        "name": "sky_triangle",
        "camera": {
            "position": [0.0, -3.0, 1.0],
            "look_at": [0.0, 0.0, 0.0],
            "fov": 0.8,
            "width": 8,
            "height": 8,
        },
        "sky": sky,
        "shapes": [
            {
                "name": "tri",
                "type": "mesh",
                "vertices": (v - centre).tolist(),
                "faces": [[0, 1, 2]],
                "albedo": 0.0,
                "translate": centre.tolist(),
            }
        ],
    }


def light_triangle_scene(
    vertices: Any, half: float = 0.5, height: float = 2.0, radiance: float = 5.0
) -> dict:
    """A square light of side ``2 half`` at ``height`` above the origin, facing down, emitting ``radiance``,
    and a black triangle with world ``vertices`` (3, 3) between, centred on their centroid; no sky.

    The irradiance at the origin (normal +z) is :func:`~sphere3d.closed_form.occluded_light_irradiance`:
    the emitter strategy's integral with a moving occluder in front of the light. Rotate and scale
    parameters of ``tri`` act about the centroid; the camera is a placeholder.
    """
    scene = sky_triangle_scene(vertices, sky=0.0)
    scene["name"] = "light_triangle"
    light = {
        "name": "light",
        "type": "rectangle",
        "size": [2.0 * half, 2.0 * half],
        "translate": [0.0, 0.0, height],
        "rotate": [np.pi, 0.0, 0.0],
        "emission": radiance,
        "fade": 0.0,
        "albedo": 0.0,
    }
    scene["shapes"] = [light, *scene["shapes"]]
    return scene


@dataclass(frozen=True)
class ShareLost:
    r"""The share of an exact derivative an estimator misses, from its independent batches.

    ``mean`` = 1 - mean over batches of $Σ \mathrm{sign}(g) d_b / Σ |g|$ (g the exact derivative, $d_b$ a
    batch's estimate; for a scalar $1 - d_b / g$); ``stderr`` its standard error; ``batches`` the count.
    Positive: the estimate is short of the exact derivative, as a missed boundary term makes it.
    """

    mean: float
    stderr: float
    batches: int


def share_lost(batch_estimates: Any, exact: Any) -> ShareLost:
    """:class:`ShareLost` of per-batch derivative estimates (B, ...) against the exact derivative (...).

    Summing over the film with the sign of the exact derivative weighs every pixel by the
    silhouette term's own direction, so a sideways motion (whose film sum is about 0: the
    triangle's area does not change) is measured like a motion in depth (whose derivative
    has one sign everywhere, so the weighted sum is the film sum itself).
    """
    d = np.asarray(batch_estimates, dtype=np.float64)
    g = np.asarray(exact, dtype=np.float64)
    if d.ndim != g.ndim + 1 or d.shape[1:] != g.shape or len(d) < 2:
        raise ValidationError("batch_estimates", f"must be (batches >= 2, *{g.shape}), got shape {d.shape}")
    total = float(np.sum(np.abs(g)))
    if total == 0.0:
        raise ValidationError("exact", "is zero everywhere: no share of it can be lost")
    kept = np.sum((np.sign(g) * d).reshape(len(d), -1), axis=1) / total
    lost = 1.0 - kept
    return ShareLost(float(lost.mean()), float(lost.std(ddof=1) / math.sqrt(len(d))), len(d))


def icosphere_scene(radius: float = 6.0, subdivisions: int = 2, width: int = 20, smooth: bool = True) -> dict:
    """:func:`pinhole_triangle_scene`'s camera and sky, with a black icosphere of ``radius`` px (at its
    centre's depth) in place of the triangle, its centre offset by (0.13, -0.21) px from the optical
    axis: a convex mesh whose outline's vertices lie about 2 px apart at ``subdivisions`` 2 and 6 px."""
    scene = pinhole_triangle_scene(1.0, width)
    scene["name"] = f"icosphere_{radius:g}px"
    scene["shapes"] = [
        {
            "name": "ball",
            "type": "icosphere",
            "radius": radius * PIXEL,
            "subdivisions": subdivisions,
            "smooth": smooth,
            "albedo": 0.0,
            "translate": [0.013, -0.021, 0.0],
        }
    ]
    return scene
