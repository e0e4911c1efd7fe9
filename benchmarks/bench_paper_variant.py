"""reparam as published (``variant="paper"``) beside the default variant on ``hard_shadow``.

Both variants of ``reparam`` render d/d ``occluder.translate.x`` of ``hard_shadow`` (the
icosphere occluder under an area light) at 64 spp for :data:`SEEDS`, with every other option at
its default, and are compared pixel by pixel with the stored reference
(:mod:`benchmarks.hard_shadow_reference`). The paper variant (Loubet et al. 2019, Sec. 4.1-4.3:
one rotation per integral from its probe rays, vMF kernel, paired samples) has none of the
extensions listed on the theory page "extensions": in particular no emitter-edge term, so the
sharp light's penumbra moves with the occluder but its estimate does not follow it (a bias that
does not shrink with spp), and no per-sample film kernel, so small silhouettes are followed by
one rotation per pixel integral.

Rows per variant, bias first (:func:`benchmarks.bench_hard_shadow.bias_floor`: rms per-pixel
bias of the mean over the seeds, its noise and the reference's subtracted), then the RMSE at
64 spp (mean over seeds and pixels) and the wall-clock seconds per 64 spp image (best of the
seeds; meaningful on an idle machine only). ``make bench``'s ``hard_shadow`` page has the same
rows at more seeds and sample counts.
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks import Row
from benchmarks.bench_hard_shadow import bias_floor, rmse
from benchmarks.hard_shadow_reference import PARAM, load_reference, path_of
from sphere3d import render_gradient

SCENE = "hard_shadow"
SPP = 64
SEEDS = (1, 2, 3, 4)
VARIANTS = ("default", "paper")


def run() -> list[Row]:
    """The rows of this page: bias floor, RMSE and time of each variant."""
    if not path_of(SCENE).exists():
        return [Row("paper_variant", f"{SCENE}: no reference", float("nan"), "", "run the generator")]
    ref = load_reference(SCENE)
    rows = []
    for variant in VARIANTS:
        images, seconds = [], []
        for seed in SEEDS:
            start = time.perf_counter()
            result = render_gradient(SCENE, PARAM, method="reparam", spp=SPP, seed=seed, variant=variant)
            seconds.append(time.perf_counter() - start)
            images.append(result.derivative)
        stack = np.stack(images)
        case = f"{SCENE} reparam ({variant})"
        note = f"{len(SEEDS)} seeds at {SPP} spp"
        rows.append(
            Row(
                "paper_variant",
                f"{case}: bias floor",
                bias_floor(stack, ref["derivative"], ref["stderr"]),
                "rms",
                note,
            )
        )
        rows.append(
            Row("paper_variant", f"{case}: RMSE {SPP} spp", rmse(stack, ref["derivative"]), "rms", note)
        )
        rows.append(Row("paper_variant", f"{case}: {SPP} spp", min(seconds), "s"))
    return rows
