"""The bias atlas (:mod:`benchmarks.atlas`): its cases, its measure and its flags.

The atlas itself is measured by ``make bench``; these tests check that its cases mean what they say
(every case's closed-form derivative is the central difference of its closed-form value, so the
tilt, the pivot and the camera motions are built as named), that a cell of an unbiased method is
not flagged while a method that misses the whole derivative is, and that the page lists every cell.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from benchmarks import atlas
from benchmarks.atlas_cases import FAMILIES, MOTIONS, QUICK, Case, grid


@pytest.mark.parametrize("family", FAMILIES)
def test01_every_motion_and_angle_has_its_closed_form_derivative(family):
    """Dual derivative against [f(h) - f(-h)] / 2h of the case's own value (h = 1e-6), one size per
    family, every motion and viewing angle of the quick grid: < 1e-5 of the scale the atlas measures
    against (the largest pixel derivative on the film, the gross boundary flux in shading, where a
    motion's net derivative may vanish by symmetry)."""
    size = QUICK.film_sizes[1] if family.endswith("film") else QUICK.shading_sizes[1]
    for motion in MOTIONS[family]:
        for angle in QUICK.angles:
            case = Case(family, motion, size, angle, "gaussian" if family.endswith("film") else "")
            exact = np.asarray(case.derivative(), dtype=np.float64)
            diff = np.asarray(case.central_difference(1e-6), dtype=np.float64)
            scale = np.max(np.abs(exact)) if case.film else atlas._scale(case, exact)
            assert scale > 1e-4, case.label()
            assert np.max(np.abs(exact - diff)) < 1e-5 * scale, case.label()


def test02_an_unbiased_cell_is_within_its_quantile_and_a_blind_one_is_flagged(monkeypatch):
    """``finite_difference`` on a flatland film cell (quick samples): |z| against its own expectation
    below the atlas's quantile, with a spread; ``boundary`` exact there (in 2D the film's jumps are
    the segment's two end points, evaluated without sampling); ``naive``, which sees no derivative
    here (a black segment against the sky: only visibility moves), loses 100 % of it and is flagged."""
    monkeypatch.setitem(atlas.METHODS, "naive", ("naive", {}, ("flatland", "sphere3d")))
    monkeypatch.setitem(atlas.QUICK_SAMPLES, "film", 1 << 14)  # 1024 spp: a spread, in seconds
    case = Case("flatland film", "translate x", 2.0, 90.0, "gaussian")
    q = atlas.quantile(len(grid(quick=True)))
    fair = atlas.measure(case, "finite_difference", quick=True)
    assert abs(fair.z) <= q and fair.stderr > 0.0
    assert abs(atlas.measure(case, "boundary", quick=True).lost) < 1e-9
    blind = atlas.measure(case, "naive", quick=True)
    assert blind.lost == pytest.approx(1.0, abs=1e-12) and blind.stderr == 0.0
    assert blind.z == math.inf and blind.flags(q) == "z, > 5 %"  # no spread: off beyond rounding
    assert dataclasses.replace(blind, lost=1e-12).z == 0.0


def test03_the_page_has_a_summary_and_one_line_per_cell():
    cells = [
        atlas.Cell(Case("flatland shading", "rotate", 0.1, 90.0), "boundary", 0.001, 0.01, 0.0, 0.1),
        atlas.Cell(Case("flatland shading", "rotate", 0.01, 5.0), "reparam", 0.5, 0.01, 0.0, 0.1),
    ]
    page = atlas.table(cells, quick=True)
    assert page.startswith("# Bias atlas")
    rows = [line for line in page.splitlines() if line.startswith("| rotate |")]
    assert len(rows) == 2 and rows[1].endswith("| z |")  # 5 degrees: outside the goals, flagged by z only
    assert "| flatland shading | reparam | 1 | 1 | 0 |" in page


def test04_finite_differences_that_saw_no_event_are_not_measured(monkeypatch):
    """At a step so small that no sample can change between θ ± h (1e-9 against 4096 samples),
    finite differences return exactly 0 in every batch: the cell reads ``no event``, is not flagged
    (a bias cannot be told from no event) and is counted as such in the summary, while ``naive``'s
    exact 0 (it draws random numbers but has no derivative to find) stays flagged (test02)."""
    monkeypatch.setitem(atlas.QUICK_SAMPLES, "film", 1 << 12)
    monkeypatch.setitem(atlas.FD_STEP, "flatland", 1e-9)
    case = Case("flatland film", "translate x", 2.0, 90.0, "gaussian")
    cell = atlas.measure(case, "finite_difference", quick=True)
    assert cell.silent and cell.stderr == 0.0 and cell.lost == pytest.approx(1.0, abs=1e-12)
    q = atlas.quantile(len(grid(quick=True)))
    assert math.isnan(cell.z) and cell.flags(q) == ""
    page = atlas.table([cell], quick=True)
    assert "| no event | " in page
    assert page.splitlines()[8].endswith("| 1 | 0 | 0 |  | 1 |")  # cells, flagged, goal, worst, no event


SMALL_SHADING = [("rotate y (turn)", 90.0), ("scale", 10.0), ("translate z (depth)", 10.0), ("scale", 5.0)]


@pytest.mark.parametrize(("motion", "angle"), SMALL_SHADING)
def test05_sphere3d_boundary_is_unbiased_on_a_small_triangle_seen_from_its_ray_origin(motion, angle):
    """``boundary`` on the sphere3d shading cells of a 0.01 rad triangle (quick samples): |z| within
    the atlas's quantile. The closed form is taken at the renderer's ray origin ``point + ε normal``
    (:meth:`benchmarks.atlas_cases.Case.origin`): measured at the point itself, the offset alone
    reads 2.8 % of the gross flux of the turning triangle (z -32); and the edge term's side rays lie
    :data:`sphere3d.boundary.shading.EPS_ANGLE` beside the edge, whose crossing of the acute
    corners at 10 degrees read 0.6 % (z 35) at 1e-5, and at 5 degrees 0.13 % (z 11 on the full
    grid) at 1e-6 with one pair of side rays: the pairs at δ and 2δ extrapolated cancel it."""
    case = Case("sphere3d shading", motion, 0.01, angle)
    q = atlas.quantile(len(grid(quick=True)))
    cell = atlas.measure(case, "boundary", quick=True)
    assert abs(cell.z) <= q, (cell.lost, cell.stderr)
    moved = np.asarray(case.origin()) - np.asarray(case.point)
    assert np.allclose(moved / np.linalg.norm(moved), case.normal) and 0.0 < np.linalg.norm(moved) < 1e-3


def test06_make_bench_turns_the_cells_into_summary_rows_and_the_page(monkeypatch):
    """``benchmarks.bench_atlas`` (what ``make bench`` runs): one row per family and method with its
    flagged cells, and the page of the same cells."""
    from benchmarks import bench_atlas

    cells = [
        atlas.Cell(Case("flatland shading", "rotate", 0.1, 90.0), "boundary", 0.001, 0.01, 0.0, 0.1),
        atlas.Cell(Case("flatland shading", "rotate", 0.01, 5.0), "reparam", 0.5, 0.01, 0.0, 0.1),
    ]
    monkeypatch.setattr(bench_atlas, "run_atlas", lambda **_: cells)
    rows = bench_atlas.run()
    assert [(r.case, r.value) for r in rows] == [
        ("flatland shading, reparam: flagged of 1", 1),
        ("flatland shading, boundary: flagged of 1", 0),
    ]
    page = bench_atlas.markdown(rows)
    assert page.replace(page.split("\n\n")[1] + "\n\n", "", 1) == atlas.table(cells, quick=bench_atlas.QUICK)
    assert page.split("\n\n")[1].startswith("Generated on ") and "from commit" in page


def test07_the_occluder_table_takes_every_motion_of_the_occluder_in_both_scenes(monkeypatch):
    """``benchmarks.bench_occluder_motions``: its motions are every translation, turn and the scale of
    the shape named ``occluder`` in both scenes (the rigid motions a user can differentiate; the
    icosphere's shape coefficients deform it, tests/sphere3d/test_shape_params.py), and one
    scene and motion gives two rows per method (all pixels, and outside the junction pixels), and two
    more for reparam's bias at more samples,
    relative to the reference's RMS (a fake renderer whose every image is the reference reads bias 0,
    its bound 0 and RMSE 0)."""
    from benchmarks import bench_occluder_motions as occ
    from sphere3d.scene import load_scene

    for scene in occ.SCENES:
        mine = {p for p in load_scene(scene).parameters if p.startswith("occluder.") and ".shape." not in p}
        assert mine - {"occluder.albedo", "occluder.emission"} == set(occ.MOTIONS)

    class Fake:
        derivative = np.array([[1.0, -2.0], [0.5, 0.0]])
        derivative_stderr = np.zeros((2, 2))

    # junctions: near the occluder and two static things (the ground and the sky beyond its far edge)
    junctions = occ.junction_pixels("hard_shadow_cube")
    assert 0 < junctions.sum() < 0.02 * junctions.size
    monkeypatch.setattr(occ, "junction_pixels", lambda scene: np.array([[True, False], [False, False]]))
    monkeypatch.setattr(occ, "render_gradient", lambda *a, **k: Fake())
    rows = occ.measure("hard_shadow", "occluder.rotate.z")
    cases = [
        f"hard_shadow occluder.rotate.z {m}: bias / rms{at}{where}"
        for m, at in (*((m, "") for m in occ.METHODS), ("reparam", f" at {occ.BIAS_SPP} spp"))
        for where in ("", " outside junctions")
    ]
    assert [r.case for r in rows] == cases
    assert all(r.value == 0.0 and "bias <= 0.000" in r.note for r in rows)
    assert all(r.note.startswith("bias <= 0.000") for r in rows[::2])
    assert all("RMSE 0.000" in r.note for r in rows[: 2 * len(occ.METHODS) : 2])
    assert all(r.note.startswith("1 junction px left out; bias <= 0.000") for r in rows[1::2])
