"""The complexity benchmark's scenes and regions (:mod:`benchmarks.bench_complexity`).

The sweep itself runs in ``make bench``; here: the irregular mesh is what its docstring says (a
sphere whose radius varies smoothly by at most the stated amplitude, over 10⁵ triangles at the
benchmark's subdivision), and the three pixel regions are disjoint and each non-empty on the
scene the benchmark judges.
"""

from __future__ import annotations

import numpy as np

from benchmarks import bench_complexity as bench
from sphere3d import load_scene


def test01_the_bumpy_sphere_varies_its_radius_within_the_amplitude():
    mesh = bench.bumpy_sphere(3, radius=0.3, amplitude=0.06)
    radius = np.linalg.norm(np.asarray(mesh["vertices"]), axis=1) / 0.3 - 1.0
    assert np.max(np.abs(radius)) <= 0.06 * (1.0 + 1e-12)
    assert np.std(radius) > 0.01  # irregular, not a sphere
    assert len(mesh["faces"]) == 20 * 4**3
    assert 20 * 4**bench.BUMPY >= 100_000


def test02_the_benchmark_scene_takes_the_bumpy_mesh_at_its_subdivision():
    data = bench.scene(3)
    assert data["shapes"][2]["subdivisions"] == 3
    loaded = load_scene(bench.scene(2))
    assert loaded.parameters == load_scene("hard_shadow").parameters


def test03_the_regions_are_disjoint_and_each_holds_pixels():
    masks = bench._regions(2)
    assert set(masks) == {"silhouette", "penumbra", "shadow"}
    total = sum(m.astype(int) for m in masks.values())
    assert total.max() == 1  # disjoint
    assert all(m.sum() > 10 for m in masks.values())
