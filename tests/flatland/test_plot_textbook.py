"""The textbook figures: each helper draws exactly the data it is given, on the axes it promises.

The helpers compute nothing, so the tests read the data back from the matplotlib artists
and compare it with the input: curve coordinates, marked discontinuities, error-bar
half-widths (z · stderr at the stated level), stacked-bar bottoms, axis scales. They
also check that figures stay out of pyplot's global figure list and that a figure renders
to a non-blank PNG.
"""

from __future__ import annotations

import io

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.collections import LineCollection
from matplotlib.colors import to_rgb
from matplotlib.figure import Figure

from flatland import estimate
from flatland.core.dual import variable
from flatland.core.stats import normal_quantile
from flatland.integrals import INTEGRALS
from flatland.plotting import textbook as pt
from flatland.plotting.style import METHOD_COLOURS, OTHER_COLOURS


def segments_of(ax):
    """All line segments of the error bars on ``ax`` as (x0, y0, x1, y1) rows."""
    rows = []
    for coll in ax.collections:
        if isinstance(coll, LineCollection):
            rows += [(s[0][0], s[0][1], s[1][0], s[1][1]) for s in coll.get_segments()]
    return np.array(rows)


def test01_helpers_return_figures_outside_pyplot():
    before = plt.get_fignums()
    x = np.linspace(0, 1, 5)
    figs = [
        pt.plot_integrand(x, x),
        pt.plot_curves(x, {"a": x}),
        pt.plot_histogram(np.random.default_rng(0).random(100), x, np.ones(5)),
        pt.plot_terms(["a"], {"t": [1.0]}),
        pt.plot_estimates({"a": (1.0, 0.1)}, 1.0),
        pt.plot_variance([10, 100], {"v": [1.0, 0.1]}),
        pt.plot_kappa_tradeoff([1, 10], [0.1, 0.0], [0.01, 0.02], [1.0, 3.0], level=0.99),
        pt.plot_histogram_vs_normal([0.9, 1.0, 1.1], 1.0, 0.1),
    ]
    assert all(isinstance(f, Figure) for f in figs)
    assert plt.get_fignums() == before


def test02_plot_integrand_draws_the_curve_and_one_mark_per_jump_with_its_jump_and_velocity():
    ig = INTEGRALS["leibniz_seed"]
    x = np.linspace(-1, 6, 101)
    y = (x > 2) & (x < 4)
    fig = pt.plot_integrand(x, y, ig.discontinuities(variable(1.0)), label="θ = 1")
    ax = fig.axes[0]
    curve, *marks = ax.lines
    np.testing.assert_array_equal(curve.get_xdata(), x)
    np.testing.assert_array_equal(curve.get_ydata(), y.astype(float))
    assert [m.get_xdata()[0] for m in marks] == [2.0, 4.0]
    texts = [t.get_text() for t in ax.texts]
    assert texts == ["jump -1\nc' = 2", "jump +1\nc' = 4"]


def test03_drawing_into_given_axes_overlays_and_returns_that_figure():
    x = np.linspace(0, 1, 11)
    fig = pt.plot_integrand(x, x, [0.5])
    again = pt.plot_integrand(x, 2 * x, [0.7], annotate=False, ax=fig.axes[0])
    assert again is fig and len(fig.axes) == 1
    assert len(fig.axes[0].lines) == 4  # two curves, two marks
    assert len(fig.axes[0].texts) == 0  # bare locations carry no jump to annotate


def test04_plot_estimates_draws_z_stderr_bars_and_the_reference():
    est = estimate("step", 0.5, "naive", n=2000, seed=1)
    level = 0.99
    fig = pt.plot_estimates(
        {"naive": est, "pair": (0.3, 0.02)}, reference=-0.35, of="derivative", level=level
    )
    ax = fig.axes[0]
    z = normal_quantile(level)
    bars = segments_of(ax)
    halves = np.abs(bars[:, 3] - bars[:, 1]) / 2
    np.testing.assert_allclose(sorted(halves), sorted([z * est.derivative_stderr, z * 0.02]))
    centres = (bars[:, 3] + bars[:, 1]) / 2
    np.testing.assert_allclose(sorted(centres), sorted([est.derivative, 0.3]))
    reference = [line for line in ax.lines if line.get_linestyle() == "--"]
    assert len(reference) == 1 and reference[0].get_ydata()[0] == -0.35
    assert [t.get_text() for t in ax.get_xticklabels()] == ["naive", "pair"]
    assert "estimate ± 99 % interval" in [t.get_text() for t in ax.get_legend().get_texts()]


