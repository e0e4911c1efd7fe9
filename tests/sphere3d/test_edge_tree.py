"""The edge tree (:mod:`sphere3d.boundary.edge_tree`): exactly the silhouette pairs, compiled as written.

The tree's walk chooses which (shading point, edge) pairs the exact silhouette test sees and runs it,
so (1) the pairs it returns must be exactly those of testing every pair (on an icosphere, from points
all around it and on the ground below; with the emitters' cone, the silhouette and the reach test),
(2) the compiled walk must return what the Python it is compiled from returns, and (3) the pairs and
an image must not depend on the size of the buffers the walk fills (a full buffer resumes the walk).
(4) Memory: on a mesh whose (points × edges) table would need 16 GB, a boundary and a reparam
gradient run in a process limited to a few GiB of address space. (5) One tree serves both groups of
points: restricted to a subset of its edges it finds the pairs of a tree over the subset. (6) The
compiled arc clip returns what its Python returns.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import sphere3d as s3
from sphere3d import jit
from sphere3d.boundary import edge_tree, shading, tree_build
from sphere3d.boundary import edges as edges_module
from sphere3d.boundary.edge_tree import EdgeTree
from sphere3d.boundary.edges import mesh_edges
from sphere3d.state import build_state

ROOT = Path(__file__).resolve().parents[2]


def _hard_shadow(subdivisions: int, size: int = 16) -> dict:
    scene = json.loads((ROOT / "sphere3d" / "scenes" / "hard_shadow.json").read_text())
    scene["shapes"][2]["subdivisions"] = subdivisions
    scene["camera"]["width"] = scene["camera"]["height"] = size
    return scene


def _points(rng: np.random.Generator) -> np.ndarray:
    """Points on the ground, in a box around the occluder (radius 0.3 at z = 0.8) and far away."""
    ground = rng.uniform([-2.5, -2.5, 1e-3], [2.5, 2.5, 2e-3], (600, 3))
    near = rng.uniform([-0.6, -0.6, 0.3], [0.8, 0.6, 1.4], (600, 3))
    far = rng.normal(size=(200, 3)) * 4.0
    return np.concatenate([ground, near, far])


def _setup(subdivisions: int, seed: int):
    state = build_state(s3.load_scene(_hard_shadow(subdivisions)))
    edges = mesh_edges(state.triangles, state.shape_of)
    bounds = shading._emitter_bounds(state)
    return state, edges, _points(np.random.default_rng(seed)), (bounds[1], bounds[2]), bounds


def _reach(edges, o: np.ndarray, rows: np.ndarray, cols: np.ndarray, bounds) -> np.ndarray:
    """The exact reach test, every pair: the cone from o around the edge's bounding sphere (midpoint,
    half length) meets the cone around the emitters' bounding sphere, or o lies in either sphere."""
    _, centre, radius = bounds
    mid = 0.5 * (edges.a + edges.b)[cols] - o[rows]
    half = 0.5 * np.linalg.norm(edges.b - edges.a, axis=-1)[cols]
    to = centre - o[rows]
    d_mid, d_to = np.linalg.norm(mid, axis=-1), np.linalg.norm(to, axis=-1)
    cos = np.einsum("ij,ij->i", mid, to) / (d_mid * d_to)
    spread = np.arcsin(np.minimum(1.0, half / d_mid)) + np.arcsin(np.minimum(1.0, radius / d_to))
    return (d_mid <= half) | (d_to <= radius) | (np.arccos(np.clip(cos, -1.0, 1.0)) <= spread)


