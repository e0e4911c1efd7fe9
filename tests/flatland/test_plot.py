"""Figures: written, of a sensible size, not blank, and with the diverging scale centred on zero."""

from __future__ import annotations

import matplotlib.image as mpimg
import numpy as np
import pytest

from flatland import plot
from flatland.__main__ import PACKAGE
from flatland.app.study import run_study
from flatland.app.study_config import StudyConfig
from flatland.core.image import Image
from flatland.plotting import films, study, style
from tests.flatland.helpers import capture_figures
from tests.flatland.helpers import gradient_image as _grad
from tests.tiers import SLOW, sweep

W = 48


def _pixels(path):
    """RGB floats in [0, 1] of a written PNG."""
    rgb = mpimg.imread(path)[..., :3]
    return rgb.astype(np.float64)


def _red(rgb):
    return rgb[..., 0] - rgb[..., 2] > 0.2


def _blue(rgb):
    return rgb[..., 2] - rgb[..., 0] > 0.2


def _not_blank(rgb):
    """Fraction of pixels that are not (near) white."""
    return float(np.mean(np.any(rgb < 0.9, axis=-1)))


@pytest.mark.parametrize("shape", sweep([(W,), (24, 32)], [(24, 32)]), ids=["film1d", "film2d"])
def test01_image_and_gradient_figures_are_written_and_not_blank(tmp_path, shape):
    x = np.linspace(-1.0, 1.0, int(np.prod(shape))).reshape(shape)
    image = Image(
        value=1.0 + np.cos(3 * x), stderr=np.full(shape, 0.05), spp=16, seed=0, batches=4, scene="t"
    )
    png = plot.plot_image(image, tmp_path / "img.png")
    rgb = _pixels(png)
    assert png.stat().st_size > 5_000 and min(rgb.shape[:2]) > 150
    assert _not_blank(rgb) > 0.05 and rgb.std() > 0.05
    gpng = plot.plot_gradient(_grad(x), tmp_path / "grad.png")
    assert _not_blank(_pixels(gpng)) > 0.05


@pytest.mark.parametrize("shape", [(W,), (24, 32)], ids=["film1d", "film2d"])
def test02_diverging_scale_is_centred_on_zero(tmp_path, shape):
    """An antisymmetric derivative paints as much red as blue; a positive one paints no blue at all."""
    x = np.linspace(-1.0, 1.0, int(np.prod(shape))).reshape(shape)
    both = _pixels(plot.plot_gradient(_grad(np.sign(x)), tmp_path / "both.png"))
    red, blue = _red(both).sum(), _blue(both).sum()
    assert red > 500 and blue > 500 and 0.8 < red / blue < 1.25
    positive = _pixels(plot.plot_gradient(_grad(x + 1.0), tmp_path / "pos.png", title="positive"))
    # the colour bar shows the negative half of the scale; the image itself must not
    assert _blue(positive).sum() < 0.5 * _red(positive).sum()


def test03_symmetric_limit_is_shared_and_ignores_a_few_outliers():
    a = np.linspace(-1.0, 1.0, 1000)
    b = 0.5 * a.copy()
    b[3] = 1e6  # one wild finite-difference pixel
    # the larger of the arrays' 99.5th percentiles of |g|: a's, and not b's outlier
    assert style.symmetric_limit([a, b]) == pytest.approx(np.percentile(np.abs(a), 99.5))
    assert style.symmetric_limit([b]) < 1.0
    assert style.symmetric_limit([np.zeros(5)]) == 1.0


@pytest.mark.parametrize("shape", sweep([(W,), (24, 32)], [(24, 32)]), ids=["film1d", "film2d"])
def test04_panel_has_one_column_per_method(tmp_path, shape):
    x = np.linspace(-1.0, 1.0, int(np.prod(shape))).reshape(shape)
    primal = Image(value=1.0 + x**2, stderr=np.full(shape, 0.01), spp=16, seed=0, batches=4, scene="t")
    methods = {
        "naive": 0 * x,
        "boundary": np.exp(-20 * x**2),
        "reparam": np.exp(-20 * x**2) + 0.05 * np.sin(40 * x),
    }
    gradients = {m: _grad(d, m) for m, d in methods.items()} | {
        "finite differences": _grad(np.exp(-20 * x**2))
    }
    png = plot.plot_panel(primal, gradients, tmp_path / "panel.png", title="panel")
    rgb = _pixels(png)
    assert rgb.shape[1] > 4 * 150 and rgb.shape[1] > rgb.shape[0]  # five columns side by side
    assert _not_blank(rgb) > 0.1 and _red(rgb).sum() > 1000


