"""The tutorial figures: each helper draws exactly the data it is given, where it promises.

The helpers compute nothing, so the tests read the data back from the matplotlib artists
(line coordinates, band edges at ± z · stderr, image arrays and colour limits) and
compare it with the input; they also check that figures stay out of pyplot's global
list, that result objects are unpacked as documented, that bad input raises one
ValidationError naming the argument, and that a figure renders to a non-blank PNG.
"""

from __future__ import annotations

import io

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.figure import Figure

from flatland.core.image import GradientImage, Image
from flatland.core.stats import normal_quantile
from flatland.core.validate import ValidationError
from flatland.plotting import probe_rays as prb
from flatland.plotting import tutorials as ptu
from flatland.plotting.style import METHOD_COLOURS
from tests.tiers import SLOW

RNG = np.random.default_rng(20191117)


def gradient_image(shape, scale=1.0):
    return GradientImage(
        value=RNG.random(shape),
        derivative=scale * RNG.standard_normal(shape),
        value_stderr=np.full(shape, 0.01),
        derivative_stderr=np.full(shape, 0.1),
        param="p",
        method="m",
        spp=4,
        seed=0,
        batches=4,
    )


def test01_helpers_return_figures_outside_pyplot():
    before = plt.get_fignums()
    film = np.linspace(-1, 1, 8)
    figs = [
        ptu.plot_grid(2),
        ptu.plot_film({"a": film}),
        ptu.plot_gradient_panel(film, {"g": film}),
        ptu.plot_gradient_panel(np.ones((3, 4)), {"g": np.zeros((3, 4))}),
        ptu.plot_descent({"run": [3.0, 1.0]}, {"run": [0.0, 0.2]}, target=0.3),
    ]
    assert all(isinstance(f, Figure) for f in figs)
    assert plt.get_fignums() == before


def test02_plot_grid_makes_the_panels_row_by_row_with_their_titles():
    fig = ptu.plot_grid(3, 2, titles=["a", "b", "c", "d"], title="grid")
    assert len(fig.axes) == 6
    assert [ax.get_title() for ax in fig.axes] == ["a", "b", "c", "d", "", ""]
    rows = [ax.get_subplotspec().rowspan.start for ax in fig.axes]
    cols = [ax.get_subplotspec().colspan.start for ax in fig.axes]
    assert rows == [0, 0, 0, 1, 1, 1] and cols == [0, 1, 2, 0, 1, 2]
    with pytest.raises(ValidationError, match="titles"):
        ptu.plot_grid(1, titles=["a", "b"])
    with pytest.raises(ValidationError, match="ncols"):
        ptu.plot_grid(0)


def test03_plot_film_draws_each_series_over_the_pixel_index_with_z_stderr_bands():
    values = np.array([0.0, 1.0, -2.0, 0.5])
    stderr = np.array([0.1, 0.2, 0.3, 0.4])
    level = 0.99
    fig = ptu.plot_film({"with band": (values, stderr), "bare": 2 * values}, level=level, marks=[1.5])
    ax = fig.axes[0]
    curve, bare = ax.lines[0], ax.lines[1]
    np.testing.assert_array_equal(curve.get_xdata(), np.arange(4))
    np.testing.assert_array_equal(curve.get_ydata(), values)
    np.testing.assert_array_equal(bare.get_ydata(), 2 * values)
    assert len(ax.collections) == 1  # only the series with a standard error has a band
    z = normal_quantile(level)
    vertices = ax.collections[0].get_paths()[0].vertices
    for j in range(values.size):  # at pixel j the band spans values ± z stderr
        ys = vertices[np.isclose(vertices[:, 0], j), 1]
        np.testing.assert_allclose([ys.min(), ys.max()], values[j] + np.array([-z, z]) * stderr[j])
    assert any(line.get_xdata()[0] == 1.5 for line in ax.lines[2:])  # the mark