def test05_plot_estimates_reads_the_value_when_asked():
    est = estimate("step", 0.5, "naive", n=2000, seed=1)
    fig = pt.plot_estimates({"naive": est}, of="value", level=0.999)
    bars = segments_of(fig.axes[0])
    assert (bars[0, 1] + bars[0, 3]) / 2 == pytest.approx(est.value)
    assert fig.axes[0].get_legend().get_texts()[0].get_text() == "estimate ± 99.9 % interval"


def test06_plot_variance_uses_log_axes_and_draws_predictions_dashed():
    n = np.array([10, 100, 1000])
    fig = pt.plot_variance(n, {"measured": 1 / n}, predicted={"measured": 1.1 / n, "guide": 2 / n})
    ax = fig.axes[0]
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
    dashed = [line for line in ax.lines if line.get_linestyle() == "--"]
    assert len(dashed) == 2
    np.testing.assert_allclose(dashed[0].get_ydata(), 1.1 / n)


def test07_plot_kappa_tradeoff_has_bias_and_std_panels_on_log_kappa():
    kappa = np.array([1.0, 10.0, 100.0])
    bias = np.array([-0.1, -0.01, 0.001])
    half = np.array([0.005, 0.01, 0.02])
    std = np.array([1.0, 3.0, 10.0])
    fig = pt.plot_kappa_tradeoff(kappa, bias, half, std, predicted_bias=(kappa, bias), level=0.999)
    left, right = fig.axes
    assert left.get_xscale() == right.get_xscale() == "log"
    assert left.get_yscale() == "symlog" and right.get_yscale() == "log"
    bars = segments_of(left)
    np.testing.assert_allclose(np.abs(bars[:, 3] - bars[:, 1]) / 2, half)
    np.testing.assert_allclose(right.lines[0].get_ydata(), std)
    assert left.get_yaxis().get_transform().linthresh == 0.005  # the smallest half-width


def test08_plot_terms_stacks_positive_up_and_negative_down():
    fig = pt.plot_terms(["a", "b"], {"t1": [1.0, -1.0], "t2": [2.0, 0.5]}, totals=[3.0, -0.5])
    ax = fig.axes[0]
    bars = ax.patches
    bottoms = [b.get_y() for b in bars]
    heights = [b.get_height() for b in bars]
    # t1: a at 0 (height 1), b at 0 (height -1); t2: a on top of t1 (1), b from 0 up (0.5)
    assert bottoms == [0.0, 0.0, 1.0, 0.0] and heights == [1.0, -1.0, 2.0, 0.5]
    totals = next(line for line in ax.lines if line.get_marker() == "D")
    np.testing.assert_array_equal(totals.get_ydata(), [3.0, -0.5])


def test09_plot_curves_and_histogram_draw_what_they_are_given():
    x = np.geomspace(1, 100, 7)
    fig = pt.plot_curves(x, {"a": x, "b": x**2}, logx=True, logy=True, marks=[10.0])
    ax = fig.axes[0]
    assert ax.get_xscale() == ax.get_yscale() == "log"
    np.testing.assert_array_equal(ax.lines[1].get_ydata(), x**2)
    samples = np.random.default_rng(2).normal(size=5000)
    grid = np.linspace(-4, 4, 81)
    fig = pt.plot_histogram(
        samples, grid, np.exp(-(grid**2) / 2) / np.sqrt(2 * np.pi), bins=41, range=(-4, 4)
    )
    ax = fig.axes[0]
    area = sum(p.get_height() * p.get_width() for p in ax.patches)
    assert area == pytest.approx(1.0)  # normalized over the range
    np.testing.assert_array_equal(ax.lines[0].get_xdata(), grid)


