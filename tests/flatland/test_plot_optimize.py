"""The optimisation figures (flatland.plotting.optimize) draw exactly the history they are given.

The helpers compute nothing but the elapsed time (the cumulative sum of the steps' seconds), so the
tests read the data back from the matplotlib artists and compare it with a hand-made history: the
target, first and last recorded images per view; the loss and every parameter's trajectory with the
target values as dashed lines in the trajectory's colour; each run's loss against the step and against
the elapsed time. Bad input raises one ValidationError naming the argument; no figure enters pyplot.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pytest

from flatland.core.optimize import OptimizeResult
from flatland.core.validate import ValidationError
from flatland.plotting.optimize import plot_history, plot_loss_curves, plot_optimize_images

RNG = np.random.default_rng(20191117)


def history(method: str = "reparam", steps: int = 3, views: int = 2, k: int = 2) -> OptimizeResult:
    """A made-up run: ``steps`` steps of k parameters, images of ``views`` 5-pixel views at 0 and the end."""
    return OptimizeResult(
        params=tuple(f"p{i}" for i in range(k)),
        theta=RNG.standard_normal((steps + 1, k)),
        loss=np.linspace(4.0, 1.0, steps + 1),
        gradient=RNG.standard_normal((steps, k)),
        seconds=np.array([0.5, 0.25, 1.0])[:steps],
        images={0: RNG.random((views, 5)), steps: RNG.random((views, 5))},
        targets=RNG.random((views, 5)),
        lower=np.full(k, -np.inf),
        upper=np.full(k, np.inf),
        lr=np.full(k, 0.1),
        decay=0.1,
        method=method,
        spp=4,
        seed=0,
    )


def test01_the_images_panel_draws_target_first_and_last_image_per_view():
    before = plt.get_fignums()
    result = history()
    fig = plot_optimize_images(result, labels=("left", "right"), title="run")
    assert plt.get_fignums() == before
    assert [ax.get_title() for ax in fig.axes] == ["left", "right"]
    for v, ax in enumerate(fig.axes):
        target, first, last = ax.lines
        np.testing.assert_array_equal(target.get_xdata(), np.arange(5))
        np.testing.assert_array_equal(target.get_ydata(), result.targets[v])
        np.testing.assert_array_equal(first.get_ydata(), result.images[0][v])
        np.testing.assert_array_equal(last.get_ydata(), result.images[3][v])
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert labels == ["target", "initial (step 0)", "optimised (step 3)"]
    with pytest.raises(ValidationError, match=r"^labels"):
        plot_optimize_images(result, labels=("one",))
    four = plot_optimize_images(history(views=4))  # two rows of two
    spans = [(ax.get_subplotspec().rowspan.start, ax.get_subplotspec().colspan.start) for ax in four.axes]
    assert spans == [(0, 0), (0, 1), (1, 0), (1, 1)]
    assert len(plot_optimize_images(history(views=5)).axes) == 5  # the sixth panel of 2 x 3 removed


def test02_the_history_draws_the_loss_and_each_trajectory_with_its_target():
    result = history(k=3)
    truth = [0.1, -0.2, 0.3]
    fig = plot_history(result, truth=truth, labels=("x", "y", "albedo"))
    left, right = fig.axes
    assert left.get_yscale() == "log"
    np.testing.assert_array_equal(left.lines[0].get_xdata(), np.arange(4))
    np.testing.assert_array_equal(left.lines[0].get_ydata(), result.loss)
    curves = [line for line in right.lines if line.get_linestyle() == "-"]
    targets = [line for line in right.lines if line.get_linestyle() == "--"]
    assert [c.get_label() for c in curves] == ["x", "y", "albedo"]
    for i, (curve, target) in enumerate(zip(curves, targets, strict=True)):
        np.testing.assert_array_equal(curve.get_ydata(), result.theta[:, i])
        assert target.get_ydata()[0] == truth[i] and target.get_color() == curve.get_color()
    assert len({c.get_color() for c in curves}) == 3  # one colour per parameter
    assert len(plot_history(result).axes[1].lines) == 3  # no truth, no dashed lines
    with pytest.raises(ValidationError, match=r"^truth"):
        plot_history(result, truth=[0.1])
    with pytest.raises(ValidationError, match=r"^labels"):
        plot_history(result, labels=("x",))


def test03_the_loss_curves_put_each_run_on_steps_and_on_elapsed_time():
    runs = {"naive": history("naive"), "finite_difference": history("finite_difference")}
    fig = plot_loss_curves(runs)
    by_step, by_time = fig.axes
    for i, result in enumerate(runs.values()):
        np.testing.assert_array_equal(by_step.lines[i].get_xdata(), np.arange(4))
        np.testing.assert_array_equal(by_step.lines[i].get_ydata(), result.loss)
        np.testing.assert_allclose(by_time.lines[i].get_xdata(), [0.0, 0.5, 0.75, 1.75], rtol=0, atol=0)
        assert by_time.lines[i].get_color() == by_step.lines[i].get_color()
    assert by_step.lines[0].get_color() != by_step.lines[1].get_color()
    with pytest.raises(ValidationError, match=r"^runs"):
        plot_loss_curves({})
