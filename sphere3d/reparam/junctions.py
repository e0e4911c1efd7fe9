r"""Where a moving silhouette meets a static edge on the film: the junction a film kernel follows.

A film kernel (:mod:`sphere3d.reparam.film_kernel`) whose probes see a moving shape and two different
static things (the ground and the black sky beyond its far edge, say) holds two discontinuities:
the moving silhouette and the static edge. One rotation per kernel, locally a translation of
the film, cannot follow the one and hold the other still (Loubet et al. 2019, Sec. 4.1: one
rotation per integral); following the silhouette drags the static edge, and the kernel's
samples lose or gain the static edge's term. Near the point J where the two edges' images
cross (a T-junction), one translation does both to first order: J's own velocity. It lies
along the static edge (which stays on its line) and its component across the moving edge is
that edge's normal velocity (the moving line stays on J). Seen from the camera at o, J's
direction is the line shared by the two planes through o that hold each edge,
$j = ((A - o) × (B - o)) × ((C - o) × (D - o))$, A B the static edge, C D the moving one,
their ends attached to their shapes (Duals: the tangent of j is J's motion, the camera's
included). The film kernel follows j instead of the point the
probe pair chose (:func:`junction_rotation`).

Each edge is found as the silhouette is (:func:`~sphere3d.reparam.bisection.bisect_silhouette`, then
:func:`~sphere3d.reparam.snaps.edge_snap` onto the exit edge of the bisected hit's triangle): the moving
one between the closest pair of a probe on a moving triangle and one that is not; the static
one between the closest pair of static probes that see different things (a miss counts as a
thing), the nearer shape's triangle holding the edge, each bisection ray having to see one of
the two (seeing a moving triangle instead abandons the row). A row is followed at its junction
only where both edges are found (a corner of either is left to the single-edge rule) and J lies
within ``radius`` pixels of the kernel's centre.

Exact to first order in the distance from J, for straight edges; the closed form of
:mod:`sphere3d.closed_form.junction` (a black triangle moving across a static one's edge) checks
it. Still biased where the two edges cross outside ``radius`` of the kernel's centre (the
single-edge rule applies), where a third discontinuity lies between the static probes (the row
is abandoned), and at a corner of either edge: where the moving silhouette's corner lies on the
static edge (a box's corner on the ground's far edge), the kernels there hold three
discontinuities with two motions; the closed form of
:func:`~sphere3d.closed_form.corner_junction_scene` measures the loss (tests/sphere3d/test_junctions.py),
and ``hard_shadow_cube``'s bias lies mostly at such a corner (the occluder-motions table).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flatland.core.dual import detach
from sphere3d.live import any_rows
from sphere3d.reparam.bisection import bisect, bisect_silhouette, closest_pair
from sphere3d.reparam.snaps import Snap, edge_snap
from sphere3d.rotation import Rotation
from sphere3d.state import SceneState
from sphere3d.tracing import Hits
from sphere3d.vector import cross, dot

__all__ = ["MOVING", "junction_rotation", "probe_classes"]

MOVING = -2
"""The class of a probe on a moving triangle (:func:`probe_classes`); a miss is -1, a static hit its shape."""


def probe_classes(hits: Hits, moving: np.ndarray) -> np.ndarray:
    """Per probe what it sees: its shape where the triangle is static, -1 for a miss, :data:`MOVING`."""
    return np.where(hits.on(moving), MOVING, hits.shape)


def _edge_ends(state: SceneState, snap: Snap, rows: np.ndarray, origin: np.ndarray, pair: tuple) -> tuple:
    """The bisected hit's exit edge (its two ends, attached: Duals) and whether one was found."""
    hits, inside, outside = pair
    _, _, lines = snap(rows, origin, inside, outside, hits)
    found = lines[:, 0, 0] >= 0
    tri = state.triangles[np.maximum(hits.triangle, 0)]
    k = np.arange(len(rows))
    return tri[k, np.maximum(lines[:, 0, 0], 0)], tri[k, np.maximum(lines[:, 0, 1], 0)], found


