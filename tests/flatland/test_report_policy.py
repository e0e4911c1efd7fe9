"""One statistics policy for every printed number: one level, flags that agree with the intervals shown,
digits from the uncertainty, no z of ±inf, and a failed reference requirement printed as a warning.

Cheap checks: the helpers on chosen numbers, the demo's error table on hand-made images, and the demo
verb with a stand-in renderer whose reference can never be precise enough.
"""

from __future__ import annotations

import argparse
import dataclasses
import math

import numpy as np
import pytest
from scipy import stats

from flatland.__main__ import PACKAGE
from flatland.app.commands import REFERENCE_GROWTH, verb_demo
from flatland.app.table import error_table, format_exact, format_interval, format_number, format_z
from flatland.core.bias import PIXEL_ALPHA, error_interval
from flatland.core.image import GradientImage
from flatland.core.stats import LEVEL, family_level, family_quantile, normal_quantile


def test01_one_level_and_the_quantiles_derived_from_it():
    """LEVEL is 99 % two-sided; m rows share it by Šidák (each at LEVEL^(1/m)); the pixel α is 1 - LEVEL."""
    assert LEVEL == 0.99 and abs(PIXEL_ALPHA - 0.01) < 1e-15
    assert family_quantile(1) == normal_quantile(0.99) == pytest.approx(2.5758293, abs=1e-7)
    assert family_level(4) ** 4 == pytest.approx(0.99, rel=1e-14)
    # four independent rows at 0.99^(1/4): P(all cover) = 0.99
    assert stats.norm.cdf(family_quantile(4)) - stats.norm.cdf(-family_quantile(4)) == pytest.approx(
        0.99**0.25
    )
    assert family_quantile(3, dof=7) == pytest.approx(stats.t.ppf(0.5 + 0.5 * 0.99 ** (1 / 3), 7), rel=1e-14)


@pytest.mark.parametrize(
    ("value", "spread", "text"),
    [
        (3.004, 7.0, "+3.0"),  # never "+3.004 ± 7"
        (12.53, 6.9, "+12.5"),
        (10.79, 0.15, "+10.79"),
        (1234.0, 220.0, "+1230"),
        (-0.26303, 0.0116, "-0.263"),
        (-1.775e-17, 4.6e-17, "-1.8e-17"),
        (-0.0004, 0.3, "+0.00"),  # no "-0.00"
        (2.0, 0.0, "+2"),  # no spread: six significant digits
    ],
)
def test02_numbers_keep_two_significant_digits_of_their_uncertainty(value, spread, text):
    assert format_number(value, spread) == text


def test03_intervals_round_with_their_half_width_and_exact_values_say_so():
    assert format_interval(3.004, 3.004 - 7.0, 3.004 + 7.0) == "+3.0 [-4.0, +10.0]"
    assert format_exact(0.0) == "0 exactly (σ = 0)" and format_exact(-0.352) == "-0.352 (σ = 0)"
    assert format_z(math.inf) == format_z(-math.inf) == "—" and format_z(-28.74) == "-28.7"


def test04_a_row_is_flagged_exactly_when_its_interval_excludes_the_reference():
    q = family_quantile(4)
    inside = error_interval(10.0, 0.0, 3.0, 0.4, q)  # |z| = 3.30 > 3.02? no: 10 / hypot(3, 0.4) = 3.30
    assert inside.biased == (abs(inside.z) > q) == (not inside.low <= 0.0 <= inside.high)
    for error in np.linspace(-12.0, 12.0, 49):
        e = error_interval(error, 0.0, 3.0, 0.4, q)
        assert e.biased == (not e.low <= 0.0 <= e.high) == (abs(e.z) > q)
    exact_miss = error_interval(0.0, 2.0, 0.0, 0.0, q)  # no spread, a deterministic miss
    assert exact_miss.biased and math.isinf(exact_miss.z) and exact_miss.spread == 0.0
    assert not error_interval(2.0, 2.0 + 1e-16, 0.0, 0.0, q).biased  # rounding is no miss


def _image(derivative, pixel_stderr, sum_stderr, method):
    return GradientImage(
        value=np.ones(8), derivative=np.broadcast_to(derivative, 8).astype(np.float64),
        value_stderr=np.full(8, 0.1), derivative_stderr=np.full(8, pixel_stderr),
        param="occluder.translate.x", method=method, spp=16, seed=0, batches=16, scene="t",
        derivative_sum_stderr=sum_stderr,
    )  # fmt: skip


def test05_the_error_table_prints_exact_misses_and_a_legend_for_every_column():
    reference = _image(1.0, 0.01, 0.05, "boundary")
    images = {"naive": _image(0.0, 0.0, 0.0, "naive"), "reparam": _image(1.1, 0.2, 1.0, "reparam")}
    table = error_table(images, {"naive": 0.1, "reparam": 0.2}, reference)
    naive = next(line for line in table.splitlines() if line.startswith("naive"))
    assert "BIASED" in naive and "0 exactly (σ = 0)" in naive and "inf" not in table
    reparam = next(line for line in table.splitlines() if line.startswith("reparam"))
    assert "BIASED" not in reparam and "[-" in reparam  # 0.8 ± 3.02 × 1.0 contains 0
    legend = table.split("-\n")[-1]
    for column in (
        "Σ dI/dθ:",
        "Σ - reference [99 % interval]:",
        "z:",
        "px |z|>t:",
        "relative error:",
        "rank:",
    ):
        assert column in legend, column
    assert "simultaneous over the 2 rows" in legend and "m the pixels" in legend


def test06_a_reference_that_cannot_meet_its_requirement_is_a_warning(tmp_path, capsys):
    """A stand-in renderer whose reference keeps the methods' standard error at any spp: the demo grows
    it to REFERENCE_GROWTH × its first count, then says so in the table and on stderr."""
    counts = []

    def render(scene, spp, seed, **kwargs):
        return None

    def render_gradient(scene, param, method, spp, seed, **kwargs):
        if seed == 1:  # the reference (seed + 1)
            counts.append(spp)
        return _image(1.0, 0.5, 1.0, method)

    package = dataclasses.replace(
        PACKAGE, render=render, render_gradient=render_gradient, demo_spp=2, demo_sections=(),
        plot_panel=lambda *args, **kwargs: tmp_path / "panel.png",
    )  # fmt: skip
    args = argparse.Namespace(spp=None, seed=0, out=str(tmp_path), quiet=True)
    assert verb_demo(package, args) == 0
    out, err = capsys.readouterr()
    first = PACKAGE.reference_factor * 2
    assert counts[0] == first and counts[-1] == REFERENCE_GROWTH * first
    assert "(required <= 0.25: NOT MET, see the warning)" in out
    assert err.startswith("warning: the demo's reference is noisier than required (1.00 > 0.25")
