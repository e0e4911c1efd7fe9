"""The study runner on textbook integrals: configuration, grid, statistics, CSV, reference cache.

The κ trade-off from the CSV the command line writes is in test_study_cli.py; the
workers=1 / workers=2 / Dask equality in test_study_parallel.py.
"""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from scipy import stats

from flatland.__main__ import PACKAGE
from flatland.app import study, study_reference
from flatland.app.study import load_config, read_csv, run_study
from flatland.app.study_config import StudyConfig, trial_seed
from flatland.core.image import GradientImage
from flatland.core.stats import normal_quantile
from flatland.core.validate import ValidationError
from flatland.integrals import get_integral


def _config(**overrides):
    data = {
        "problem": {"integral": "step", "theta": 0.5},
        "methods": [{"method": "naive"}, {"method": "reparam"}, {"method": "finite_difference", "h": 0.05}],
        "n": 4000,
        "trials": 12,
        "seed": 7,
    }
    data.update(overrides)
    return StudyConfig.from_dict(data, package=PACKAGE)


def test01_grid_expands_swept_options_in_order():
    config = StudyConfig.from_dict(
        {
            "problem": {"integral": "two_steps"},
            "methods": [
                {"method": "boundary"},
                {"method": "reparam", "kappa": [1, 10], "paired": [False, True], "n": [100, 200]},
            ],
            "n": 50,
            "trials": 3,
        },
        package=PACKAGE,
    )
    cells = config.cells
    assert [c.index for c in cells] == list(range(9))
    assert (cells[0].method, cells[0].options, cells[0].n) == ("boundary", (), 50)
    swept = [(c.options_dict["kappa"], c.options_dict["paired"], c.n) for c in cells[1:]]
    assert swept == [(k, p, n) for k in (1.0, 10.0) for p in (False, True) for n in (100, 200)]
    assert config.problem.theta == get_integral("two_steps").default_theta
    assert cells[4].label == "reparam kappa=1 paired"
    assert config.reference is None  # closed form


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"trials": 1}, "trials:"),
        ({"seed": -1}, "seed:"),
        ({"colour": 3}, "colour:"),
        ({"problem": {"integral": "nope"}}, "problem.integral:"),
        ({"problem": {"integral": "step", "theta": 9.0}}, "problem.theta:"),
        ({"problem": {"integral": "step", "param": "x"}}, "problem.param:"),
        ({"problem": {"integral": "step", "scene": "shadow"}}, "problem:"),
        ({"methods": []}, "methods:"),
        ({"methods": [{"method": "naive"}, {"method": "reparam", "kappa": [1, -2]}]}, "methods[1].kappa:"),
        ({"methods": [{"method": "reparam", "probes": 4}]}, "methods[0].probes:"),
        ({"methods": [{"method": "magic"}]}, "methods[0].method:"),
        ({"methods": [{"method": "naive", "n": 0}]}, "methods[0].n:"),
        ({"methods": [{"method": "naive", "spp": 4}]}, "methods[0].spp:"),
        ({"spp": 16}, "spp:"),
        ({"level": 1.5}, "level:"),
        ({"workers": 0}, "workers:"),
        ({"reference": {"method": "reparam", "kappa": 0}}, "reference.kappa:"),
    ],
)
def test02_configuration_errors_name_the_field(change, field):
    with pytest.raises(ValidationError) as info:
        _config(**change)
    assert str(info.value).startswith(field), str(info.value)


def test03_trial_seeds_depend_only_on_seed_cell_and_trial():
    seeds = {(c, k): trial_seed(5, c, k) for c in range(20) for k in range(20)}
    assert len(set(seeds.values())) == 400
    assert seeds[3, 4] == trial_seed(5, 3, 4)
    assert trial_seed(6, 3, 4) != seeds[3, 4]