def _meets_image(edges, o: np.ndarray, rows: np.ndarray, cols: np.ndarray, triangles) -> np.ndarray:
    """The exact image test, every pair: the cone from o around the edge's bounding sphere is not
    wholly beyond a side's great circle of every emitter triangle whose front o sees (sides' normals
    $c_k = q_{k+1} × q_k$, $q_k = L_k - o$, front where $q_0·(q_2 × q_1) > 0$), or o lies in the sphere."""
    mid = 0.5 * (edges.a + edges.b)[cols] - o[rows]
    half = 0.5 * np.linalg.norm(edges.b - edges.a, axis=-1)[cols]
    d_mid = np.linalg.norm(mid, axis=-1)
    u, sin_b = mid / d_mid[:, None], half / d_mid
    q = triangles[None] - o[rows][:, None, None, :]  # (pairs, T, 3, 3)
    c = np.cross(q[:, :, [1, 2, 0]], q)
    c = c / np.linalg.norm(c, axis=-1, keepdims=True)
    front = np.einsum("ptk,ptk->pt", q[:, :, 0], c[:, :, 1]) > 0.0
    beyond = np.einsum("pk,ptsk->pts", u, c) < -sin_b[:, None, None] - edge_tree.SLACK
    return (d_mid <= half) | np.any(front & ~np.any(beyond, axis=2), axis=1)


@pytest.mark.parametrize("emitters", ["none", "cone", "images"])
def test01_the_walk_finds_exactly_the_silhouette_pairs(emitters):
    _, edges, o, cone, bounds = _setup(3, 5)
    sil = edges.silhouette(o)  # (points, edges): the exact test, every pair
    exact = set(zip(*np.nonzero(sil), strict=True))
    tree = EdgeTree.build(edges, np.arange(len(edges)))
    rows, cols = tree.silhouettes(
        o, None if emitters == "none" else cone, bounds[0] if emitters == "images" else None
    )
    found = set(zip(rows.tolist(), cols.tolist(), strict=True))
    assert len(found) == rows.size  # no pair twice
    if emitters == "none":
        assert found == exact
        return
    r, c = np.nonzero(sil)
    keep = _reach(edges, o, r, c, bounds)
    if emitters == "images":
        keep &= _meets_image(edges, o, r, c, bounds[0])
    assert found == set(zip(r[keep].tolist(), c[keep].tolist(), strict=True))
    assert len(found) < 0.8 * len(exact)  # the reach test drops pairs
    if emitters == "images":  # the images drop pairs the cone keeps
        assert len(found) < 0.9 * np.count_nonzero(_reach(edges, o, r, c, bounds))


def test02_the_compiled_walk_returns_what_its_python_returns():
    _, edges, o, cone, bounds = _setup(2, 6)
    o = o[::7]  # the Python walk is slow: a few hundred points
    subset = np.flatnonzero(np.arange(len(edges)) % 3 != 0)  # a tree over a subset, with padding
    tree = EdgeTree.build(edges, subset)
    triangles = bounds[0]
    compiled = tree.silhouettes(o, cone, triangles)
    emit = np.array([*cone[0], cone[1]])
    rows, cols = np.empty(len(o) * len(edges), dtype=np.int64), np.empty(len(o) * len(edges), dtype=np.int64)
    stop, count = edge_tree.walk(
        np.ascontiguousarray(o), 0, emit, triangles, tree.centre, tree.radius, tree.axis, tree.cos_spread,
        tree.sin_spread, tree.depth, tree.order, tree.planes, tree.always, tree.spheres, tree.live,
        tree.active, rows, cols,
    )  # fmt: skip
    assert stop == len(o) and count > 50
    assert np.array_equal(compiled[0], rows[:count]) and np.array_equal(compiled[1], cols[:count])
    assert set(cols[:count].tolist()) <= set(subset.tolist())


def test03_pairs_and_images_do_not_depend_on_the_buffers():
    _, edges, o, cone, _ = _setup(4, 7)
    tree = EdgeTree.build(edges, np.arange(len(edges)))
    scene = s3.load_scene(_hard_shadow(3))
    results = []
    for size in (edge_tree.PAIRS_PER_POINT, 1):  # 1: full after the first point's pairs, many resumes
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(edge_tree, "PAIRS_PER_POINT", size)
            pairs = tree.silhouettes(o, cone)
            g = s3.render_gradient(
                scene, "occluder.translate.x", method="boundary", spp=4, seed=2, progress=False
            )
        results.append((pairs, g.derivative))
    (a, image_a), (b, image_b) = results
    assert a[0].size > 100 and np.any(image_a != 0.0)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert np.array_equal(image_a, image_b)


LIMIT_GIB = 3
"""The address space of test04's process: far below the 16 GB a (points × edges) table would need."""