def test04_plot_film_unpacks_result_objects_and_skips_non_finite_bands():
    g = gradient_image(6)
    image = Image(value=np.arange(6.0), stderr=np.full(6, np.inf), spp=1, seed=0, batches=1)
    fig = ptu.plot_film({"gradient": g, "image": image})
    ax = fig.axes[0]
    np.testing.assert_array_equal(ax.lines[0].get_ydata(), g.derivative)
    np.testing.assert_array_equal(ax.lines[1].get_ydata(), image.value)
    # the image's standard errors are infinite (one batch): its band is empty
    assert len(ax.collections) == 2 and ax.collections[1].get_paths() == []


def test05_plot_film_rejects_mismatched_input_naming_the_series():
    with pytest.raises(ValidationError, match=r"curves\['b'\]"):
        ptu.plot_film({"a": np.zeros(4), "b": np.zeros(5)})
    with pytest.raises(ValidationError, match=r"curves\['a'\].*stderr"):
        ptu.plot_film({"a": (np.zeros(4), np.zeros(3))})
    with pytest.raises(ValidationError, match="1D film"):
        ptu.plot_film({"a": np.zeros((2, 2))})
    with pytest.raises(ValidationError, match="tuple"):
        ptu.plot_film({"a": (np.zeros(2), np.zeros(2), np.zeros(2))})


def test06_the_1d_panel_has_strips_on_one_symmetric_scale_and_the_curves_below():
    primal = np.linspace(0.0, 2.0, 10)
    small, large = 0.1 * RNG.standard_normal(10), gradient_image(10, scale=5.0)
    fig = ptu.plot_gradient_panel(primal, {"small": small, "large": large}, title="panel")
    strips = [ax for ax in fig.axes if ax.images]
    assert [ax.get_title() for ax in strips] == ["primal", "small", "large"]
    np.testing.assert_array_equal(strips[0].images[0].get_array()[0], primal)
    assert strips[0].images[0].get_cmap().name == ptu.PRIMAL
    limit = np.max(np.abs(np.concatenate([small, large.derivative])))
    for ax, data in zip(strips[1:], [small, large.derivative], strict=True):
        im = ax.images[0]
        assert im.get_cmap().name == ptu.DIVERGING
        assert im.norm.vmin == -limit and im.norm.vmax == limit  # shared and centred on zero
        np.testing.assert_array_equal(im.get_array()[0], data)
        assert im.get_extent()[:2] == [-0.5, 9.5]  # pixel j centred on x = j, like the curves
    curves = [ax for ax in fig.axes if ax.get_xlabel() == "pixel" and not ax.images]
    assert len(curves) == 1 and len(curves[0].collections) == 1  # one band: only `large` has stderr
    np.testing.assert_array_equal(curves[0].lines[1].get_ydata(), large.derivative)


def test07_the_2d_panel_draws_images_and_accepts_image_objects():
    g = gradient_image((4, 5))
    fig = ptu.plot_gradient_panel(g, {"reparam": g, "zero": np.zeros((4, 5))})
    images = [ax for ax in fig.axes if ax.images]
    assert len(images) == 3
    np.testing.assert_array_equal(images[0].images[0].get_array(), g.value)
    np.testing.assert_array_equal(images[1].images[0].get_array(), g.derivative)
    assert images[2].images[0].norm.vmax == np.max(np.abs(g.derivative))
    assert not [ax for ax in fig.axes if ax.lines]  # no curve row for a 2D film


def test08_the_panel_rejects_shapes_that_do_not_match_the_primal():
    with pytest.raises(ValidationError, match=r"gradients\['g'\]"):
        ptu.plot_gradient_panel(np.zeros(4), {"g": np.zeros(5)})
    with pytest.raises(ValidationError, match="primal"):
        ptu.plot_gradient_panel(np.zeros((2, 2, 2)), {})