@pytest.mark.parametrize(
    ("call", "field"),
    [
        (lambda: pt.plot_integrand([0, 1], [0, 1, 2]), "values"),
        (lambda: pt.plot_curves([0, 1], {"a": [1.0]}), "curves['a']"),
        (lambda: pt.plot_terms(["a", "b"], {"t": [1.0]}), "terms['t']"),
        (lambda: pt.plot_estimates({"a": (1.0, 2.0, 3.0)}), "estimates['a']"),
        (lambda: pt.plot_estimates({"a": (1.0, 2.0)}, of="bias"), "of"),
        (lambda: pt.plot_variance([1, 2], {"v": [1.0]}), "variances['v']"),
        (lambda: pt.plot_kappa_tradeoff([1, 2], [0.1], [0.1, 0.1], [1, 1], level=0.99), "bias"),
        (lambda: pt.plot_histogram_vs_normal([1.0, np.nan], 1.0, 0.1), "estimates"),
        (lambda: pt.plot_histogram_vs_normal([1.0], 1.0, 0.0), "stderr"),
        (lambda: pt.plot_histogram_vs_normal([1.0], np.inf, 0.1), "mean"),
        (lambda: pt.plot_histogram_vs_normal([1.0], 1.0, 0.1, level=1.0), "level"),
    ],
)
def test10_mismatched_input_raises_one_value_error_naming_the_field(call, field):
    with pytest.raises(ValueError) as info:
        call()
    assert str(info.value).startswith(field)


def test11_a_figure_renders_to_a_non_blank_png():
    x = np.linspace(0, 1, 50)
    fig = pt.plot_integrand(x, np.sin(6 * x), [0.3], title="t")
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    image = plt.imread(io.BytesIO(buffer.getvalue()))
    assert image.shape[0] > 100 and image.std() > 0.01


def test12_plot_histogram_vs_normal_draws_the_densities_the_predicted_normal_and_its_interval():
    mean, stderr, level = 2.0, 0.5, 0.99
    estimates = np.array([1.0, 1.9, 2.0, 2.1, 2.2, 3.9, 9.0])  # 9.0 lies outside mean ± 4 stderr
    fig = pt.plot_histogram_vs_normal(estimates, mean, stderr, bins=8, level=level, label="naive dI/dθ")
    ax = fig.axes[0]
    bars = ax.patches
    assert len(bars) == 8
    assert bars[0].get_x() == pytest.approx(mean - 4 * stderr) and bars[0].get_width() == pytest.approx(0.5)
    area = sum(b.get_height() * b.get_width() for b in bars)
    assert area == pytest.approx(6 / 7)  # densities over all estimates: the area is the fraction inside
    assert bars[2].get_height() == pytest.approx(1 / (7 * 0.5))  # 1.0 falls into [1.0, 1.5)
    assert bars[0].get_facecolor()[:3] == pytest.approx(to_rgb(METHOD_COLOURS["naive"]))
    curve = ax.lines[0]
    x, y = curve.get_xdata(), curve.get_ydata()
    np.testing.assert_allclose(y, np.exp(-0.5 * ((x - mean) / stderr) ** 2) / (stderr * np.sqrt(2 * np.pi)))
    assert curve.get_color() == "#000000" and curve.get_linestyle() == "--"
    z = normal_quantile(level)
    marks = sorted(line.get_xdata()[0] for line in ax.lines[1:])
    np.testing.assert_allclose(marks, [mean - z * stderr, mean + z * stderr])
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend == [
        "normal, predicted mean and stderr",
        "mean ± 2.58 stderr, 99 % interval",
        "naive dI/dθ, 7 runs",
    ]
    other = pt.plot_histogram_vs_normal(estimates, mean, stderr, label="plain")
    assert other.axes[0].patches[0].get_facecolor()[:3] == pytest.approx(to_rgb(OTHER_COLOURS[0]))
