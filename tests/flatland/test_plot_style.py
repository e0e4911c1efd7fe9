"""One style for every figure: a fixed colour per method, bands that state their coverage, no backend.

The figure modules (the demo panel and study files, the textbook and tutorial figures)
take their colours from :mod:`flatland.plotting.style` and draw estimates with bands
through :func:`flatland.plotting.bands.draw_estimate`. The tests read the colours and
legend texts back from the artists of figures the modules produce, so a figure that
picks its own colour, or a band whose legend does not say its coverage, fails here.
"""

from __future__ import annotations

import itertools
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib.colors import rgb_to_hsv, same_color, to_rgb
from matplotlib.container import ErrorbarContainer

from flatland.__main__ import PACKAGE
from flatland.app.study import run_study
from flatland.app.study_config import StudyConfig
from flatland.plotting import films, study
from flatland.plotting import textbook as pt
from flatland.plotting import tutorials as ptu
from flatland.plotting.style import (
    METHOD_COLOURS,
    OTHER_COLOURS,
    coverage_label,
    method_colour,
    method_of,
    series_styles,
    symmetric_limit,
)
from tests.flatland.helpers import capture_figures
from tests.flatland.helpers import gradient_image as _grad
from tests.tiers import SLOW

ROOT = Path(__file__).resolve().parents[2]
SHARED = ("naive", "boundary", "reparam")
"""Methods drawn by the demo, study, textbook and tutorial figures of the tests below."""


def _line_colours(ax):
    """Colour of the first labelled curve of each method on ``ax`` (its first variant: the method's own
    colour; further variants take shades of it)."""
    colours = {}
    for line in ax.lines:
        if method_of(line.get_label()):
            colours.setdefault(method_of(line.get_label()), line.get_color())
    return colours


def _errorbar_colours(ax):
    """Colour of each error-bar container's markers on ``ax``, by the method its x tick names."""
    ticks = [t.get_text() for t in ax.get_xticklabels()]
    bars = [c for c in ax.containers if isinstance(c, ErrorbarContainer)]
    return {method_of(tick): bar.lines[0].get_color() for tick, bar in zip(ticks, bars, strict=True)}


def _legend_texts(ax):
    """The texts of the legend of ``ax``, or of its figure's legend when the figure holds it (outside
    the Axes)."""
    legend = ax.get_legend() or (ax.figure.legends[0] if ax.figure.legends else None)
    return [t.get_text() for t in legend.get_texts()]


def _gradient(derivative, method):
    """A small gradient image of one method (the figures' input), as in test_plot."""
    return _grad(derivative, method)


@pytest.fixture(scope="module")
def small_study():
    """A tiny study of the three shared methods on the textbook step (a few seconds)."""
    config = StudyConfig.from_dict(
        {
            "name": "colours",
            "problem": {"integral": "two_steps"},
            "methods": [
                {"method": "naive"},
                {"method": "boundary"},
                {"method": "reparam", "kappa": [1, 10]},
            ],
            "n": 500,
            "trials": 3,
        },
        package=PACKAGE,
    )
    return run_study(config, progress=False)


def test01_every_method_of_every_table_has_its_own_fixed_colour():
    tables = [PACKAGE.methods, PACKAGE.estimators]
    if _has_embree():
        from sphere3d.__main__ import PACKAGE as SPHERE

        tables.append(SPHERE.methods)
    names = {name for table in tables for name in table.names}
    assert {"naive", "finite_difference", "boundary", "reparam"} <= names
    for name in names:
        assert method_of(name) == name and method_colour(name) == METHOD_COLOURS[name], name
    colours = list(METHOD_COLOURS.values())
    assert len(set(colours)) == len(colours)  # one colour per method
    assert not set(colours) & set(OTHER_COLOURS)  # and none of them is used for other series
    # variants and the spellings figures use name their method; other labels name none
    assert method_of("reparam kappa=10 paired") == "reparam" and method_of("reparam, κ × 4") == "reparam"
    assert method_of("finite differences") == method_of("fd h=0.01") == "finite_difference"
    assert method_of("closed form I_j(θ)") == method_of("reference") == "reference"
    assert method_of("reparameterized") is None and method_of("θ = 1") is None
    assert method_colour("θ = 1", "k") == "k"


def _has_embree():
    try:
        import embreex  # noqa: F401
    except ImportError:
        return False
    return True


