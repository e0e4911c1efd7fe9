"""The tutorials' interactive views: what each draws for its slider values, its speed, and the sliders.

The views compute with the library and return figures; the tests call them as the sliders do and
read the artists back: the step's jump in x moves with θ and stays at θ0 in y, the kernel's width
is 1/sqrt(κ), the probes' count and the chosen point follow the rule of Loubet et al. 2019, Sec. 4.3,
and every figure passes the layout checks of tests/figure_checks.py.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from flatland import widgets
from flatland.core.validate import ValidationError
from tests.figure_checks import figure_defects


def _dotted_x(ax):
    """x of the vertical dotted marks (discontinuities) on ``ax``."""
    return sorted({round(float(line.get_xdata()[0]), 12) for line in ax.lines if line.get_linestyle() == ":"
                   and len(set(np.atleast_1d(line.get_xdata()))) == 1})  # fmt: skip


def test01_the_translation_view_moves_the_jump_in_x_and_keeps_it_at_theta0_in_y():
    fig = widgets.translation_view(1.1)
    in_x, in_y = fig.axes
    assert _dotted_x(in_x) == [0.5, 1.1] and _dotted_x(in_y) == [0.5]
    assert in_y.get_ylabel() == "f(y + θ − θ0, θ)" and in_y.get_xlabel() == "y"
    assert figure_defects(fig) == []


def test02_the_kernel_view_draws_a_kernel_of_width_one_over_sqrt_kappa_and_three_estimates():
    for kappa in (4.0, 100.0):
        fig = widgets.kernel_view(kappa, n=2000)
        kernel = next(line for line in fig.axes[0].lines if line.get_label() == "kernel around a sample")
        x, y = kernel.get_xdata(), kernel.get_ydata()
        half = x[y >= 0.5 * y.max()]
        # full width at half maximum of a Gaussian of standard deviation 1/sqrt(κ): 2 sqrt(2 ln 2)/sqrt(κ)
        expected = 2.0 * np.sqrt(2.0 * np.log(2.0)) / np.sqrt(kappa)
        assert abs((half.max() - half.min()) - expected) <= 2.0 * (x[1] - x[0])
        ticks = [t.get_text().replace("\n", " ") for t in fig.axes[1].get_xticklabels()]
        assert ticks == ["naive", "boundary", f"reparam κ = {kappa:g}"]
        assert figure_defects(fig) == []
    with pytest.raises(ValidationError, match="kappa"):
        widgets.kernel_view(0.0)


def test03_the_probes_view_traces_the_probes_asked_for_and_finds_the_occluders_end():
    fig = widgets.probes_view(probes=4)
    probes = [line for line in fig.axes[0].lines if line.get_gid() == "probe"]
    assert len(probes) == 4
    assert "point (-0.10, 1.00), dp/dθ = 1.00" in fig.axes[0].get_title()  # probe 1's hit, on the occluder
    many = widgets.probes_view(probes=8)
    assert len([line for line in many.axes[0].lines if line.get_gid() == "probe"]) == 8
    far = widgets.probes_view(probes=2, offset=0.4)  # both probes right of the end: the wall alone
    assert "dp/dθ = 0.00" in far.axes[0].get_title()
    for f in (fig, many, far):
        assert figure_defects(f) == []
    with pytest.raises(ValidationError, match="probes"):
        widgets.probes_view(probes=1)


def test04_each_view_redraws_in_well_under_a_second():
    """The slider's promise, with a tenfold margin for a loaded machine: each view at its defaults."""
    for view, value in (
        (widgets.translation_view, 0.8),
        (widgets.kernel_view, 30.0),
        (widgets.probes_view, 6),
    ):
        view(value)  # first call: imports and caches
        start = time.perf_counter()
        view(value)
        assert time.perf_counter() - start < 5.0, view.__name__


def test05_explore_builds_one_slider_per_keyword_and_redraws_on_a_change():
    pytest.importorskip("ipywidgets")
    seen = []

    def view(theta, probes):
        seen.append((theta, probes))
        return widgets.translation_view(theta)

    box = widgets.explore(view, theta=(0.0, 2.0, 0.5), probes=(2, 16, 4))
    theta, probes, output = box.children
    assert type(output).__name__ == "Output"
    assert type(probes).__name__ == "IntSlider" and type(theta).__name__ == "FloatSlider"
    assert seen == [(0.5, 4)]  # drawn once when built
    theta.value = 1.5
    probes.value = 8
    assert seen == [(0.5, 4), (1.5, 4), (1.5, 8)]
    assert box.update() is not None and seen[-1] == (1.5, 8)
