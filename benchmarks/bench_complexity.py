"""sphere3d at growing geometric complexity: time and memory per method from 320 to 327 680 triangles.

The ``hard_shadow`` scene with its occluder's icosphere subdivided 2 to 6 times (320 to 81 920
triangles, 64 × 64 pixels, 16 spp, d/d ``occluder.translate.x``, seed 1), and an irregular mesh:
the same sphere subdivided 7 times (327 680 triangles) with each vertex moved along its radius by
a smooth random field (:func:`bumpy_sphere`; smooth-shaded as ``hard_shadow``'s sphere, its
silhouette and shadow ragged). Each run is a fresh process (``python -m benchmarks.bench_complexity
TRIANGLES METHOD``) reporting its wall time (the call only, after the imports and a warm-up call
on a 4 × 4 px image of the coarsest mesh: what a method loads once per process, such as the edge
tree's compiled walk, is not the scene's cost) and its peak resident set size (``getrusage``),
the fastest of :data:`REPEATS` runs; all the cores the renderer uses (``SPHERE3D_THREADS``), and
reparam and boundary again on one thread at 81 920 triangles, to show how the chunks share the
cores.

Rows: seconds and peak MB per triangle count and method, and the time's ratio to the same method
at 320 triangles (goal of the scale issue: at most 3 at 81 920 triangles, peak under 1.5 GB).

Where the time goes as the mesh grows: the per-state tables (mesh edges, the film corners, the
penumbra planes, the edge tree) are O(E log E) and built once per state by the first chunk that
asks; ``boundary``'s shading term enumerates, per shading point, every silhouette edge whose arc
can meet the emitters (:mod:`sphere3d.boundary.edge_tree` finds them without scanning the mesh),
so its cost grows with the silhouette edges a point sees, about the square root of the mesh's
edges, not with the mesh: the work per penumbra point grows with the mesh's resolution, as the
number of arcs it sums over does (the estimator's probability of an arc is its angle over all of
them). More cores: the chunks (at most :data:`sphere3d.tasks.CHUNK` samples, and at least
:data:`sphere3d.execution.CHUNKS_PER_THREAD` per thread) are independent, so their share of the
time divides by the cores, up to the chunks' count; the per-state tables and the state's build do
not (the one-thread rows: their difference from the two-thread rows is the chunks' share).

Agreement per region: at 5 120 and 81 920 triangles, ``reparam`` and ``boundary`` against
``finite_difference`` (h = 1e-2) on three pixel regions, from S = 12 seeds at 16 spp each: the
**silhouette** (pixels whose 3 × 3 neighbourhood holds both the occluder and the ground at the
pixel centres), the **penumbra** (ground pixels lit by some but not all of a 4 × 4 grid of points
on the light) and the **shadow** (ground pixels lit by none of them). Per region the sum of the
derivative over its pixels, per seed; z = (mean difference) / (its standard error over seeds,
Student t with S - 1 degrees of freedom), flagged above the two-sided quantile at family-wise
1 % (Šidák over the rows). finite_difference's own truncation is part of the difference.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats

from benchmarks import Row

ROOT = Path(__file__).resolve().parents[1]
PARAM = "occluder.translate.x"
SPP = 16
SUBDIVISIONS = (2, 3, 4, 5, 6)
BUMPY = 7
"""Subdivisions of the irregular mesh (327 680 triangles)."""
METHODS = ("render", "naive", "reparam", "boundary", "finite_difference")
REPEATS = 3
"""Fresh-process runs per row; the row reports the fastest (other processes on a shared machine only
ever slow a run down, so the minimum is the least disturbed) and the largest peak memory."""
REGION_SEEDS = tuple(range(1, 13))
REGION_SIZES = (4, 6)
LEVEL = 0.01


def bumpy_sphere(subdivisions: int, radius: float = 0.3, amplitude: float = 0.06, seed: int = 7) -> dict:
    """An inline mesh: an icosphere whose vertices move along their radius by a sum of 24 random
    spherical waves $a_k \\sin(f_k\\, d_k · \\hat v + φ_k)$ (frequencies 2 to 12, seeded), scaled to
    ±``amplitude`` of the radius: smooth at the scale of the sphere, irregular at every other."""
    from sphere3d.shapes import icosphere

    mesh = icosphere(1.0, subdivisions)
    v = np.asarray(mesh.vertices, dtype=np.float64)
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(24, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    field = np.sin(rng.uniform(2.0, 12.0, 24) * (v @ d.T) + rng.uniform(0.0, 2 * np.pi, 24)) @ rng.normal(
        size=24
    )
    field *= amplitude / np.max(np.abs(field))
    return {
        "vertices": (v * (radius * (1.0 + field))[:, None]).tolist(),
        "faces": np.asarray(mesh.faces).tolist(),
    }


def scene(subdivisions: int) -> dict:
    """``hard_shadow`` with its occluder subdivided (or the bumpy sphere at :data:`BUMPY`)."""
    data = json.loads((ROOT / "sphere3d" / "scenes" / "hard_shadow.json").read_text())
    occluder = data["shapes"][2]
    if subdivisions == BUMPY:
        keep = {k: occluder[k] for k in ("name", "translate", "albedo")}
        data["shapes"][2] = {**keep, "type": "mesh", "smooth": True, **bumpy_sphere(subdivisions)}
    else:
        occluder["subdivisions"] = subdivisions
    return data


def _one(subdivisions: int, method: str) -> dict:
    """One run in this process (the subprocess's work): seconds and peak MB, after a warm-up."""
    from sphere3d import load_scene, render, render_gradient

    loaded = load_scene(scene(subdivisions))
    # warm-up, not timed: a 4 x 4 px call of the same method on the coarsest mesh imports what the
    # method imports on first use and loads its compiled code (Numba's, from the disk cache)
    small = scene(0)
    small["camera"]["width"] = small["camera"]["height"] = 4
    if method == "render":
        render(load_scene(small), spp=1, seed=1, progress=False)
    else:
        render_gradient(load_scene(small), PARAM, method=method, spp=1, seed=1, progress=False)
    start = time.perf_counter()
    if method == "render":
        render(loaded, spp=SPP, seed=1, progress=False)
    else:
        render_gradient(loaded, PARAM, method=method, spp=SPP, seed=1, progress=False)
    seconds = time.perf_counter() - start
    return {"seconds": seconds, "mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def _fresh(subdivisions: int, method: str, threads: int | None = None) -> dict:
    """The fastest of :data:`REPEATS` fresh-process runs (and the largest peak memory of them)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    if threads is not None:
        env["SPHERE3D_THREADS"] = str(threads)
    cmd = [sys.executable, "-m", "benchmarks.bench_complexity", str(subdivisions), method]
    runs = []
    for _ in range(REPEATS):
        out = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=env, check=True)
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    return {"seconds": min(r["seconds"] for r in runs), "mb": max(r["mb"] for r in runs)}


def _regions(subdivisions: int) -> dict[str, np.ndarray]:
    """Pixel masks of the silhouette, penumbra and shadow (module docstring), from pixel-centre rays."""
    from sphere3d import load_scene
    from sphere3d.state import build_state
    from sphere3d.vector import normalize

    state = build_state(load_scene(scene(subdivisions)))
    cam = state.camera
    h, w = cam.height, cam.width
    rows, cols = np.divmod(np.arange(h * w), w)
    d = np.asarray(cam.directions(cols + 0.5, rows + 0.5), dtype=np.float64)
    o = np.broadcast_to(np.asarray(cam.origin, dtype=np.float64), d.shape)
    hits = state.tracer.intersect(o, d)
    shape = np.where(hits.hit, state.shape_of[np.maximum(hits.triangle, 0)], -1)
    occluder, ground = (shape == 2).reshape(h, w), (shape == 0).reshape(h, w)
    pad = lambda m: np.pad(m, 1, mode="edge")  # noqa: E731
    near = lambda m: np.any([pad(m)[i : i + h, j : j + w] for i in range(3) for j in range(3)], axis=0)  # noqa: E731
    silhouette = near(occluder) & near(ground)
    light = np.asarray(state.triangles)[state.emitters].reshape(-1, 3)
    lo, hi = light.min(axis=0), light.max(axis=0)
    u = (np.arange(4) + 0.5) / 4
    grid = np.array(
        [[lo[0] + a * (hi[0] - lo[0]), lo[1] + b * (hi[1] - lo[1]), lo[2] - 1e-3] for a in u for b in u]
    )
    on = np.flatnonzero(ground.ravel())
    x = o[on] + d[on] * hits.t[on, None] + 1e-4 * np.array([0.0, 0.0, 1.0])  # just above the ground
    count = np.zeros(h * w, dtype=int)
    for target in grid:  # 16 shadow rays per ground pixel
        to = target - x
        count[on] += ~state.tracer.occluded(x, normalize(to), np.linalg.norm(to, axis=1))
    count = count.reshape(h, w)
    ground_only = ground & ~silhouette
    return {
        "silhouette": silhouette,
        "penumbra": ground_only & (count > 0) & (count < len(grid)),
        "shadow": ground_only & (count == 0),
    }


def _region_rows() -> list[Row]:
    from sphere3d import load_scene, render_gradient

    cases = [(s, m) for s in REGION_SIZES for m in ("reparam", "boundary")]
    quantile = stats.t.ppf(1 - 0.5 * (1 - (1 - LEVEL) ** (1 / (3 * len(cases)))), len(REGION_SEEDS) - 1)
    rows = []
    for subdivisions in REGION_SIZES:
        loaded = load_scene(scene(subdivisions))
        masks = _regions(subdivisions)
        sums = {}
        for method in ("finite_difference", "reparam", "boundary"):
            images = [
                render_gradient(loaded, PARAM, method=method, spp=SPP, seed=s, progress=False).derivative
                for s in REGION_SEEDS
            ]
            sums[method] = {k: np.array([img[m].sum() for img in images]) for k, m in masks.items()}
        for method in ("reparam", "boundary"):
            for region, mask in masks.items():
                diff = sums[method][region] - sums["finite_difference"][region]
                se = diff.std(ddof=1) / np.sqrt(len(diff))
                z = diff.mean() / se if se > 0 else 0.0
                flag = "FLAGGED" if abs(z) > quantile else "within noise"
                note = (
                    f"{int(mask.sum())} px; sum {sums[method][region].mean():+.4g} vs finite_difference"
                    f" {sums['finite_difference'][region].mean():+.4g}; |z| <= {quantile:.2f}: {flag}"
                )
                case = f"{20 * 4**subdivisions} triangles, {method} - finite_difference, {region}: z"
                rows.append(Row("complexity", case, z, "", note))
    return rows


def run() -> list[Row]:
    """The sweep (fresh processes), the thread rows and the regions (module docstring)."""
    rows, base = [], {}
    for subdivisions in (*SUBDIVISIONS, BUMPY):
        triangles = 20 * 4**subdivisions
        label = f"{triangles} triangles" + (" (bumpy)" if subdivisions == BUMPY else "")
        for method in METHODS:
            result = _fresh(subdivisions, method)
            base.setdefault(method, result["seconds"])
            ratio = result["seconds"] / base[method]
            note = f"peak {result['mb']:.0f} MB; {ratio:.1f}x its time at 320 triangles"
            rows.append(Row("complexity", f"{label}, {method}", result["seconds"], "s", note))
    for method in ("reparam", "boundary"):
        result = _fresh(6, method, threads=1)
        note = f"peak {result['mb']:.0f} MB, one thread (SPHERE3D_THREADS=1)"
        rows.append(Row("complexity", f"81920 triangles, {method}, 1 thread", result["seconds"], "s", note))
    return rows + _region_rows()


if __name__ == "__main__":
    print(json.dumps(_one(int(sys.argv[1]), sys.argv[2])))
