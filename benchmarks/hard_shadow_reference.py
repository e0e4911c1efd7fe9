"""Per-pixel reference derivative of the ``hard_shadow`` scenes: finite differences, Richardson-extrapolated.

``python -m benchmarks.hard_shadow_reference [--scenes hard_shadow hard_shadow_cube] [--passes 64]``
writes ``sphere3d/scenes/references/<scene>.npz`` (package data, read by
:func:`sphere3d.scene.load_reference`): the derivative of every pixel with
respect to ``occluder.translate.x`` at θ = 0 and its standard error.

Estimator. Pass k renders the image at θ = ±h and ±h/2 with the samples of seed
``SEED + k`` (common random numbers: the four renders share every primary sample) and
forms the central differences D(h) = [I(h) - I(-h)] / 2h and D(h/2); their truncation
errors are c h² + O(h⁴) and c h²/4 + O(h⁴), so the Richardson combination

    R = (4 D(h/2) - D(h)) / 3

cancels the h² term. The passes are independent batches: the stored derivative is the
mean of the per-pass R, its standard error the sample standard deviation over passes
/ sqrt(passes). Unbiased up to O(h⁴) (no assumption about edges: finite differences
see every moving discontinuity).

Choice of h = 0.01 (measured with 16 batches of 1024 spp, seed 7; rms over the 64 × 64
pixels, bias estimated as sqrt(mean(m² - se²)) of the per-pixel mean difference m):

===================  ==================  ==================
                     sphere              cube
===================  ==================  ==================
D(0.04) - D(0.02)    0.167               0.376
D(0.02) - D(0.01)    0.052               0.143
D(0.01) - D(0.005)   0.011               0.050
R(0.02) - R(0.01)    < noise (0.107)     0.050 (noise 0.154)
===================  ==================  ==================

D(h) - D(h/2) = 3/4 of D(h)'s truncation error: at h = 0.01 a plain central difference
would still be off by 0.014 (sphere) and 0.066 (cube) rms, more than the 2^16-spp noise;
the edge moves 0.28 px per 0.01 (119 px per unit at 4.3 units), comparable to the
σ = 0.5 px filter, so larger steps leave the h² regime (the cube's ratios are 2.6-2.9
instead of 4). R(0.02) and R(0.01) differ by about 0.05 rms on the cube, an upper
estimate of R(0.02)'s residual; R(0.01), the stored one, is closer. Its noise is
1.5 × that of D(0.005) alone; at 64 passes of 1024 spp, about 0.016 (sphere) and
0.023 (cube) rms per pixel.

The passes use the per-pixel film (``film="pixel"``, each sample in the pixel that drew it),
as the stored files were made before film splatting (:mod:`sphere3d.film`) became the default:
``--resume`` adds passes of the same estimator. Both films estimate the same pixel integrals.

The file is rewritten after every pass, so a run cut short keeps what it completed,
and ``--resume`` adds passes to a stored file.

``--scheduler ADDRESS`` runs every render's chunks as tiles on the workers of that
``dask.distributed`` scheduler (:func:`sphere3d.execution.cluster`; the ``cluster`` extra), each
worker on its own cores (``SPHERE3D_THREADS`` there), this process only assembling the images:
the passes are bit for bit those of a local run, so a cluster's passes and a machine's mix in one
file (``--resume``).

Stored: ``hard_shadow`` 43 passes (44 032 spp; on one core of a shared machine a pass
took 25-110 s and the time budget ended the run before 64), rms standard error 0.020;
``hard_shadow_cube`` 64 passes (65 536 spp), rms standard error 0.024; 44 and 32
minutes of wall time on one core (``execution.WORKERS = 1``).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from flatland.core.validate import ValidationError
from sphere3d import execution
from sphere3d.scene import load_scene
from sphere3d.tasks import ImageTask

SCENES = ("hard_shadow", "hard_shadow_cube")
PARAM = "occluder.translate.x"
H = 0.01
SEED = 1000
SPP_PER_PASS = 1024
PASSES = 64
DIRECTORY = Path(__file__).resolve().parents[1] / "sphere3d" / "scenes" / "references"  # package data


def richardson_pass(scene_name: str, seed: int, spp: int = SPP_PER_PASS, h: float = H) -> np.ndarray:
    """One pass: arrays D(h), D(h/2) and R = (4 D(h/2) - D(h)) / 3, each (height, width), stacked."""
    task = ImageTask(load_scene(scene_name), PARAM, spp, seed, 1, film="pixel")  # the stored files' film
    image = {theta: task.evaluate(theta).value[0] for theta in (h, -h, h / 2, -h / 2)}
    d_h = (image[h] - image[-h]) / (2 * h)
    d_h2 = (image[h / 2] - image[-h / 2]) / h
    return np.stack([d_h, d_h2, (4.0 * d_h2 - d_h) / 3.0])


def path_of(scene_name: str) -> Path:
    return DIRECTORY / f"{scene_name}.npz"


def load_reference(scene_name: str) -> dict[str, np.ndarray]:
    """The stored reference: ``derivative``, ``stderr``, ``d_h``, ``d_h2`` (per pixel) and the settings."""
    with np.load(path_of(scene_name)) as z:
        return {k: z[k] for k in z.files}


def _write(scene_name: str, n: int, sums: np.ndarray, m2: np.ndarray, seconds: float) -> None:
    """Store the means of ``n`` passes (``sums``: D(h), D(h/2), R summed) and R's standard error
    (``m2``: the sum of R's squared deviations from its mean)."""
    DIRECTORY.mkdir(exist_ok=True)
    np.savez_compressed(
        path_of(scene_name),
        derivative=sums[2] / n,
        stderr=np.sqrt(m2 / (n - 1) / n),
        d_h=sums[0] / n,
        d_h2=sums[1] / n,
        scene=scene_name,
        param=PARAM,
        h=H,
        spp=n * SPP_PER_PASS,
        spp_per_pass=SPP_PER_PASS,
        batches=n,
        seed=SEED,
        seconds=seconds,
    )


def generate(
    scene_name: str,
    passes: int = PASSES,
    budget: float = float("inf"),
    resume: bool = False,
    scheduler: str | None = None,
) -> int:
    """Run passes (seeds SEED + k) until ``passes`` are stored or ``budget`` seconds are spent; returns
    the number of passes stored. The file is rewritten after every pass (from the second on); with
    ``resume`` the passes already stored are kept (their sums and squared deviations are recovered
    from the stored means and standard error) and the run continues with the next seed. With
    ``scheduler`` (a ``dask.distributed`` address) the renders run on that cluster, with the same
    numbers (:func:`sphere3d.execution.cluster`)."""
    with execution.cluster(scheduler):
        return _passes(scene_name, passes, budget, resume)


def _passes(scene_name: str, passes: int, budget: float, resume: bool) -> int:
    """:func:`generate`'s loop over passes, wherever the renders run."""
    n, seconds = 0, 0.0
    sums = m2 = None
    if resume and path_of(scene_name).exists():
        ref = load_reference(scene_name)
        n, seconds = int(ref["batches"]), float(ref["seconds"])
        sums = n * np.stack([ref["d_h"], ref["d_h2"], ref["derivative"]])
        m2 = ref["stderr"] ** 2 * n * (n - 1)
    start = time.perf_counter() - seconds
    run_start, run_passes = time.perf_counter(), 0
    while n < passes:
        r = richardson_pass(scene_name, SEED + n)
        run_passes += 1
        if sums is None:
            sums, m2 = r.copy(), np.zeros_like(r[2])
        else:
            # Welford / Chan update of R's squared deviations with one more pass
            m2 = m2 + (r[2] - sums[2] / n) ** 2 * n / (n + 1)
            sums = sums + r
        n += 1
        elapsed = time.perf_counter() - start
        print(f"{scene_name}: pass {n}/{passes}, {elapsed:.0f} s", flush=True)
        if n >= 2:
            _write(scene_name, n, sums, m2, elapsed)
        spent = time.perf_counter() - run_start
        if spent / run_passes * (run_passes + 1) > budget and n >= 2:  # the next pass would not fit
            break
    return n


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.hard_shadow_reference", description=__doc__)
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=SCENES)
    parser.add_argument("--passes", type=int, default=PASSES)
    parser.add_argument("--budget", type=float, default=float("inf"), help="seconds per scene (this run)")
    parser.add_argument("--resume", action="store_true", help="add passes to the stored ones")
    parser.add_argument(
        "--scheduler", default=None,
        help="dask.distributed scheduler address: the renders run on that cluster (default: here, one core)",
    )  # fmt: skip
    args = parser.parse_args(argv)
    execution.WORKERS = 1  # one core: the reference runs beside other work (on a cluster: the workers' own)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    for name in args.scenes:
        try:
            stored = generate(name, args.passes, args.budget, args.resume, args.scheduler)
        except ValidationError as e:  # a bad --scheduler: one line, status 2
            parser.error(str(e))
        print(f"{name}: stored {stored} passes ({stored * SPP_PER_PASS} spp) in {path_of(name)}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