def junction_rotation(
    state: SceneState,
    origin: Any,
    directions: np.ndarray,
    hits: Hits,
    moving: np.ndarray,
    centre: np.ndarray,
    radius: float,
    refine: int,
) -> tuple[np.ndarray, Rotation]:
    r"""The rows of film probe rings that see a moving silhouette cross a static edge, and the
    rotations following that junction (module docstring).

    Parameters
    ----------
    state : SceneState
        The scene at θ.
    origin : Dual or ndarray, shape (3,)
        The camera's origin (its tangent moves the junction too).
    directions : ndarray, shape (m, P, 3)
        The rings' probe directions; ``hits`` (m, P) their first hits.
    moving : ndarray of bool
        One flag per triangle: its vertices have a tangent.
    centre : ndarray, shape (m, 2)
        The kernels' centres on the film (pixels); ``radius``: how far J may lie from them.
    refine : int
        Bisection rays per edge.

    Returns
    -------
    rows : ndarray of int
        Rows (of the m) followed at their junction.
    rotation : Rotation
        Their rotations, shape (len(rows),).
    """
    seen = probe_classes(hits, moving)
    # a moving probe, and two static probes that see different things (their classes' least and
    # greatest differ): a candidate junction
    low = np.where(seen == MOVING, np.iinfo(seen.dtype).max, seen).min(axis=1)
    rows = np.flatnonzero(any_rows(seen == MOVING) & (low < seen.max(axis=1)))
    if rows.size == 0 or refine == 0:
        return rows[:0], Rotation.identity((0,), state.k)
    d, cls, h = directions[rows], seen[rows], hits.take(rows)
    on_moving, static = cls == MOVING, cls != MOVING
    k = np.arange(rows.size)
    snap = edge_snap(state, lambda r, ends: np.full(ends.shape[:2], np.inf), 0.0)  # exit edges, no corner
    o = np.asarray(detach(origin), dtype=np.float64)
    trace = np.broadcast_to(o, (rows.size, 3))
    # the moving edge: between the closest pair of a moving probe and a static one
    i, j, ok = closest_pair(d, lambda r: on_moving[r, :, None] & static[r, None, :])
    start = h.take((k, i))
    moved = bisect_silhouette(state, trace, d[k, i], d[k, j], start, None, refine)
    c_end, d_end, found_m = _edge_ends(state, snap, k, trace, moved)

    def differ_in_front(r: slice) -> np.ndarray:  # (rows, P, P) of a slice of rows (closest_pair)
        c, t = cls[r], h.t[r]
        differ = static[r, :, None] & static[r, None, :] & (c[:, :, None] != c[:, None, :])
        return differ & (c[:, :, None] >= 0) & ((t[:, :, None] < t[:, None, :]) | (c[:, None, :] < 0))

    # the static edge: between the closest pair of static probes that see different things, the
    # inside one a hit in front of what the other sees (a miss is never in front)
    a, b, ok_s = closest_pair(d, differ_in_front)
    # a row stays valid while every bisection ray sees one of the two (else a third discontinuity lies
    # between them)
    inside_class, outside_class = cls[k, a], cls[k, b]

    def side(seen: Hits, _: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c = probe_classes(seen, moving)
        return c == inside_class, c == outside_class

    fixed, inside, outside, valid = bisect(state, trace, d[k, a], d[k, b], h.take((k, a)), side, refine)
    a_end, b_end, found_s = _edge_ends(state, snap, k, trace, (fixed, inside, outside))
    # the junction's direction: the line shared by the planes through o holding each edge
    n_static, n_moving = cross(a_end - origin, b_end - origin), cross(c_end - origin, d_end - origin)
    j_dir = cross(n_static, n_moving)
    toward = d.sum(axis=1)  # roughly the kernel's centre
    j_dir = j_dir * np.where(dot(detach(j_dir), toward) < 0.0, -1.0, 1.0)[:, None]
    jv = detach(j_dir)
    with np.errstate(divide="ignore", invalid="ignore"):  # rows without both edges: dropped by `keep`
        fx, fy = (np.asarray(detach(f)) for f in state.camera.film(jv))
        near = np.hypot(fx - centre[rows, 0], fy - centre[rows, 1]) <= radius
    keep = ok & ok_s & found_m & found_s & valid & near & (dot(jv, state.camera.forward) > 0.0)
    return rows[keep], Rotation.following(j_dir[keep], np.ones(int(keep.sum()), dtype=bool))
