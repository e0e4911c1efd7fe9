r"""Where a moving silhouette meets a static edge on the film: the map a film kernel there follows.

A film kernel (:mod:`sphere3d.reparam.film_kernel`) that holds a moving silhouette and a static edge
(the ground's far edge against the sky behind an occluder, say) holds two discontinuities with two
motions. One rotation per kernel, locally a translation of the film, cannot follow the one and hold
the other still (Loubet et al. 2019, Sec. 4.1: one rotation per integral); following the silhouette
drags the static edge, and the kernel's samples lose or gain the static edge's term. A field on
the film that keeps both lines on their moved lines replaces it: the blend of the two lines' own
least-norm maps by the distances to them (:func:`~sphere3d.reparam.film_lines.blend_map`),
pinned to the crossing J's
velocity where the two cross near the kernel (there a translation by $\dot J$ where they only
translate). Where they run nearly parallel (a silhouette along a static edge, a thin sliver of sky
between them, J far away) it follows both, which no translation does, and strains only the sliver
and its neighbourhood (the one affine map keeping both lines strains the whole kernel at 1 / g for
a gap g). Each sample carries the field's value and gradient at its own film point.

The lines come from the scene, not from the probes (:mod:`sphere3d.reparam.film_lines`): a kernel
gets the map where exactly one moving discontinuity edge (a silhouette, or a crease of a flat-shaded
shape) and at least one static one pass within its ring (the nearest static one is kept); a thin
sliver between the two lines, which the probes miss, is still followed. A crease alone in the ring
(two faces of one shape, which the probes, pairing different shapes, do not see as a discontinuity)
gets the map keeping its line: a rotation following one point of a turning crease drifts off it with
the distance from that point. Two moving edges in the ring and no static one: the corner rule where
they meet at a vertex in it (:mod:`sphere3d.reparam.film_corners`; with a static line there as well,
:mod:`sphere3d.reparam.corner_lines`), the blended field of the two elsewhere where one of them is a
crease (a thin face seen nearly edge-on); two silhouettes that do not meet keep the probes' rotation
(the lines are queried only near a static line or a crease: on a finely meshed smooth shape every
kernel on the silhouette holds several short edges).

Exact to first order for straight edges; the closed forms of :mod:`sphere3d.closed_form.junction` (a
black triangle moving across a static one's edge, a sliver between them, and its corner on that
edge) check it (tests/sphere3d/test_junctions.py). Still biased where the kernel holds a second
static line (one is kept), the end of the static edge, three moving edges, or two silhouettes.
"""

from __future__ import annotations

import numpy as np

from sphere3d.film import AffineFilm
from sphere3d.reparam.film_lines import blend_map, line_map, moving_edges, near_creases, static_lines
from sphere3d.state import SceneState

__all__ = ["junction_maps"]


def junction_maps(
    state: SceneState, centre: np.ndarray, at: np.ndarray, reach: float
) -> tuple[np.ndarray, AffineFilm]:
    r"""The kernels (centres (m, 2), pixels) whose ring of radius ``reach`` px holds one moving
    discontinuity edge and a static one, two moving ones (one a crease) and no static one, or a crease
    alone, and
    the film maps that keep those lines on their moved lines (module docstring), each sample's at its
    own film point ``at`` (m, 2).

    Returns
    -------
    rows : ndarray of int
        Rows (of the m) with a map, ascending.
    maps : AffineFilm
        Their maps, (len(rows),) (:class:`~sphere3d.film.AffineFilm`, every mask True): two lines by
        :func:`~sphere3d.reparam.film_lines.blend_map` (each sample its field's value and gradient at
        its point), a crease alone by :func:`~sphere3d.reparam.film_lines.line_map`.
    """
    # the rules below need a static line or a moving crease in the ring: the moving edges only there
    static = static_lines(state, centre, reach)
    rows = np.union1d(static.rows, near_creases(state, centre, reach))
    near = moving_edges(state, centre[rows], reach)
    first_rows = rows[near.first.rows]  # the rows (of the m) with a moving edge near
    static = static.take(np.searchsorted(static.rows, first_rows[np.isin(first_rows, static.rows)]))
    with_static = np.zeros(len(centre), dtype=bool)
    with_static[static.rows] = True
    count = near.count[near.first.rows]  # per row of near.first
    has = with_static[first_rows]
    pairs = []
    # one moving edge and the nearest static one
    one = np.flatnonzero(has & (count == 1))
    pick = np.searchsorted(static.rows, first_rows[one])
    pairs.append((first_rows[one], static.take(pick), near.first.take(one)))
    # two moving edges (one a crease; not at a corner of theirs: the corner rule has those rows), no static
    second_rows = rows[near.second.rows]
    two = ~with_static[second_rows] & (near.count[near.second.rows] == 2)
    first = np.searchsorted(near.first.rows, near.second.rows[two])
    pairs.append((second_rows[two], near.first.take(first), near.second.take(two)))
    parts = []
    for rows, line_a, line_b in pairs:
        v, grad = blend_map(centre[rows], at[rows], line_a, line_b, reach)
        parts.append((rows, v, grad, at[rows]))
    # a crease alone: the map keeping its line, where a rotation follows one point of it
    alone = np.flatnonzero((count == 1) & near.crease & ~has)
    rows = first_rows[alone]
    parts.append((rows, *line_map(centre[rows], near.first.take(alone)), centre[rows]))
    rows = np.concatenate([p[0] for p in parts])
    order = np.argsort(rows, kind="stable")
    a_dot, b_dot, about = (np.concatenate([p[i] for p in parts])[order] for i in (1, 2, 3))
    return rows[order], AffineFilm(np.ones(rows.size, dtype=bool), a_dot, b_dot, about)