def test04_cell_statistics_follow_their_definitions():
    """Each column recomputed from the trial estimates it summarizes. The bias intervals of the 3 cells
    are simultaneous at the one level 0.99 (Šidák: each at 0.99^(1/3)); a cell is flagged exactly
    when its interval excludes 0."""
    result = run_study(_config(), progress=False)
    reference = get_integral("step").derivative(0.5)
    assert result.reference.derivative == reference and result.reference.source == "closed form"
    for row in result.rows:
        d = np.array(row.derivatives)
        assert row.trials == d.size == 12 and row.samples == 4000
        assert row.mean_derivative == pytest.approx(d.mean(), rel=1e-14)
        assert row.variance_per_sample == pytest.approx(d.var(ddof=1) * 4000, rel=1e-12, abs=1e-300)
        assert row.rmse == pytest.approx(np.sqrt(np.mean((d - reference) ** 2)), rel=1e-12)
        assert row.bias == pytest.approx(d.mean() - reference, rel=1e-14, abs=1e-16)
        assert row.relative_error == pytest.approx(np.mean(np.abs(d - reference)) / abs(reference), rel=1e-12)
        half = stats.t.ppf(0.5 + 0.5 * 0.99 ** (1 / 3), 11) * d.std(ddof=1) / np.sqrt(12)
        assert row.level == 0.99 and row.bias_high - row.bias_low == pytest.approx(
            2 * half, rel=1e-9, abs=1e-14
        )
        assert row.biased == (not row.bias_low <= 0.0 <= row.bias_high)
        assert row.seconds_per_sample > 0.0
        cost = row.variance_per_sample * row.seconds_per_sample
        if row.efficiency is not None:  # unbiased cells only (test05, test13)
            assert row.efficiency == (1.0 / cost if cost > 0 else math.inf)
        assert row.equal_time_rmse == pytest.approx(math.sqrt(row.bias**2 + cost / row.time_budget))


def test05_biased_and_unbiased_methods_are_told_apart():
    """Naive drops the whole derivative of the step (bias -dI/dθ, zero variance); the translation
    and finite differences (h² I'''/6 ≈ 2e-4 here, far below their interval) cover the closed form.

    Level 0.999 per interval, seed fixed.
    """
    result = run_study(_config(level=0.999), progress=False)
    naive = result.row("naive")
    assert naive.mean_derivative == 0.0 and naive.variance_per_sample == 0.0
    assert naive.bias == -result.reference.derivative and not naive.bias_contains_zero()
    assert naive.biased and naive.efficiency is None  # efficiency ignores bias: none for a biased cell
    for method in ("reparam", "finite_difference"):
        row = result.row(method)
        assert row.bias_contains_zero(), (method, row.bias_low, row.bias_high)
        assert row.variance_per_sample > 0.0


def test06_boundary_has_zero_variance_up_to_rounding():
    """The boundary estimator of two_steps adds the exact jump term to a zero interior term: its
    spread over trials is floating-point noise, reported as zero variance and an unbiased interval."""
    config = StudyConfig.from_dict(
        {"problem": {"integral": "two_steps"}, "methods": [{"method": "boundary"}], "n": 1000, "trials": 5},
        package=PACKAGE,
    )
    row = run_study(config, progress=False).rows[0]
    assert row.variance_per_sample == 0.0 and math.isinf(row.efficiency)
    assert row.bias_contains_zero() and abs(row.bias) < 1e-14


def test07_csv_round_trips_every_number_exactly(tmp_path):
    result = run_study(_config(trials=3), progress=False)
    path = result.to_csv(tmp_path / "out" / "s.csv")
    rows = read_csv(path)
    assert tuple(rows[0]) == study.CSV_COLUMNS
    for written, row in zip(rows, result.rows, strict=True):
        for column in ("mean_derivative", "bias", "bias_low", "bias_high", "variance_per_sample", "rmse"):
            assert written[column] == getattr(row, column)
        assert written["method"] == row.cell.method and written["n"] == 4000 and written["trials"] == 3
    assert rows[2]["h"] == 0.05 and rows[1]["h"] is None and rows[0]["kappa"] is None
    assert rows[0]["efficiency"] is None and rows[0]["biased"] is True  # naive: biased, no efficiency


def test08_monte_carlo_reference_is_cached_by_its_inputs(tmp_path, monkeypatch):
    config = _config(reference={"method": "finite_difference", "h": 0.01, "n": 20000, "seed": 3}, trials=2)
    first = study_reference.resolve_reference(config, tmp_path)
    files = list(tmp_path.glob("*.npz"))
    assert len(files) == 1 and first.source.startswith("finite_difference h=0.01 n=20000")
    assert "cached" not in first.source

    def fail(*args):
        raise AssertionError("the cached reference should have been used")

    monkeypatch.setattr(study_reference, "_compute_reference", fail)
    second = study_reference.resolve_reference(config, tmp_path)
    assert second.source.endswith("(cached)") and second.derivative == first.derivative
    assert second.stderr == first.stderr > 0.0
    # the reference estimate itself: within z(0.999) standard errors of the closed form (h² bias ~4e-6)
    assert (
        abs(first.derivative - get_integral("step").derivative(0.5)) <= normal_quantile(0.999) * first.stderr
    )

    monkeypatch.undo()
    other = _config(reference={"method": "finite_difference", "h": 0.01, "n": 20000, "seed": 4}, trials=2)
    study_reference.resolve_reference(other, tmp_path)
    assert len(list(tmp_path.glob("*.npz"))) == 2