def test09_an_all_zero_derivative_gets_a_unit_colour_scale():
    fig = ptu.plot_gradient_panel(np.ones(3), {"naive": np.zeros(3)})
    strip = [ax for ax in fig.axes if ax.images][1]
    assert strip.images[0].norm.vmin == -1.0 and strip.images[0].norm.vmax == 1.0


def test10_plot_descent_draws_loss_and_parameter_per_iteration_with_the_target():
    loss = {"reparam": [4.0, 1.0, 0.1], "naive": [4.0, 4.0, 4.0]}
    theta = {"reparam": [0.0, 0.2, 0.3], "naive": [0.0, 0.0, 0.0]}
    fig = ptu.plot_descent(loss, theta, target=0.3, title="descent")
    left, right = fig.axes
    assert left.get_yscale() == "log"
    np.testing.assert_array_equal(left.lines[0].get_ydata(), loss["reparam"])
    np.testing.assert_array_equal(right.lines[1].get_ydata(), theta["naive"])
    np.testing.assert_array_equal(right.lines[0].get_xdata(), [0, 1, 2])
    assert right.lines[0].get_color() == left.lines[0].get_color()  # one colour per run
    assert right.lines[-1].get_ydata()[0] == 0.3  # the target line
    with pytest.raises(ValidationError, match="params"):
        ptu.plot_descent(loss, {"reparam": [0.0, 0.1, 0.2]})
    with pytest.raises(ValidationError, match=r"params\['naive'\]"):
        ptu.plot_descent(loss, {"reparam": theta["reparam"], "naive": [0.0]})


@SLOW
def test11_figures_render_to_non_blank_pngs():
    film = np.sin(np.linspace(0, 3, 16))
    figs = [
        ptu.plot_gradient_panel(np.abs(film), {"a": film, "b": -film}),
        ptu.plot_gradient_panel(np.outer(film, film), {"a": np.outer(film, -film)}),
        ptu.plot_descent({"r": [1.0, 0.5]}, {"r": [0.0, 0.1]}),
    ]
    for fig in figs:
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png")
        data = plt.imread(io.BytesIO(buffer.getvalue()))
        assert data.std() > 0.01


# ------------------------------------------------------------------ the probe figure (tutorial 8)
PROBE_SEGMENTS = np.array([[[-1.0, 1.0], [0.0, 1.0]], [[-2.0, 2.0], [2.0, 2.0]]])  # near, wall
PROBE_ENDS = np.array([[-0.3, 1.0], [-0.1, 1.0], [0.2, 2.0], [1.5, 5.0]])  # the last one misses


def _probe_figure(**kw):
    return prb.plot_probes(PROBE_SEGMENTS, [0.0, 0.0], PROBE_ENDS, np.array([0, 0, 1, -1]), **kw)


def _by_gid(ax, gid):
    return [a for a in [*ax.lines, *ax.patches] if a.get_gid() == gid]


