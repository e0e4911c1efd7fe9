"""The error-against-time figure of the notebooks: it draws the data it is given, where it promises.

The helper computes nothing, so the tests read the data back from the matplotlib artists
(line coordinates, axis scales, colours) and compare it with the input.
"""

from __future__ import annotations

import io

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.colors import same_color
from matplotlib.figure import Figure

from flatland.core.validate import ValidationError
from flatland.plotting.convergence import plot_error_time
from flatland.plotting.style import METHOD_COLOURS, OTHER_COLOURS

SERIES = {
    "reparam": ([0.4, 0.1, 1.6], [0.9, 1.2, 0.8]),
    "boundary": ([0.2, 0.8], [0.5, 0.25]),
    "finite differences": ([0.1, 0.4], [0.6, 0.3]),
    "mine": ([0.3], [0.7]),
}


def _lines(ax):
    return {line.get_label(): line for line in ax.get_lines()}


def test01_each_series_is_drawn_in_time_order_in_its_methods_colour_on_log_axes():
    fig = plot_error_time(SERIES, {"reparam": 0.75}, title="t")
    assert isinstance(fig, Figure) and fig not in map(plt.figure, plt.get_fignums())
    ax = fig.axes[0]
    assert (ax.get_xscale(), ax.get_yscale(), ax.get_title()) == ("log", "log", "t")
    lines = _lines(ax)
    np.testing.assert_array_equal(lines["reparam"].get_xdata(), [0.1, 0.4, 1.6])  # sorted by time
    np.testing.assert_array_equal(lines["reparam"].get_ydata(), [1.2, 0.9, 0.8])  # with their errors
    for label, method in (
        ("reparam", "reparam"),
        ("boundary", "boundary"),
        ("finite differences", "finite_difference"),
    ):
        assert same_color(lines[label].get_color(), METHOD_COLOURS[method]), label
    assert same_color(lines["mine"].get_color(), OTHER_COLOURS[0])
    floor = lines["reparam: bias floor"]
    assert list(floor.get_ydata()) == [0.75, 0.75] and same_color(
        floor.get_color(), METHOD_COLOURS["reparam"]
    )


def test02_the_guide_has_slope_minus_one_half_through_the_points_geometric_centre():
    ax = plot_error_time(SERIES).axes[0]
    guide = _lines(ax)["∝ 1/√t (guide)"]
    t, e = np.asarray(guide.get_xdata()), np.asarray(guide.get_ydata())
    slope = np.diff(np.log(e)) / np.diff(np.log(t))
    np.testing.assert_allclose(slope, -0.5, rtol=1e-12)
    seconds = np.concatenate([s for s, _ in SERIES.values()])
    errors = np.concatenate([r for _, r in SERIES.values()])
    centre_t, centre_e = np.exp(np.mean(np.log(seconds))), np.exp(np.mean(np.log(errors)))
    np.testing.assert_allclose(e[0] * np.sqrt(t[0] / centre_t), centre_e, rtol=1e-12)
    assert (t.min(), t.max()) == (seconds.min(), seconds.max())


def test03_it_draws_into_a_given_axes_and_renders():
    fig = Figure()
    ax = fig.add_subplot()
    assert plot_error_time({"boundary": ([1.0], [1.0])}, {"boundary": 0.0}, ax=ax) is fig
    assert "boundary: bias floor" not in _lines(ax)  # a zero floor has no place on a log axis
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    assert buffer.tell() > 1000


@pytest.mark.parametrize(
    "series, floors, field",
    [
        ({}, None, "series"),
        ({"reparam": ([1.0, 2.0], [1.0])}, None, "series['reparam']"),
        ({"reparam": ([1.0], [0.0])}, None, "series['reparam']"),
        ({"reparam": ([np.nan], [1.0])}, None, "series['reparam']"),
        ({"reparam": 3.0}, None, "series['reparam']"),
        ({"reparam": ([1.0], [1.0])}, {"boundary": 1.0}, "floors"),
    ],
)
def test04_bad_input_is_one_validation_error_naming_the_argument(series, floors, field):
    with pytest.raises(ValidationError) as info:
        plot_error_time(series, floors)
    assert info.value.field == field