@pytest.mark.parametrize("method", ["boundary", "reparam"])
def test04_no_table_of_points_by_edges_on_a_fine_mesh(method):
    # 32 × 32 pixels × 16 spp = 16 384 shading points, 122 880 edges: 16 GB as float64
    code = textwrap.dedent(
        f"""
        import json, resource
        resource.setrlimit(resource.RLIMIT_AS, ({LIMIT_GIB} << 30, {LIMIT_GIB} << 30))
        import sphere3d as s3
        scene = json.loads({json.dumps(json.dumps(_hard_shadow(6, 32)))})
        g = s3.render_gradient(s3.load_scene(scene), "occluder.translate.x", method={method!r}, spp=16,
                               progress=False)
        print(float(abs(g.derivative).sum()))
        """
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    assert float(run.stdout.split()[-1]) > 0.0


def test05_a_restricted_tree_finds_the_pairs_of_a_tree_over_the_subset():
    # the moving edges are a subset of the mesh's: one tree over all edges, restricted, must find
    # exactly the pairs of a tree built over the subset alone (in its own leaf order)
    _, edges, o, cone, bounds = _setup(3, 8)
    mask = (np.arange(len(edges)) % 5 != 0) & (edges.a[:, 2] > 0.7)  # two thirds of the upper half
    whole = EdgeTree.build(edges, np.arange(len(edges)), mask)  # the subset's edges first
    restricted, alone = whole.restrict(mask), EdgeTree.build(edges, np.flatnonzero(mask))
    assert restricted.live.sum() < whole.live.sum()  # some subtrees are skipped
    slots = whole.order.reshape(-1, edge_tree.LEAF)  # one leaf per row
    first, other = (slots >= 0) & mask[slots.clip(0)], (slots >= 0) & ~mask[slots.clip(0)]
    assert np.sum(first.any(axis=1) & other.any(axis=1)) <= 1  # one leaf at most holds both groups
    for cull in ((None, None), (cone, None), (cone, bounds[0])):
        a, b = restricted.silhouettes(o, *cull), alone.silhouettes(o, *cull)
        # the same pairs, in the same order: by point, by edge index within one (whatever the tree)
        assert a[0].size > 100 and np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
        assert mask[a[1]].all()


def test06_the_compiled_arc_clip_returns_what_its_python_returns():
    # shading.clip_arcs runs compiled in every render: its Python, run here as written, is the spec
    _, edges, o, cone, bounds = _setup(2, 9)
    o = o[::5]
    tree = EdgeTree.build(edges, np.arange(len(edges)))
    rows, cols = tree.silhouettes(o, cone)
    n0 = np.tile([0.0, 0.0, 1.0], (len(o), 1))
    clip = np.arange(len(edges)) % 4 != 0  # some edges unclipped
    sides, front = shading._image_sides(o, bounds[0])
    results = []
    for func in (shading.clip_arcs, jit.compiled(shading.clip_arcs)):
        out = np.empty(rows.size), np.empty(rows.size), np.empty((rows.size, 2)), np.empty((rows.size, 2))
        func(o, n0, rows, cols, edges.a, edges.b, clip, sides, front, *out)
        results.append(out)
    (s0, s1, lo, hi), compiled = results
    # the same arithmetic; atan2 may differ by an ulp or two between numpy's and the compiled libm, and
    # the angles are below 2π: a few ulp of 2π
    for x, y in zip(results[0], compiled, strict=True):
        np.testing.assert_allclose(x, y, rtol=0.0, atol=8 * np.spacing(2.0 * np.pi))
    above = s1 > s0
    assert 0 < above.sum() < rows.size  # some arcs cross the horizon or lie below it
    assert np.any((hi > lo)[clip[cols]]) and np.any((hi <= lo)[clip[cols] & above])  # clipped, some away
    assert np.all(lo[~clip[cols], 1] == hi[~clip[cols], 1])  # unclipped: one sub-arc, in column 0


def _tree_checks(edges, tree, subset, first):
    """The bounds the culls rely on, and the split: every node's sphere holds its edges' spheres and
    its normal cone their face normals; each group in slots of its own, every node's edges of one
    group split at the median of some axis."""
    leaves = 1 << tree.depth
    slots = tree.order.reshape(leaves, edge_tree.LEAF)
    assert sorted(tree.order[tree.order >= 0].tolist()) == sorted(subset.tolist())
    real = tree.order[tree.order >= 0]
    assert np.all(np.diff(~first[real]) >= 0)  # the first group, then the others
    mid, half = 0.5 * (edges.a + edges.b), 0.5 * np.linalg.norm(edges.b - edges.a, axis=1)
    for level in range(tree.depth + 1):
        for node in range(1 << level, 2 << level):
            shift = tree.depth - level
            span = slots[(node << shift) - leaves : ((node + 1) << shift) - leaves]
            e = span[span >= 0]
            if e.size == 0:
                assert tree.radius[node] == -1.0
                continue
            gap = np.linalg.norm(mid[e] - tree.centre[node], axis=1) + half[e]
            assert np.all(gap <= tree.radius[node] * (1 + 1e-9))
            if tree.spread[node] < np.pi:
                for n in (edges.n1[e], edges.n2[e]):
                    assert np.all(n @ tree.axis[node] >= np.cos(tree.spread[node]) - 1e-9)
            if level < tree.depth:  # the split: one group's left edges against its right ones
                left, right = np.array_split(span.ravel(), 2)
                left, right = left[left >= 0], right[right >= 0]
                for g in (True, False):
                    a, b = left[first[left] == g], right[first[right] == g]
                    if a.size and b.size:
                        assert any(mid[a, k].max() <= mid[b, k].min() for k in range(3))


@pytest.mark.parametrize("case", ["all", "subset", "two groups"])
def test07_the_bounds_hold_their_edges_and_each_node_splits_at_a_median(case):
    _, edges, *_ = _setup(3, 9)
    rng = np.random.default_rng(3)
    subset = np.arange(len(edges)) if case != "subset" else np.flatnonzero(rng.random(len(edges)) < 0.6)
    first = rng.random(len(edges)) < 0.3 if case == "two groups" else np.ones(len(edges), dtype=bool)
    tree = EdgeTree.build(edges, subset, None if case != "two groups" else first)
    _tree_checks(edges, tree, subset, first)


def test08_the_compiled_build_returns_what_its_python_returns():
    _, edges, *_ = _setup(2, 10)
    mid = np.ascontiguousarray((0.5 * (edges.a + edges.b)).T)
    depth = int(np.ceil(np.log2(len(edges) / edge_tree.LEAF)))
    split = tree_build.compiled_split()(mid, 100, depth, edge_tree.LEAF)
    assert np.array_equal(split, tree_build.median_split(mid, 100, depth, edge_tree.LEAF))
    order = np.full(edge_tree.LEAF << depth, -1)
    order[: len(edges)] = split
    outputs = []
    for func in (tree_build.leaf_bounds, jit.compiled(tree_build.leaf_bounds)):
        n = 1 << depth
        out = (np.zeros((n, 3)), np.full(n, -1.0), np.zeros((n, 3)), np.zeros(n))
        func(order, edge_tree.LEAF, edges.a, edges.b, edges.n1, edges.n2, edges.always, *out)
        outputs.append(out)
    for a, b in zip(*outputs, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-15)


def _grid_mesh(n: int, rng: np.random.Generator) -> np.ndarray:
    """Triangles (T, 3, 3) of an n × n height field on an integer grid (many equal coordinates: long
    runs for the weld's sort), with some faces repeated (edges of three or four faces), shuffled."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    height = rng.integers(0, 3, (n + 1, n + 1)).astype(float) * 0.5
    corner = lambda a, b: np.stack([a, b, height[a, b]], axis=-1)  # noqa: E731
    lower = np.stack([corner(i, j), corner(i + 1, j), corner(i + 1, j + 1)], axis=-2)
    upper = np.stack([corner(i, j), corner(i + 1, j + 1), corner(i, j + 1)], axis=-2)
    tri = np.concatenate([lower.reshape(-1, 3, 3), upper.reshape(-1, 3, 3)])
    tri = np.concatenate([tri, tri[rng.choice(len(tri), 7, replace=False)]])
    return tri[rng.permutation(len(tri))]


@pytest.mark.parametrize("mesh", ["icosphere", "grid"])
def test09_the_welded_edges_are_those_of_a_dictionary_of_vertex_pairs(mesh):
    # mesh_edges' weld (sort_ties) and grouping (edge_groups) run compiled: against np.unique's ids
    # and a dictionary of (lower id, higher id) -> half-edges, built one half-edge at a time
    rng = np.random.default_rng(11)
    if mesh == "icosphere":
        tri = np.asarray(build_state(s3.load_scene(_hard_shadow(3))).triangles, dtype=np.float64)
    else:
        tri = _grid_mesh(40, rng)
    rows = tri.reshape(-1, 3)
    expected_ids = np.unique(rows, axis=0, return_inverse=True)[1].ravel()
    ids = edges_module.row_ids(rows)
    assert np.array_equal(ids, expected_ids)
    order = np.argsort(rows[:, 0])
    python, compiled_order = order.copy(), order.copy()
    edges_module.sort_ties(python, rows)
    jit.compiled(edges_module.sort_ties)(compiled_order, rows)
    assert np.array_equal(python, compiled_order)
    vid = ids.reshape(-1, 3)
    groups: dict[tuple[int, int], list[int]] = {}
    for h in range(3 * len(vid)):
        a, b = vid[h // 3, h % 3], vid[h // 3, (h % 3 + 1) % 3]
        if a != b:
            groups.setdefault((min(a, b), max(a, b)), []).append(h)
    keys = sorted(groups)
    face, slot, other, count = jit.compiled(edges_module.edge_groups)(vid)
    assert np.array_equal(face, [groups[k][0] // 3 for k in keys])
    assert np.array_equal(slot, [groups[k][0] % 3 for k in keys])
    assert np.array_equal(count, [len(groups[k]) for k in keys])
    assert np.array_equal(other, [groups[k][1] // 3 if len(groups[k]) == 2 else -1 for k in keys])
    assert count.max() >= (3 if mesh == "grid" else 2)
    for got, want in zip(edges_module.edge_groups(vid), (face, slot, other, count), strict=True):
        assert np.array_equal(got, want)  # the Python it is compiled from


@pytest.mark.parametrize("numbering", ["state", "one per corner", "shared, with unused numbers"])
def test10_the_weld_by_vertex_numbers_gives_the_edges_of_the_weld_by_positions(numbering):
    # mesh_edges with ``corners`` ranks one corner per number: the same ids, hence the same edges, as
    # ranking every corner, whether numbers are shared (a state's meshes), unique per corner (a mesh
    # whose equal positions carry different numbers) or leave gaps (vertices no face uses)
    rng = np.random.default_rng(5)
    if numbering == "state":
        scene = s3.load_scene("hard_shadow_cube")
        state = build_state(scene)
        tri, shape_of, corners = np.asarray(state.triangles), state.shape_of, state.corners
        flat = tri.reshape(-1, 3)
        for c in (0, 1, 2):  # every corner of one number holds one position, bit for bit
            first = np.full(corners.max() + 1, -1)
            first[corners.ravel()] = np.arange(corners.size)
            assert np.array_equal(flat[first[corners.ravel()], c], flat[:, c])
    else:
        tri = _grid_mesh(12, rng)
        shape_of = np.zeros(len(tri), dtype=np.int64)
        corners = np.arange(tri.size // 3).reshape(-1, 3)
        if numbering != "one per corner":
            ids = np.unique(tri.reshape(-1, 3), axis=0, return_inverse=True)[1].ravel()
            spread = rng.permutation(3 * (ids.max() + 1))[: ids.max() + 1]  # gaps between numbers
            corners = spread[ids].reshape(-1, 3)
    by_position = mesh_edges(tri, shape_of)
    by_number = mesh_edges(tri, shape_of, corners)
    assert len(by_number.face) > 0
    for field in by_position.__dataclass_fields__:
        got, want = (np.asarray(getattr(e, field)).tobytes() for e in (by_number, by_position))
        assert got == want