def test12_plot_probes_draws_segments_probes_pair_bracket_tangents_and_the_point():
    before = plt.get_fignums()
    fig = _probe_figure(
        pair=(0, 2), bracket=(1, 2), point=[-0.1, 1.0], tangents=[([-0.1, 1.0], [0.0, -1.0])], moving=[0]
    )
    assert isinstance(fig, Figure) and plt.get_fignums() == before
    ax = fig.axes[0]
    segments = _by_gid(ax, "segment")
    assert len(segments) == 2
    for line, (a, b), k in zip(segments, PROBE_SEGMENTS, range(2), strict=True):
        np.testing.assert_array_equal(line.get_xydata(), [a, b])
        assert line.get_color() == prb.SEGMENT_COLOURS[k]
    assert segments[0].get_linewidth() > segments[1].get_linewidth()  # the moving one is thicker
    probes = _by_gid(ax, "probe")
    assert len(probes) == 4
    for line, end in zip(probes, PROBE_ENDS, strict=True):
        np.testing.assert_array_equal(line.get_xydata(), [[0.0, 0.0], end])
    # a hit has the colour of what it hits; a miss is grey and dashed
    assert [p.get_color() for p in probes] == [prb.SEGMENT_COLOURS[0]] * 2 + [
        prb.SEGMENT_COLOURS[1],
        prb.MISS_COLOUR,
    ]
    assert probes[3].get_linestyle() == "--" and probes[0].get_linestyle() == "-"
    widths = [p.get_linewidth() for p in probes]
    assert widths[0] == widths[2] == prb.THICK and widths[1] == widths[3] == prb.THIN  # the pair is thick
    (wedge,) = _by_gid(ax, "bracket")
    np.testing.assert_allclose(wedge.get_xy()[:3], [[0.0, 0.0], PROBE_ENDS[1], PROBE_ENDS[2]])
    (tangent,) = _by_gid(ax, "tangent")
    assert tangent.get_linestyle() == ":"
    (point,) = _by_gid(ax, "point")
    np.testing.assert_array_equal(point.get_xydata(), [[-0.1, 1.0]])
    assert point.get_color() == prb.CHOSEN_COLOUR == METHOD_COLOURS["reparam"]
    assert len(ax.get_legend().get_texts()) == 6
    assert [t.get_text() for t in ax.texts] == ["0", "1", "2", "3"]  # probes numbered in order


def test13_plot_probes_without_a_choice_draws_no_point_and_renders():
    fig = _probe_figure(title="identity")
    ax = fig.axes[0]
    assert _by_gid(ax, "point") == [] and _by_gid(ax, "bracket") == [] and _by_gid(ax, "tangent") == []
    assert ax.get_title() == "identity" and len(ax.get_legend().get_texts()) == 2
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    assert plt.imread(io.BytesIO(buffer.getvalue())).std() > 0.01


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"segments": np.zeros((2, 3))}, "segments"),
        ({"ends": np.full((4, 2), np.nan)}, "ends"),
        ({"hits": np.array([0, 0, 1])}, "hits"),
        ({"hits": np.array([0, 0, 2, -1])}, "hits"),
        ({"pair": (0, 4)}, "pair"),
        ({"bracket": (1,)}, "bracket"),
        ({"point": [1.0]}, "point"),
    ],
)
def test14_plot_probes_rejects_bad_input_naming_the_field(change, field):
    args = {
        "segments": PROBE_SEGMENTS,
        "origin": [0.0, 0.0],
        "ends": PROBE_ENDS,
        "hits": np.array([0, 0, 1, -1]),
    }
    args.update(change)
    with pytest.raises(ValidationError, match=field):
        prb.plot_probes(**args)


def test15_a_flatland_scene_is_sketched_left_of_the_film_and_the_panel():
    film = np.linspace(-1.0, 1.0, 12)
    panel = ptu.plot_gradient_panel(film, {"reparam": film}, scene="shadow", param="occluder.translate.x")
    sketch = panel.axes[0]
    assert sketch.get_title() == "shadow: occluder.translate.x" and sketch.get_aspect() == 1.0
    spec = sketch.get_subplotspec()
    assert spec.colspan.start == 0 and spec.rowspan == range(spec.get_gridspec().nrows)
    assert [ax.get_title() for ax in panel.axes[1:3]] == ["primal", "reparam"]
    assert any(a.get_gid() == "moving:occluder" for a in sketch.get_children())
    lone = ptu.plot_film({"reparam": film}, scene="silhouette", title="film")
    assert [ax.get_title() for ax in lone.axes] == ["silhouette", "film"]
    assert lone.axes[0].get_position().x1 < lone.axes[1].get_position().x0
    grid = ptu.plot_grid(2)
    with pytest.raises(ValidationError, match=r"^scene:"):
        ptu.plot_film({"reparam": film}, scene="shadow", ax=grid.axes[1])
    assert ptu.plot_scene("shadow", ax=grid.axes[0]) is grid
