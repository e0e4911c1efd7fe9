"""Every built-in scene and every kind of parameter: ``reparam`` against a high-sample finite difference.

Metric: ``relative_error = mean|g - g_ref| / max|g_ref|`` over a 16 × 16 image, with
g_ref a ``finite_difference`` image (h = 0.01, common random numbers, seed 1) and g
the ``reparam`` image (default options, seed 2). It mixes both images' noise with
the bias, so each case states the measured value (a fixed-seed run) and bounds it by
1.5 × that; it also requires ``naive`` (same samples as reparam) to be visibly
worse, its error being the missing boundary terms. Measured run (default, splatted film;
in brackets the per-pixel film's, measured before splatting became the default):

==============  ======================  ======  =======  ===============  ===============
scene           parameter               FD spp  rp. spp  reparam err      naive err
==============  ======================  ======  =======  ===============  ===============
shadow          occluder.translate.x    2048    512      0.0204 (0.0220)  0.0794 (0.0678)
shadow          light.translate.x       2048    1024     0.0298 (0.0530)  0.0321 (0.0778)
shadow          camera.translate.x      2048    512      0.0146 (0.0276)  0.0865 (0.0798)
silhouette      occluder.rotate.z       2048    512      0.0262 (0.0264)  0.0584 (0.0529)
silhouette      occluder.scale          2048    512      0.0074 (0.0211)  0.1370 (0.1375)
two_occluders   left.translate.x        2048    512      0.0126 (0.0203)  0.0518 (0.0523)
sky             occluder.scale          4096    2048     0.0237 (0.0250)  0.1237 (0.0857)
==============  ======================  ======  =======  ===============  ===============

The finite-difference references' own noise (mean standard error / max|g_ref|) was
0.010–0.028 with the per-pixel film; the remaining reparam error is mostly its own noise,
plus the small biases measured in test_closed_forms. On ``light.translate.x`` (a faded
light) naive's missing term is below this metric's resolution: at 4096 spp against an
8192 spp reference (noise 0.0076) naive 0.0234, reparam 0.0229; naive's larger error with
the per-pixel film was its noise. That case is not held to the naive comparison.
"""

from __future__ import annotations

import numpy as np
import pytest

import sphere3d as s3

SIZE = 16
CASES = [
    # scene, parameter, reference spp, reparam spp, measured reparam error
    ("shadow", "occluder.translate.x", 2048, 512, 0.0204),
    ("shadow", "light.translate.x", 2048, 1024, 0.0298),
    ("shadow", "camera.translate.x", 2048, 512, 0.0146),
    ("silhouette", "occluder.rotate.z", 2048, 512, 0.0262),
    ("silhouette", "occluder.scale", 2048, 512, 0.0074),
    ("two_occluders", "left.translate.x", 2048, 512, 0.0126),
    ("sky", "occluder.scale", 4096, 2048, 0.0237),
]
NAIVE_UNSEEN = {("shadow", "light.translate.x")}
"""Cases where naive's missing term is below the metric's resolution (module docstring)."""


def _small(name: str) -> dict:
    d = s3.load_scene(name).to_dict()
    d["camera"].update(width=SIZE, height=SIZE)
    return d


@pytest.mark.slow
@pytest.mark.parametrize("scene, param, ref_spp, spp, measured", CASES, ids=[f"{c[0]}-{c[1]}" for c in CASES])
def test01_reparam_agrees_with_a_finite_difference_reference(scene, param, ref_spp, spp, measured):
    d = _small(scene)
    ref = s3.render_gradient(d, param, method="finite_difference", spp=ref_spp, seed=1, h=0.01)
    assert np.abs(ref.derivative).max() > 0.0
    reparam = s3.render_gradient(d, param, method="reparam", spp=spp, seed=2)
    naive = s3.render_gradient(d, param, method="naive", spp=spp, seed=2)
    err, naive_err = reparam.error_vs(ref), naive.error_vs(ref)
    print(f"{scene} {param}: reparam {err:.4f}, naive {naive_err:.4f}")
    assert err <= 1.5 * measured
    assert (scene, param) in NAIVE_UNSEEN or naive_err > 1.3 * err
