"""The edge tree (:mod:`sphere3d.boundary.edge_tree`): conservative culls, the same pairs, the same images.

The tree only chooses which (shading point, edge) pairs the boundary term's exact tests see, so
(1) its candidates must hold every pair the exact tests keep (checked against the scan of every pair
on an icosphere, from points all around it and on the ground below, with and without the emitters'
cone), and (2) an image must not depend on whether the tree or the scan found the pairs (bit for
bit). (3) Memory: on a mesh whose (points × edges) table would need 16 GB, a boundary and a reparam
gradient run in a process limited to a few GiB of address space.
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
from sphere3d.boundary import shading
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


@pytest.mark.parametrize("emitters", [True, False], ids=["emitter_cone", "no_cone"])
def test01_candidates_hold_every_silhouette_pair(emitters):
    state = build_state(s3.load_scene(_hard_shadow(3)))
    edges = mesh_edges(state.triangles, state.shape_of)
    o = _points(np.random.default_rng(5))
    bounds = shading._emitter_bounds(state)
    sil = edges.silhouette(o)  # (points, edges): the exact test, every pair
    if emitters:
        r, c = np.nonzero(sil)
        keep = shading._reach(edges, o, r, c, bounds)
        sil[:] = False
        sil[r[keep], c[keep]] = True
    exact = set(zip(*np.nonzero(sil), strict=True))
    tree = EdgeTree.build(edges, np.arange(len(edges)))
    rows, cols, tests = tree.candidates(o, (bounds[1], bounds[2]) if emitters else None)
    found = set(zip(rows.tolist(), cols.tolist(), strict=True))
    assert exact and exact <= found  # conservative: no pair the exact tests keep is lost
    assert len(found) < 0.5 * sil.size  # and it culls: fewer than half of all pairs
    assert tests < 0.5 * sil.size


def test02_the_tree_keeps_the_same_pairs_as_the_scan():
    state = build_state(s3.load_scene(_hard_shadow(4)))
    edges = mesh_edges(state.triangles, state.shape_of)
    o = _points(np.random.default_rng(6))
    n0 = np.tile([0.0, 0.0, 1.0], (len(o), 1))
    moving = state.shape_of[edges.face] == 2
    point_moves = np.arange(len(o)) % 7 == 0  # some points see every edge
    bounds = shading._emitter_bounds(state)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(shading, "NODE_COST", 0.0)  # the tree for every block
        tree = shading._pairs(edges, o, n0, moving, point_moves, bounds)
        mp.setattr(shading, "NODE_COST", np.inf)  # the scan after the first block
        mp.setattr(shading, "QUERY_POINTS", 1)
        scan = shading._pairs(edges, o, n0, moving, point_moves, bounds)
    assert len(tree[0]) > 100
    for a, b in zip(tree, scan, strict=True):
        assert np.array_equal(a, b)


def test03_an_image_is_the_same_whether_the_tree_or_the_scan_finds_the_pairs():
    scene = s3.load_scene(_hard_shadow(3))
    images = []
    for cost in (0.0, np.inf):
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(shading, "NODE_COST", cost)
            mp.setattr(shading, "QUERY_POINTS", 1)
            g = s3.render_gradient(
                scene, "occluder.translate.x", method="boundary", spp=4, seed=2, progress=False
            )
        images.append(g.derivative)
    assert np.any(images[0] != 0.0)
    assert np.array_equal(images[0], images[1])


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
