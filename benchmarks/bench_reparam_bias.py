"""sphere3d ``reparam``: the share of an exact derivative it misses, against the closed forms.

Two tables, both from :mod:`sphere3d.closed_form`, with ``reparam`` at its defaults
(κ = 1000, 4 probes, spread 3) and 16 independent batches (the ± is one standard error):

camera
    A black triangle about 1, 2, 4, 8 and 20 px across against a sky
    (:func:`~sphere3d.closed_form.pinhole_triangle_scene`, gaussian filter), moving
    sideways (``tri.translate.x``) or in depth (``tri.translate.z``): the share of the
    silhouette term lost, 1 - Σ sign(g) d / Σ |g| over the film (g the closed form,
    :func:`~sphere3d.closed_form.share_lost`).
shading
    The irradiance at the origin (normal +z) under a sky with a black triangle above it
    (:func:`~sphere3d.closed_form.occluded_sky_irradiance`, Lambert's formula): 1 - d / g for
    translations, scale and rotations of the triangle, a large triangle reaching down to near
    the horizon moving sideways, and ``kappa=None``; 2^22 samples, 2^24 where the derivative
    is small against the noise.

``python -m benchmarks --only reparam_bias`` prints the table (about 8 minutes on 2 cores).
"""

from __future__ import annotations

import math

import numpy as np

from benchmarks import Row
from sphere3d import closed_form as cf
from sphere3d.methods import GRADIENT_METHODS
from sphere3d.scene import load_scene
from sphere3d.tasks import ImageTask, PointTask

BATCHES = 16
SEED = 11
MOTIONS = {"sideways": "tri.translate.x", "depth": "tri.translate.z"}
CAMERA_CASES = [
    # triangle size (px), image width (px), spp
    (1, 8, 65536),
    (2, 8, 65536),
    (4, 8, 65536),
    (8, 16, 16384),
    (20, 32, 4096),
]
SKY_TRIANGLE = np.array([[-0.2, -0.5, 1.0], [0.9, 0.1, 1.1], [0.1, 0.6, 0.9]])
"""The shading case's triangle above the origin: no symmetry, so every parameter changes Φ."""
SHADING_N = 1 << 22
SHADING_N_SMALL = 1 << 24
"""For the parameters whose derivative is small against the noise (x-translation, rotations)."""


def horizon_triangle(elevation: float) -> np.ndarray:
    """A large triangle whose lower edge (y from -1.2 to 1.2 at x = 1.5) lies ``elevation`` (radians)
    above the horizon of the origin, its apex at (0.3, 0, 1.5), high in the sky."""
    low = math.hypot(1.5, 1.2) * math.tan(elevation)  # the lower edge's end points at that elevation
    return np.array([[1.5, -1.2, low], [1.5, 1.2, low], [0.3, 0.0, 1.5]])


SHADING_CASES = [
    # label, triangle, parameter, samples, reparam options
    ("z-translation", SKY_TRIANGLE, "tri.translate.z", SHADING_N, {}),
    ("x-translation", SKY_TRIANGLE, "tri.translate.x", SHADING_N_SMALL, {}),
    ("scale", SKY_TRIANGLE, "tri.scale", SHADING_N, {}),
    ("rotation about x", SKY_TRIANGLE, "tri.rotate.x", SHADING_N_SMALL, {}),
    ("rotation about y", SKY_TRIANGLE, "tri.rotate.y", SHADING_N_SMALL, {}),
    (
        "x-translation, lower edge 20 deg up",
        horizon_triangle(math.radians(20.0)),
        "tri.translate.x",
        SHADING_N,
        {},
    ),
    (
        "x-translation, lower edge 10 deg up",
        horizon_triangle(math.radians(10.0)),
        "tri.translate.x",
        SHADING_N,
        {},
    ),
    (
        "x-translation, lower edge 5 deg up",
        horizon_triangle(math.radians(5.0)),
        "tri.translate.x",
        SHADING_N,
        {},
    ),
    ("z-translation, kappa=None", SKY_TRIANGLE, "tri.translate.z", SHADING_N, {"kappa": None}),
    ("scale, kappa=None", SKY_TRIANGLE, "tri.scale", SHADING_N, {"kappa": None}),
]


def camera_loss(size: float, motion: str, width: int, spp: int, seed: int = SEED, **options) -> cf.ShareLost:
    """Share of the silhouette term ``reparam`` misses on the triangle of ``size`` px moving by ``motion``."""
    scene = load_scene(cf.pinhole_triangle_scene(size, width))
    param = MOTIONS[motion]
    exact = cf.triangle_image(scene, param).derivative
    tally = GRADIENT_METHODS.run("reparam", ImageTask(scene, param, spp, seed, BATCHES), **options)
    return cf.share_lost(tally.derivative, exact)


def shading_loss(triangle: np.ndarray, param: str, n: int, seed: int = SEED, **options) -> cf.ShareLost:
    """Share of dE/dθ ``reparam`` misses at the origin (:func:`~sphere3d.closed_form.sky_triangle_scene`)."""
    scene = load_scene(cf.sky_triangle_scene(triangle))
    point, normal = (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)
    _, exact = cf.occluded_sky_irradiance(scene, point, normal, param)
    tally = GRADIENT_METHODS.run(
        "reparam", PointTask(scene, param, point, normal, n, seed, BATCHES), **options
    )
    return cf.share_lost(tally.derivative, np.float64(exact))


def run(camera: bool = True, shading: bool = True) -> list[Row]:
    rows = []
    for size, width, spp in CAMERA_CASES if camera else []:
        for motion in MOTIONS:
            lost = camera_loss(size, motion, width, spp)
            note = f"+- {100 * lost.stderr:.1f} %; {width}x{width}, {spp} spp"
            rows.append(
                Row("reparam bias", f"camera: {size} px triangle, {motion}", 100 * lost.mean, "% lost", note)
            )
    for label, triangle, param, n, options in SHADING_CASES if shading else []:
        lost = shading_loss(triangle, param, n, **options)
        note = f"+- {100 * lost.stderr:.1f} %; n = 2^{n.bit_length() - 1}"
        rows.append(Row("reparam bias", f"shading: {label}", 100 * lost.mean, "% lost", note))
    return rows
