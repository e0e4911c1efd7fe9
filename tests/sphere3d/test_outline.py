"""One step along an occluder's outline (:mod:`sphere3d.reparam.outline`), against brute force.

On a single triangle the next edges at both ends of an edge are its other two; on the cube and the
sphere of the built-in scenes, seen from points around them, every next edge shares the found edge's
end, differs from it, and is a silhouette edge by the faces' facing (every mesh edge tested), and an
end has none only where no silhouette edge but the found one meets it. Walked on edge by edge
(:func:`~sphere3d.reparam.outline.outline_chain`), the convex sphere's outline is one closed loop: the
two chains from a found edge cover every silhouette edge of it, each step meeting the last at a vertex,
and a chain told to stop after its first step stops there.
"""

from __future__ import annotations

import itertools

import numpy as np

from sphere3d import closed_form as cf
from sphere3d.boundary.edges import state_edges
from sphere3d.reparam.outline import next_edges, outline_chain, outline_table
from sphere3d.scene import load_scene
from sphere3d.state import build_state

TRIANGLE = np.array([[0.0, -0.5, 1.0], [0.9, 0.0, 1.0], [0.0, 0.5, 1.0]])


def _silhouette(state, x):
    """Every mesh edge's silhouette flag from the point x (brute force over all edges)."""
    e = state_edges(state)
    to = e.a - x
    return (e.other < 0) | (
        (np.einsum("ex,ex->e", e.n1, to) > 0.0) != (np.einsum("ex,ex->e", e.n2, to) > 0.0)
    )


def test01_a_single_triangle_s_edge_continues_along_its_other_two():
    state = build_state(load_scene(cf.sky_triangle_scene(TRIANGLE)))
    for i, j in ((0, 1), (1, 2), (2, 0), (1, 0)):
        after = next_edges(state, np.zeros((1, 3)), np.array([0]), np.array([[i, j]]))
        assert after.found.all()
        got = {frozenset((int(after.ia[0, end]), int(after.ib[0, end]))) for end in range(2)}
        assert got == {frozenset((i, 3 - i - j)), frozenset((j, 3 - i - j))}


def test02_on_the_cube_and_the_sphere_the_next_edges_are_silhouette_edges_at_the_ends():
    rng = np.random.default_rng(5)
    for name in ("hard_shadow_cube", "hard_shadow"):
        scene = load_scene(name)
        state = build_state(scene)
        table, edges = outline_table(state), state_edges(state)
        shape = [s.name for s in scene.shapes].index("occluder")
        mine = np.flatnonzero(state.shape_of[edges.face] == shape)
        centre = np.concatenate([edges.a[mine], edges.b[mine]]).mean(axis=0)
        va_all, vb_all = table.vid[edges.face, edges.ia], table.vid[edges.face, edges.ib]
        checked = 0
        for _ in range(6):  # points around the occluder
            x = centre + rng.normal(size=3) * 3.0
            silhouette = _silhouette(state, x)
            found = mine[silhouette[mine]]
            slots = np.stack([edges.ia[found], edges.ib[found]], axis=1)
            after = next_edges(state, np.tile(x, (len(found), 1)), edges.face[found], slots)
            ends = table.vid[edges.face[found][:, None], slots]
            for end in range(2):
                f = after.found[:, end]
                e = table.edge_of[after.face[f, end], after.ia[f, end]]
                assert np.all(silhouette[e]) and np.all(e != found[f])
                assert np.all((va_all[e] == ends[f, end]) | (vb_all[e] == ends[f, end]))
                for row in np.flatnonzero(~f):  # no other silhouette edge meets that end
                    meets = (va_all == ends[row, end]) | (vb_all == ends[row, end])
                    assert not np.any(meets & silhouette & (np.arange(len(meets)) != found[row]))
                checked += int(f.sum())
        assert checked > 0


def test03_walked_on_the_sphere_s_outline_is_one_loop_of_silhouette_edges():
    scene = load_scene("hard_shadow")
    state = build_state(scene)
    table, edges = outline_table(state), state_edges(state)
    shape = [s.name for s in scene.shapes].index("occluder")
    mine = np.flatnonzero(state.shape_of[edges.face] == shape)
    x = np.array([[0.3, -0.4, 0.0]])  # a point on the ground below the sphere
    loop = mine[_silhouette(state, x[0])[mine]]
    start = loop[:1]
    slots = np.stack([edges.ia[start], edges.ib[start]], axis=1)
    ids = lambda face, ia, ib: table.edge_of[face, np.where(ib == (ia + 1) % 3, ia, ib)]  # noqa: E731
    every = outline_chain(
        state, x, edges.face[start], slots, lambda r, f, a, b: np.ones(r.size, bool), len(loop)
    )
    walked = [int(ids(f, a, b)[0]) for _, f, a, b in every]
    assert set(walked) | {int(start[0])} == set(loop.tolist())
    for side in (walked[: len(walked) // 2], walked[len(walked) // 2 :]):
        for e1, e2 in itertools.pairwise(side):  # each step meets the last at a vertex
            ends1 = {table.vid[edges.face[e1], edges.ia[e1]], table.vid[edges.face[e1], edges.ib[e1]]}
            ends2 = {table.vid[edges.face[e2], edges.ia[e2]], table.vid[edges.face[e2], edges.ib[e2]]}
            assert len(ends1 & ends2) == 1
    first = outline_chain(state, x, edges.face[start], slots, lambda r, f, a, b: np.zeros(r.size, bool), 5)
    assert len(first) == 2 and all(r.size == 1 for r, *_ in first)
