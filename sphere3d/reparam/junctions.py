r"""Where a moving silhouette meets a static edge on the film: the map a film kernel there follows.

A film kernel (:mod:`sphere3d.reparam.film_kernel`) that holds a moving silhouette and a static edge
(the ground's far edge against the sky behind an occluder, say) holds two discontinuities with two
motions. One rotation per kernel, locally a translation of the film, cannot follow the one and hold
the other still (Loubet et al. 2019, Sec. 4.1: one rotation per integral); following the silhouette
drags the static edge, and the kernel's samples lose or gain the static edge's term. An affine map
of the film can keep both lines on their moved lines: each line takes two of its six degrees of
freedom (:func:`~sphere3d.reparam.film_lines.line_map`, the least-norm one). Where the two lines
cross in the kernel (a T-junction at J) it holds J's motion to first order, as the translation by
$\dot J$ would; where they run nearly parallel (a silhouette along a static edge, a thin sliver of
sky between them, J far away) it follows both, which no translation does.

The lines come from the scene, not from the probes (:mod:`sphere3d.reparam.film_lines`): a kernel
gets the map where exactly one moving discontinuity edge (a silhouette, or a crease of a flat-shaded
shape) and at least one static one pass within its ring (the nearest static one is kept); a thin
sliver between the two lines, which the probes miss, is still followed. A crease alone in the ring
(two faces of one shape, which the probes, pairing different shapes, do not see as a discontinuity)
gets the map keeping its line: a rotation following one point of a turning crease drifts off it
with the distance from that point. With two moving edges in the ring the corner rule applies where
they meet at a vertex (:mod:`sphere3d.reparam.film_corners`, which drags a static line), the
probes' rotation elsewhere.

Exact to first order for straight edges; the closed forms of :mod:`sphere3d.closed_form.junction` (a
black triangle moving across a static one's edge, a sliver between them, and its corner on that
edge) check it (tests/sphere3d/test_junctions.py). Still biased where the kernel holds a second
static line (one is kept), the end of the static edge, or two moving edges that do not meet in it.
"""

from __future__ import annotations

import numpy as np

from sphere3d.film import AffineFilm
from sphere3d.reparam.film_lines import line_map, moving_edges, static_lines
from sphere3d.state import SceneState

__all__ = ["junction_maps"]


def junction_maps(state: SceneState, centre: np.ndarray, reach: float) -> tuple[np.ndarray, AffineFilm]:
    r"""The kernels (centres (m, 2), pixels) whose ring of radius ``reach`` px holds one moving
    discontinuity edge and a static one, two moving ones and no static one, or a crease alone, and
    the affine film maps about their centres that keep those lines on their moved lines (module
    docstring).

    Returns
    -------
    rows : ndarray of int
        Rows (of the m) with a map, ascending.
    maps : AffineFilm
        Their maps, (len(rows),) (:class:`~sphere3d.film.AffineFilm`, every mask True).
    """
    near = moving_edges(state, centre, reach)
    static = static_lines(state, centre[near.first.rows], reach)
    with_static = np.zeros(len(centre), dtype=bool)
    with_static[near.first.rows[static.rows]] = True
    count = near.count[near.first.rows]  # per row of near.first
    parts = []
    # one moving edge and the nearest static one
    one = np.flatnonzero(count[static.rows] == 1)
    parts.append((near.first.rows[static.rows[one]], (static.take(one), near.first.take(static.rows[one]))))
    # two moving edges (not at a corner of theirs: the corner rule has those rows) and no static one
    two = ~with_static[near.second.rows] & (near.count[near.second.rows] == 2)
    at = np.searchsorted(near.first.rows, near.second.rows[two])
    parts.append((near.second.rows[two], (near.first.take(at), near.second.take(two))))
    # a crease alone: the map keeping its line, where a rotation follows one point of it
    alone = np.flatnonzero((count == 1) & near.crease & ~with_static[near.first.rows])
    parts.append((near.first.rows[alone], (near.first.take(alone),)))
    maps = [line_map(centre[rows], *lines) for rows, lines in parts]
    rows = np.concatenate([rows for rows, _ in parts])
    order = np.argsort(rows, kind="stable")
    a_dot = np.concatenate([a for a, _ in maps])[order]
    b_dot = np.concatenate([b for _, b in maps])[order]
    return rows[order], AffineFilm(np.ones(rows.size, dtype=bool), a_dot, b_dot, centre[rows[order]])
