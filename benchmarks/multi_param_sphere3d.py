"""sphere3d's rows of ``bench_multi_param``: k = 8 parameters per pass against k = 1, and reparam against
finite differences at k = 8 (the module is not a ``bench_*`` page of its own).

:func:`sphere3d.render.render_gradient` on ``hard_shadow`` (64 × 64 px) at :data:`SPP` samples per pixel
(seed 0, default options), once with ``occluder.translate.x`` (k = 1) and once with the occluder's eight
parameters :data:`OCCLUDER` (k = 8: its translations, rotations, scale and albedo), fastest of the
repeats. ``reparam`` renders them in one pass (they move one shape), ``finite_difference`` in
2k + 1 = 17 renders.

The comparison with finite differences, for k = 8: the RMSE per parameter of an image against a
reference, $\\mathrm{RMSE}_i = \\sqrt{\\max(0, \\overline{(x_i - r_i)^2} - \\overline{s_i^2})}$ over the
pixels, r_i the reference image of parameter i (``boundary``, unbiased, all eight in one pass at
:data:`REFERENCE_SPP` spp, another seed) and s_i its standard errors: the reference's own variance,
independent of x, is subtracted. ``finite_difference`` at :data:`SPP` spp gives each parameter its
RMSE (listed relative to the reference's RMS: the rotations of a sphere move its image by its facets
only, a derivative near 0 under much noise at the silhouette); ``reparam`` is run at 1, 2, 4, ... spp
(seed 0) until every parameter's RMSE is at most FD's, and that run's time (fastest of the repeats) is
compared with FD's (goal: at most a third); ``boundary`` likewise, for comparison. The ratio of the
RMSEs at the reported spp is the worst over the parameters, named in the note.
"""

from __future__ import annotations

import numpy as np

from benchmarks import Row, best_seconds
from sphere3d.render import render_gradient
from sphere3d.scene import load_scene

SCENE = "hard_shadow"
SPP = 16
REFERENCE_SPP = 256
"""Samples per pixel of the boundary reference (all eight parameters in one pass)."""
OCCLUDER = [
    "occluder.translate.x",
    "occluder.translate.y",
    "occluder.translate.z",
    "occluder.rotate.x",
    "occluder.rotate.y",
    "occluder.rotate.z",
    "occluder.scale",
    "occluder.albedo",
]
METHODS = ("naive", "boundary", "reparam", "finite_difference")
GOAL, FD_GOAL = 3.0, 1.0 / 3.0
"""Most k = 8 may cost against k = 1 (every method but finite differences); most of FD's time reparam
may take to reach its RMSE on every parameter."""
LADDER = (1, 2, 4, 8, 16, 32, 64, 128)
"""Samples per pixel tried, in order, against FD's RMSE (reparam, and boundary for comparison)."""


def _rmse(images, reference) -> np.ndarray:
    """Per parameter, the RMSE over the pixels with the reference's own variance taken out (module doc)."""
    err = np.mean((images.derivative - reference.derivative) ** 2, axis=(1, 2))
    floor = np.mean(reference.derivative_stderr**2, axis=(1, 2))
    return np.sqrt(np.maximum(err - floor, 0.0))


def sphere3d_rows(repeats: int = 3) -> list[Row]:
    """Seconds at k = 1 and k = 8 per method and their ratio; reparam's time to FD's RMSE at k = 8."""
    scene = load_scene(SCENE)
    case = f"sphere3d {SCENE} {scene.camera.width}x{scene.camera.height} px x {SPP} spp"
    rows, seconds = [], {}
    for method in METHODS:

        def call(param, m=method):
            return render_gradient(scene, param, m, spp=SPP, seed=0, progress=False)

        one = best_seconds(lambda c=call: c(OCCLUDER[0]), repeats)
        eight = seconds[method] = best_seconds(lambda c=call: c(OCCLUDER), repeats)
        ratio = eight / one
        if method == "finite_difference":
            note = f"2k + 1 = {2 * len(OCCLUDER) + 1} renders against 3: no goal"
        else:
            note = f"goal <= {GOAL:g}x: {'met' if ratio <= GOAL else 'not met'}"
        rows += [
            Row("multi_param", f"{case}: {method}, k = 1", one, "s"),
            Row("multi_param", f"{case}: {method}, k = {len(OCCLUDER)}", eight, "s"),
            Row("multi_param", f"{case}: {method}, k = {len(OCCLUDER)} / k = 1", ratio, "x", note),
        ]
    return rows + _against_fd(scene, seconds["finite_difference"], repeats)


def _against_fd(scene, fd_seconds: float, repeats: int) -> list[Row]:
    """reparam's (and boundary's) time to reach FD's RMSE on every one of the eight parameters (module
    docstring)."""
    reference = render_gradient(scene, OCCLUDER, "boundary", spp=REFERENCE_SPP, seed=1, progress=False)
    fd = _rmse(
        render_gradient(scene, OCCLUDER, "finite_difference", spp=SPP, seed=0, progress=False), reference
    )
    scale = np.sqrt(np.mean(reference.derivative**2, axis=(1, 2)))
    case = f"sphere3d {SCENE}, k = {len(OCCLUDER)}"
    rows = [Row("multi_param", f"{case}: finite_difference RMSE / reference RMS, {name}", float(e / r), "",
                f"{SPP} spp") for name, e, r in zip(OCCLUDER, fd, scale, strict=True)]  # fmt: skip
    for method in ("reparam", "boundary"):
        rows += _reach(scene, method, reference, fd, fd_seconds, repeats, case)
    return rows


def _reach(scene, method: str, reference, fd: np.ndarray, fd_seconds: float, repeats: int, case: str) -> list:
    """The first spp of :data:`LADDER` at which ``method`` has at most FD's RMSE on every parameter, the
    worst ratio there and its time (fastest of ``repeats``) over FD's."""
    name = f"{case}: {method}"
    same: list[Row] = []  # at FD's spp, per parameter
    for spp in LADDER:
        images = render_gradient(scene, OCCLUDER, method, spp=spp, seed=0, progress=False)
        ratios = _rmse(images, reference) / fd
        worst = OCCLUDER[int(np.argmax(ratios))]
        if spp == SPP:
            same = [Row("multi_param", f"{name} RMSE / FD RMSE at {SPP} spp, {p}", float(r), "x")
                    for p, r in zip(OCCLUDER, ratios, strict=True)]  # fmt: skip
        if np.max(ratios) <= 1.0:
            seconds = best_seconds(
                lambda s=spp: render_gradient(scene, OCCLUDER, method, spp=s, seed=0, progress=False), repeats
            )
            share = seconds / fd_seconds
            goal = f"goal <= 1/3: {'met' if share <= FD_GOAL else 'not met'}" if method == "reparam" else ""
            return [
                *same,
                Row("multi_param", f"{name} spp to reach FD's RMSE on every parameter", spp, "spp"),
                Row(
                    "multi_param",
                    f"{name} RMSE / FD RMSE there, worst parameter",
                    float(np.max(ratios)),
                    "x",
                    worst,
                ),
                Row("multi_param", f"{name} time there / FD time ({SPP} spp, 17 renders)", share, "x", goal),
            ]
    at = f"{name} at {LADDER[-1]} spp, RMSE / FD RMSE, worst parameter"
    return [*same, Row("multi_param", at, float(np.max(ratios)), "x", f"{worst}: FD's RMSE not reached")]