def test09_load_config_reads_json_and_applies_overrides(tmp_path):
    path = tmp_path / "my_study.json"
    data = {"problem": {"integral": "arc"}, "methods": [{"method": "reparam", "n": [10, 20]}]}
    data.update(n=5, trials=2)
    path.write_text(json.dumps(data))
    config = load_config(path, package=PACKAGE)
    assert config.name == "my_study" and [c.n for c in config.cells] == [10, 20]
    replaced = load_config(path, package=PACKAGE, seed=11, samples=64)
    assert replaced.seed == 11 and [c.n for c in replaced.cells] == [64]
    bad = tmp_path / "bad.json"
    bad.write_text('{"problem": {"integral": "arc"},}')
    with pytest.raises(ValidationError, match=r"bad\.json': invalid JSON: .*line 1"):
        load_config(bad, package=PACKAGE)


def test10_trial_k_of_cell_c_is_the_estimate_with_trial_seed_of_seed_c_k():
    """Each trial recomputed through flatland.estimate with its documented seed: the same numbers."""
    from flatland import estimate

    config = _config(trials=3)
    result = run_study(config, progress=False)
    for c, row in enumerate(result.rows):
        trials = [
            estimate("step", 0.5, row.cell.method, n=4000, seed=trial_seed(7, c, k), **row.cell.options_dict)
            for k in range(3)
        ]
        assert row.derivatives == tuple(e.derivative for e in trials)
        assert row.mean_value == pytest.approx(np.mean([e.value for e in trials]), rel=1e-14)


@pytest.mark.parametrize("pixel", [None, 5], ids=["film_sum", "one_pixel"])
def test11_scene_cells_study_the_film_sum_or_one_pixel_of_the_gradient_image(tmp_path, pixel):
    """Scene problems recomputed through render_gradient: the functional of each trial's gradient
    image, the reference's standard error from independent pixels, and the per-pixel error metric
    relative_error = mean|g - g_ref| / max|g_ref| averaged over the trials."""
    from flatland.core.image import relative_error
    from flatland.render import render_gradient
    from flatland.scene import load_scene

    scene = load_scene("shadow").with_camera(pixels=16)
    path = tmp_path / "small.json"
    path.write_text(json.dumps(scene.to_dict()))
    problem = {"scene": str(path), "param": "occluder.translate.x"}
    if pixel is not None:
        problem["pixel"] = pixel
    config = StudyConfig.from_dict(
        {"problem": problem, "methods": [{"method": "reparam", "kappa": 1000}], "spp": 4, "trials": 3,
         "seed": 5, "reference": {"spp": 32, "seed": 9}}, package=PACKAGE
    )  # fmt: skip
    result = run_study(config, progress=False)
    row = result.rows[0]
    ref = render_gradient(scene, "occluder.translate.x", "boundary", spp=32, seed=9)
    trials = [
        render_gradient(scene, "occluder.translate.x", "reparam", spp=4, seed=trial_seed(5, 0, k), kappa=1000)
        for k in range(3)
    ]

    def functional(image):
        return float(np.sum(image)) if pixel is None else float(image[pixel])

    assert np.array_equal(result.reference.image, ref.derivative)
    assert result.reference.derivative == functional(ref.derivative)
    # the film sum's standard error from the batches' sums (the boundary edge term correlates pixels)
    expected_stderr = ref.derivative_sum_stderr if pixel is None else ref.derivative_stderr[pixel]
    assert result.reference.stderr == pytest.approx(expected_stderr, rel=1e-14)
    assert row.derivatives == tuple(functional(g.derivative) for g in trials)
    assert row.samples == 4 * 16
    assert row.mean_value == pytest.approx(np.mean([functional(g.value) for g in trials]), rel=1e-14)
    errors = [relative_error(g.derivative, ref.derivative) for g in trials]
    assert row.relative_error == pytest.approx(np.mean(errors), rel=1e-14)