@SLOW
def test05_study_figures_kappa_and_efficiency(tmp_path):
    config = StudyConfig.from_dict(
        {
            "name": "fig",
            "problem": {"integral": "two_steps"},
            "methods": [
                {"method": "naive"},
                {"method": "boundary"},
                {"method": "reparam", "kappa": [1, 10, 100]},
            ],
            "n": 2000,
            "trials": 4,
        },
        package=PACKAGE,
    )
    result = run_study(config, progress=False)
    paths = plot.plot_study(result, tmp_path)
    assert [p.name for p in paths] == ["fig_error_time.png", "fig_kappa.png", "fig_efficiency.png"]
    for p in paths:
        rgb = _pixels(p)
        ink = 0.05 if p.name.endswith("efficiency.png") else 0.02  # line plots: less ink than bars
        assert p.stat().st_size > 20_000 and min(rgb.shape[:2]) > 300 and _not_blank(rgb) > ink
    flat = {"name": "flat", "problem": {"integral": "step"}, "n": 500, "trials": 3}
    flat["methods"] = [{"method": "naive"}, {"method": "reparam"}]
    no_sweep = run_study(StudyConfig.from_dict(flat, package=PACKAGE), progress=False)
    assert [p.name for p in plot.plot_study(no_sweep, tmp_path)] == [
        "flat_error_time.png",
        "flat_efficiency.png",
    ]
    with pytest.raises(ValueError, match="kappa"):
        plot.plot_kappa(no_sweep, tmp_path / "none.png")


def test06_error_time_figure_is_log_log_with_one_line_per_method(tmp_path, monkeypatch):
    config = StudyConfig.from_dict(
        {
            "name": "et",
            "problem": {"integral": "step"},
            "methods": [{"method": "naive", "n": [500, 2000]}, {"method": "reparam", "n": [500, 2000, 8000]}],
            "trials": 3,
        },
        package=PACKAGE,
    )
    result = run_study(config, progress=False)
    figures = capture_figures(monkeypatch, study)
    path = plot.plot_error_time(result, tmp_path / "et.png")
    ax = figures[-1].axes[0]
    labels = [line.get_label() for line in ax.get_lines()]
    assert path.stat().st_size > 10_000 and ax.get_xscale() == "log" and ax.get_yscale() == "log"
    methods = [label for label in labels if not label.startswith(("∝", "_"))]
    assert methods == ["naive (BIASED)", "reparam"] and "∝ 1/√t (guide)" in labels


@pytest.mark.parametrize("shape", sweep([(W,), (24, 32)], [(24, 32)]), ids=["film1d", "film2d"])
@SLOW
def test07_a_sketch_gets_a_left_panel_spanning_every_row_of_each_film_figure(tmp_path, shape, monkeypatch):
    x = np.linspace(-1.0, 1.0, int(np.prod(shape))).reshape(shape)
    image = Image(value=1.0 + x**2, stderr=np.full(shape, 0.01), spp=16, seed=0, batches=4, scene="t")
    figures = capture_figures(monkeypatch, films)
    drawn = []
    sketch = drawn.append  # a sketch draws into the Axes it is given; this one records it
    writers = [
        lambda **kw: plot.plot_image(image, tmp_path / f"i{len(kw)}.png", **kw),
        lambda **kw: plot.plot_gradient(_grad(x), tmp_path / f"g{len(kw)}.png", **kw),
        lambda **kw: plot.plot_panel(image, {"b": _grad(x, "boundary")}, tmp_path / f"p{len(kw)}.png", **kw),
    ]
    for write in writers:
        plain = write()
        plain_width = figures[-1].get_figwidth()
        with_sketch = write(sketch=sketch)
        fig, ax = figures[-1], drawn[-1]
        assert ax.figure is fig and fig.get_figwidth() == pytest.approx(plain_width + films.SKETCH_INCHES)
        spec = ax.get_subplotspec()
        others = [a.get_position().x0 for a in fig.axes if a is not ax]
        assert spec.colspan.start == 0 and ax.get_position().x1 < min(others)  # leftmost, before every film
        assert spec.rowspan == range(spec.get_gridspec().nrows)  # spans every row
        assert _pixels(with_sketch).shape[1] > _pixels(plain).shape[1]
    assert len(drawn) == 3
