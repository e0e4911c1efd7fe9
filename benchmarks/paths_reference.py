"""Per-pixel reference derivatives of sphere3d's light-path scenes: Richardson-extrapolated differences.

``python -m benchmarks.paths_reference [--scenes glossy_reflection interreflection] [--passes 16]``
writes ``.cache/paths_reference/<scene>.npz`` (a gitignored cache, rebuilt on demand by
:func:`reference`): the derivative of every pixel of the 64 x 64 image with respect to
``occluder.translate.x`` at θ = 0, at ``max_depth`` 4 and 2, and their standard errors.

Estimator: that of :mod:`benchmarks.hard_shadow_reference`, per depth. Pass k renders the image at
θ = ±h and ±h/2 with the samples of one seed (common random numbers: the four renders share every
sample, so their differences see only what θ moved) and forms the central differences D(h) and
D(h/2); the Richardson combination R = (4 D(h/2) - D(h)) / 3 cancels their common h² truncation
error, leaving O(h⁴), h = 0.01 as for ``hard_shadow`` (the same occluder, light and film). The
passes are the batches of one render per θ (independent: every sample's numbers are keyed on its
index), the stored derivative the mean of the per-pass R, its standard error their sample standard
deviation / sqrt(passes). The depth-2 and depth-4 renders of a pass share the seed, so the paths'
first two vertices are common and the difference of the two references is less noisy than either.
Default film (``"splat"``), as the methods measured against it.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from sphere3d.scene import load_scene
from sphere3d.tasks import ImageTask

SCENES = ("glossy_reflection", "interreflection")
PARAM = "occluder.translate.x"
H = 0.01
SEED = 2000
SPP_PER_PASS = 1024
PASSES = 16
DEPTHS = (4, 2)
DIRECTORY = Path(__file__).resolve().parents[1] / ".cache" / "paths_reference"


def path_of(scene_name: str) -> Path:
    return DIRECTORY / f"{scene_name}.npz"


def richardson(scene_name: str, depth: int, passes: int, seed: int, h: float = H) -> np.ndarray:
    """R = (4 D(h/2) - D(h)) / 3 per pass, shape (passes, height, width): four renders of ``passes``
    batches of :data:`SPP_PER_PASS` samples, the same samples at every θ."""
    task = ImageTask(load_scene(scene_name), PARAM, passes * SPP_PER_PASS, seed, passes, max_depth=depth)
    image = {theta: task.evaluate(theta).value for theta in (h, -h, h / 2, -h / 2)}
    d_h = (image[h] - image[-h]) / (2 * h)
    d_h2 = (image[h / 2] - image[-h / 2]) / h
    return (4.0 * d_h2 - d_h) / 3.0


def generate(scene_name: str, passes: int = PASSES) -> dict[str, np.ndarray]:
    """Render and store the references of ``scene_name`` (module docstring); returns what was stored."""
    start = time.perf_counter()
    out: dict[str, np.ndarray] = {}
    r = {depth: richardson(scene_name, depth, passes, SEED) for depth in DEPTHS}
    for depth in DEPTHS:
        out[f"depth{depth}"] = r[depth].mean(axis=0)
        out[f"stderr{depth}"] = r[depth].std(axis=0, ddof=1) / np.sqrt(passes)
    diff = r[4] - r[2]  # per pass: the common random numbers cancel in the difference
    out["difference"] = diff.mean(axis=0)
    out["difference_stderr"] = diff.std(axis=0, ddof=1) / np.sqrt(passes)
    DIRECTORY.mkdir(parents=True, exist_ok=True)
    meta = {"h": H, "passes": passes, "spp": passes * SPP_PER_PASS, "seconds": time.perf_counter() - start}
    np.savez_compressed(path_of(scene_name), **out, **{k: np.asarray(v) for k, v in meta.items()})
    return {**out, **{k: np.asarray(v) for k, v in meta.items()}}


def reference(scene_name: str, passes: int = PASSES) -> dict[str, np.ndarray]:
    """The cached reference of ``scene_name`` (however many passes it has: its noise is a row of the
    page), generated with ``passes`` passes if absent."""
    if path_of(scene_name).exists():
        with np.load(path_of(scene_name)) as z:
            return {k: z[k] for k in z.files}
    return generate(scene_name, passes)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.paths_reference", description=__doc__)
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=SCENES)
    parser.add_argument("--passes", type=int, default=PASSES)
    args = parser.parse_args(argv)
    for name in args.scenes:
        ref = generate(name, args.passes)
        noise = float(np.sqrt(np.mean(ref["stderr4"] ** 2)))
        print(f"{name}: {args.passes} passes, {float(ref['seconds']):.0f} s, rms se {noise:.4f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