def test12_labels_show_the_options_set_true_ones_by_name_floats_by_g():
    from flatland.app.table import method_label

    options = [("kappa", 100.0), ("probes", 4), ("paired", True), ("h", None), ("antithetic", False)]
    assert method_label("reparam", options) == "reparam kappa=100 probes=4 paired"
    config = StudyConfig.from_dict(
        {"problem": {"integral": "two_steps"}, "methods": [{"method": "reparam", "kappa": 0.5}], "n": 10,
         "reference": {"method": "reparam", "kappa": 2000, "paired": True, "n": 20}}, package=PACKAGE
    )  # fmt: skip
    assert config.cells[0].label == "reparam kappa=0.5"  # the defaults filled in are not shown
    source = study_reference.resolve_reference(config).source
    assert source.startswith("reparam kappa=2000 ") and source.endswith(" paired n=20 seed=2147483647")


def _shadow_study(**overrides):
    data = {
        "problem": {"scene": "shadow", "param": "occluder.translate.x"},
        "methods": [{"method": "naive"}, {"method": "boundary"}, {"method": "reparam", "kappa": 1000}],
        "spp": 4,
        "trials": 4,
        "seed": 2,
        "reference": {"spp": 512, "seed": 9},
    }
    data.update(overrides)
    return StudyConfig.from_dict(data, package=PACKAGE)


def printed_intervals(table):
    """(row text, low, high, flagged) of every table row that prints an interval ``[low, high]``."""
    found = []
    for line in table.splitlines()[3:]:  # after the title, the header and its rule
        m = INTERVAL.search(line)
        if m:
            found.append((line, float(m.group(1)), float(m.group(2)), " BIASED " in f" {line} "))
    return found


INTERVAL = re.compile(r"\[([+-][0-9.e+-]+), ([+-][0-9.e+-]+)\]")


def test13_naive_on_the_shadow_is_flagged_has_no_efficiency_and_never_ranks_first():
    """Naive drops the moving shadow edge: its film sum is ~0 against ~10.7, far outside its interval.
    Every printed interval is flagged exactly when it excludes 0, and no z prints as ±inf."""
    result = run_study(_shadow_study(), progress=False)
    naive = result.row("naive")
    assert naive.biased and naive.bias_high < 0.0 and naive.efficiency is None
    assert naive.rank == len(result.rows) and result.ranking()[0].cell.method != "naive"
    assert all(r.rank < naive.rank for r in result.rows if not r.biased)
    table = result.table()
    assert "BIASED" in table and "inf" not in table
    assert table.splitlines()[1].split()[:4] == ["method", "rank", "bias", "z"]
    rows = printed_intervals(table)
    assert len(rows) == len(result.rows)
    assert all(flagged == (not low <= 0.0 <= high) for _, low, high, flagged in rows), rows


def test14_the_reference_ratio_check_raises_or_grows_the_reference(tmp_path):
    """A 4-spp reference against 4 trials of 4 spp has about the cells' standard error: the 1/4 rule fails."""
    config = _shadow_study(reference={"spp": 4, "seed": 9})
    with pytest.raises(ValidationError, match=r"^reference.spp: .* give at least \d+"):
        run_study(config, progress=False, grow_reference=False)
    grown = run_study(config, progress=False, cache_dir=tmp_path)
    judged = min(r.stderr for r in grown.rows if not r.biased and r.stderr > 0)
    assert grown.reference.n > 4 and grown.reference.stderr <= 0.25 * judged


def test15_a_grown_reference_keeps_sixteen_equal_batches():
    """457 spp (prime) left one batch and an infinite standard error: counts are multiples of 16."""
    from flatland.core.bias import reference_spp_needed

    # stderr 1 at 4 spp, target 0.25 x 0.8: (1 / 0.2)^2 x 4 x 1.25 = 125, rounded up to 128
    assert reference_spp_needed(4, 1.0, 0.8) == 128
    assert reference_spp_needed(4, 0.1, 0.8) == 4  # already precise enough
    with pytest.raises(ValueError, match="reference_stderr: must be finite"):
        reference_spp_needed(457, float("inf"), 0.8)