@SLOW
def test02_a_method_has_the_same_colour_in_demo_study_textbook_and_tutorial_figures(
    tmp_path, monkeypatch, small_study
):
    x = np.linspace(-1.0, 1.0, 32)
    shapes = {"naive": 0 * x, "boundary": np.exp(-20 * x**2), "reparam": np.exp(-20 * x**2) + 0.05 * x}
    seen = {}  # figure -> {method: colour}

    saved = capture_figures(monkeypatch, films)
    primal = _gradient(1 + x**2, "naive")
    columns = {m: _gradient(d, m) for m, d in shapes.items()} | {"finite differences": _gradient(x, "fd")}
    films.plot_panel(primal, columns, tmp_path / "panel.png")
    curves = next(ax for ax in saved[-1].axes if ax.lines and not ax.images)
    seen["demo panel"] = _line_colours(curves)

    saved = capture_figures(monkeypatch, study)
    study.plot_error_time(small_study, tmp_path / "et.png")
    seen["study error/time"] = _line_colours(saved[-1].axes[0])
    study.plot_efficiency(small_study, tmp_path / "eff.png")
    left, right = saved[-1].axes[:2]
    ticks = [t.get_text() for t in left.get_yticklabels()]  # one RMSE bar per row on the right
    seen["study efficiency"] = {
        method_of(t): bar.get_facecolor() for t, bar in zip(ticks, right.patches, strict=True)
    }

    seen["textbook estimates"] = _errorbar_colours(
        pt.plot_estimates({m: (1.0, 0.1) for m in SHARED}, reference=1.0).axes[0]
    )
    seen["textbook curves"] = _line_colours(pt.plot_curves(x, shapes).axes[0])
    seen["tutorial film"] = _line_colours(
        ptu.plot_film({m: (d, 0.1 + 0 * d) for m, d in shapes.items()}).axes[0]
    )
    panel = ptu.plot_gradient_panel(1 + x**2, {m: _gradient(d, m) for m, d in shapes.items()})
    seen["tutorial panel"] = _line_colours(next(ax for ax in panel.axes if ax.lines and not ax.images))
    descent = ptu.plot_descent({m: [1.0, 0.5] for m in SHARED}, {m: [0.0, 0.1] for m in SHARED})
    seen["tutorial descent"] = _line_colours(descent.axes[0])

    for figure, colours in seen.items():
        for method in SHARED:
            if figure == "study error/time" and method == "boundary":
                continue  # exact on the textbook step: its RMSE 0 has no place on log axes, left out
            assert method in colours, (figure, method)
            assert same_color(colours[method], METHOD_COLOURS[method]), (figure, method, colours[method])
    assert "finite_difference" in seen["demo panel"]


@SLOW
def test03_bands_state_their_coverage_in_the_legend(tmp_path, monkeypatch, small_study):
    x = np.linspace(-1.0, 1.0, 16)
    film = ptu.plot_film({"reparam": (x, np.full(16, 0.1)), "bare": x}, level=0.99).axes[0]
    assert _legend_texts(film) == ["reparam ± 99 % interval", "bare"]

    saved = capture_figures(monkeypatch, films)
    films.plot_panel(_gradient(1 + x**2, "naive"), {"boundary": _gradient(x, "boundary")}, tmp_path / "p.png")
    curves = next(ax for ax in saved[-1].axes if ax.lines and not ax.images)
    assert _legend_texts(curves) == ["boundary ± 99 % interval"]  # the one level, flatland.core.stats.LEVEL

    estimates = pt.plot_estimates({"naive": (1.0, 0.1)}, 1.0, level=0.999).axes[0]
    assert "estimate ± 99.9 % interval" in _legend_texts(estimates)
    tradeoff = pt.plot_kappa_tradeoff([1, 10], [0.1, 0.0], [0.01, 0.02], [1.0, 3.0], level=0.999)
    assert "measured bias ± 99.9 % interval" in _legend_texts(tradeoff.axes[0])

    saved = capture_figures(monkeypatch, study)
    study.plot_kappa(small_study, tmp_path / "k.png")
    level = coverage_label(small_study.rows[0].level)
    texts = _legend_texts(saved[-1].axes[0])
    assert texts and all(text.endswith(f"± {level}") for text in texts), texts


@SLOW
def test04_importing_the_plotting_modules_leaves_the_backend_alone():
    """A notebook's backend must survive ``import flatland.plotting...``: run in a fresh interpreter
    with the svg backend selected, import every figure module, and read the backend back."""
    code = (
        "import sys, matplotlib\n"
        "matplotlib.use('svg')\n"
        "import flatland.plotting, flatland.plotting.style, flatland.plotting.bands\n"
        "import flatland.plotting.films, flatland.plotting.study, flatland.plotting.textbook\n"
        "import flatland.plotting.tutorials, flatland.plotting.convergence, flatland.plotting.sketch\n"
        "import flatland.plot, sphere3d.plot\n"
        "print(matplotlib.get_backend(), 'matplotlib.pyplot' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["svg", "False"]


def test05_limits_labels_and_variant_styles():
    a = np.array([-3.0, 1.0, np.inf, np.nan])
    assert symmetric_limit([a], percentile=100.0) == 3.0  # the largest finite |a|
    assert symmetric_limit([np.zeros(3), np.array([np.nan])]) == 1.0
    sparse = np.zeros(1000)
    sparse[0] = -2.0  # non-zero on fewer pixels than the percentile skips
    assert symmetric_limit([sparse]) == 2.0
    assert coverage_label(0.99) == "99 % interval" and coverage_label(0.999) == "99.9 % interval"
    assert coverage_label(0.99999) == "99.999 % interval"
    kappas = [f"reparam kappa={k}" for k in (1, 10, 100, 1000, 10000)]
    styles = series_styles([*kappas, "naive", "uniform"])
    assert styles["reparam kappa=1"]["color"] == METHOD_COLOURS["reparam"]  # the first variant: the colour
    colours = [np.array(to_rgb(styles[k]["color"])) for k in kappas]
    markers = [styles[k]["marker"] for k in kappas]
    assert len(set(markers)) == len(kappas)  # every variant its own marker and its own shade of blue
    assert min(np.abs(a - b).max() for a, b in itertools.combinations(colours, 2)) > 0.08
    hue = rgb_to_hsv(np.array(to_rgb(METHOD_COLOURS["reparam"])))[0]
    assert all(abs(rgb_to_hsv(c)[0] - hue) < 0.02 for c in colours)  # shades: the same hue
    assert styles["naive"]["color"] == METHOD_COLOURS["naive"]
    assert styles["uniform"]["color"] == OTHER_COLOURS[0]
    lines = series_styles(["reparam", "reparam paired", "other"], vary="linestyle", others=False)
    assert lines["reparam"]["linestyle"] != lines["reparam paired"]["linestyle"] and lines["other"] == {}
