"""The outline of a convex mesh seen from a point (:mod:`sphere3d.reparam.outline_anchors`).

Predicted by the module's construction, checked by brute force over every vertex:

1. each climb ends at the vertex whose chart coordinate along its direction is the largest of the
   whole mesh (a ratio of linear functions has no other local maximum on a convex polytope);
2. the anchors (the maxima and their neighbours) hold every vertex of the outline: the hull of their
   charts is the hull of all the vertices' charts, on icospheres of 42 to 642 vertices seen from
   points and kernel centres around them.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from flatland.core.dual import variable
from sphere3d.reparam.outline_anchors import DIRECTIONS, chart_extremes, mesh_graph, outline_candidates
from sphere3d.scene import load_scene
from sphere3d.state import build_state
from sphere3d.vector import frame


def _kernels(subdivisions: int, n: int = 40, seed: int = 3):
    """An icosphere of radius 0.05 at distance about 1 turned off its axes, its graph, and ``n`` kernels:
    shading points near the origin, chart centres within 0.05 rad of the direction to the ball."""
    scene = {
        "name": "ball",
        "camera": {"position": [0, -3, 1], "look_at": [0, 0, 0], "up": [0, 0, 1], "fov": 0.5,
                   "width": 8, "height": 8},
        "sky": 1.0,
        "shapes": [{"name": "ball", "type": "icosphere", "radius": 0.05, "subdivisions": subdivisions,
                    "albedo": 0.0, "translate": [0.3, 0.15, 1.0], "rotate": [0.3, 0.2, 0.1]}],
    }  # fmt: skip
    state = build_state(load_scene(scene), "ball.rotate.x", variable(0.0))
    graph = mesh_graph([state.triangles.reshape(-1, 3)])
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, 3)) * 0.05
    to = np.array([0.3, 0.15, 1.0]) - x
    c = to / np.linalg.norm(to, axis=1)[:, None] + rng.normal(size=(n, 3)) * 0.05
    c /= np.linalg.norm(c, axis=1)[:, None]
    t, b = frame(c)
    return graph, x, c, t, b


def _charts(points: np.ndarray, x, c, t, b) -> np.ndarray:
    y = points - x
    return np.stack([y @ t, y @ b], axis=-1) / (y @ c)[..., None]


@pytest.mark.parametrize("subdivisions", [1, 2, 3])
def test01_every_climb_ends_at_the_mesh_s_maximum_along_its_direction(subdivisions):
    graph, x, c, t, b = _kernels(subdivisions)
    found = chart_extremes(graph, np.zeros(len(x), dtype=np.intp), x, c, t, b)
    points = np.asarray(graph.vertices.value)
    phi = 2.0 * np.pi * np.arange(DIRECTIONS) / DIRECTIONS
    for r in range(len(x)):
        u = _charts(points, x[r], c[r], t[r], b[r])  # (V, 2)
        along = u @ np.stack([np.cos(phi), np.sin(phi)])  # (V, D)
        reached = along[found[r], np.arange(DIRECTIONS)]
        np.testing.assert_allclose(reached, along.max(axis=0), rtol=0.0, atol=1e-12)


@pytest.mark.parametrize("subdivisions", [1, 2, 3])
def test02_the_anchors_hold_the_whole_outline(subdivisions):
    """The hull of the anchors' charts has the same vertices as the hull of all the vertices' charts
    (by :class:`scipy.spatial.ConvexHull`); the maxima alone miss outline vertices of small exterior
    angle on at least one of these meshes, which the neighbours restore."""
    graph, x, c, t, b = _kernels(subdivisions)
    rows = np.zeros(len(x), dtype=np.intp)
    anchors = outline_candidates(graph, rows, x, c, t, b)
    maxima = chart_extremes(graph, rows, x, c, t, b)
    points = np.asarray(graph.vertices.value)
    short = 0
    for r in range(len(x)):
        u = _charts(points, x[r], c[r], t[r], b[r])
        outline = set(ConvexHull(u).vertices.tolist())
        assert outline <= set(anchors[r].tolist()), outline - set(anchors[r].tolist())
        short += len(outline - set(maxima[r].tolist()))
    if subdivisions == 1:
        assert short > 0  # what the neighbours are for