def test16_a_method_judged_by_its_own_kind_of_reference_is_noted():
    """Finite differences against a finite-difference reference share its O(h²) bias: the footer says so."""
    from flatland.app.table import own_method_note

    note = own_method_note(["naive", "finite_difference"], "finite_difference")
    assert note.startswith("finite_difference is the reference's own method") and "O(h²)" in note
    assert own_method_note(["naive", "reparam"], "finite_difference") == ""
    assert "O(h²)" not in own_method_note(["boundary"], "boundary")


def _film(derivative, pixel_stderr, sum_stderr, method="reparam"):
    """A gradient image of 10 pixels whose film sum's standard error is ``sum_stderr`` (None: not given)."""
    return GradientImage(
        value=np.ones(10), derivative=np.broadcast_to(derivative, 10).astype(np.float64),
        value_stderr=np.full(10, 0.1), derivative_stderr=np.full(10, pixel_stderr),
        param="occluder.translate.x", method=method, spp=16, seed=0, batches=16, scene="t",
        derivative_sum_stderr=sum_stderr,
    )  # fmt: skip


def test17_the_error_table_judges_film_sums_by_their_batch_standard_errors():
    """Film sum 10 against 0 (pixels ±0.5): its pixels' standard errors 0.1 in quadrature give 0.32
    and z = 31 (flagged BIASED), the batches' sums (pixels correlated) 5.0 and z = +2.0 (not flagged:
    its 99 % interval 10 ± 2.576 × 5.0 contains 0): the table, the reference's ratio and the printed
    film sum all use the batches' 5.0, to two significant digits of the half-width 12.9."""
    from flatland.app.commands import _film_sum, _reference_ratio
    from flatland.app.table import error_table

    zero_sum = np.tile([0.5, -0.5], 5)
    method = _film(1.0, 0.1, 5.0)
    reference = _film(zero_sum, 0.01, 0.05, method="boundary")
    table = error_table({"reparam": method}, {"reparam": 1.0}, reference)
    row = next(line for line in table.splitlines() if line.startswith("reparam"))
    assert "BIASED" not in row and "+2.0" in row.split() and "+10 [-3, +23]" in row
    assert _reference_ratio({"reparam": method}, reference) == pytest.approx(0.05 / 5.0, rel=1e-15)
    assert _film_sum(method) == "+10 [-3, +23] (99 % interval)"
    # the same images without their batch sums: the quadrature, z = 10 / 0.32
    assert "BIASED" in error_table(
        {"reparam": _film(1.0, 0.1, None)}, {"reparam": 1.0}, _film(zero_sum, 0.01, None)
    )


def test18_a_scene_reference_caches_its_film_sums_standard_error_from_the_batches(tmp_path, monkeypatch):
    """The cached reference reloads the film sum's standard error it stored: the render's, from the
    per-batch sums, not the pixels' in quadrature (measured: 0.75 against 0.47, the boundary edge
    term correlating pixels). A trial's run carries it too, and pickles (worker processes)."""
    import pickle

    from flatland import render_gradient
    from flatland.app.study_trials import _Calls, _run_one

    config = StudyConfig.from_dict(
        {"problem": {"scene": "shadow", "param": "occluder.translate.x"}, "methods": [{"method": "naive"}],
         "spp": 4, "trials": 2, "seed": 5, "reference": {"spp": 32, "seed": 9}}, package=PACKAGE
    )  # fmt: skip
    first = study_reference.resolve_reference(config, tmp_path)
    ref = render_gradient("shadow", "occluder.translate.x", "boundary", spp=32, seed=9)
    quadrature = float(np.sqrt(np.sum(ref.derivative_stderr**2)))
    print(f"film sum stderr: batches {first.stderr:.3f}, quadrature {quadrature:.3f}")
    assert first.stderr == ref.film_sum().stderr == ref.derivative_sum_stderr != quadrature

    def fail(*args):
        raise AssertionError("the cached reference should have been used")

    monkeypatch.setattr(study_reference, "_compute_reference", fail)
    second = study_reference.resolve_reference(config, tmp_path)
    assert second.source.endswith("(cached)") and second.stderr == first.stderr
    assert np.array_equal(second.image_stderr, ref.derivative_stderr)
    run = _run_one(_Calls.of(PACKAGE), config.problem, config.cells[0], 5)
    naive = render_gradient("shadow", "occluder.translate.x", "naive", spp=4, seed=5)
    assert pickle.loads(pickle.dumps(run)).derivative_stderr == naive.derivative_sum_stderr
