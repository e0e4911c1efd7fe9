"""Every figure the command lines and the tutorials draw is readable: no overlapping tick labels, no text
running into another panel or the colour bar, no legend over data, no legend entry for nothing drawn.

The checks (tests/figure_checks.py) read matplotlib's own extents after a draw. The figures
are drawn by the library's writers and helpers, the same calls as the command lines'
(``demo``, ``render``, ``gradient``, ``study`` of both packages) and the tutorials', with small
settings: the film figures from real small renders, the study figures from small real
studies, the tutorial figures from data of the shapes and ranges the tutorials draw
(decades of κ, signed biases with small intervals, a dozen iterations, a few CPU seconds).
The tutorials' own figures, with their real data, are checked by the same functions while
tests/test_tutorials.py runs them.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from matplotlib.axes import Axes
from matplotlib.figure import Figure

import flatland as fl
from flatland import plot
from flatland.__main__ import PACKAGE
from flatland.app.study import run_study
from flatland.app.study_config import StudyConfig
from flatland.core.image import GradientImage, Image
from flatland.core.optimize import OptimizeResult
from flatland.core.stats import LEVEL, normal_quantile
from flatland.plotting import convergence, films, study
from flatland.plotting import optimize as pto
from flatland.plotting import probe_rays as prb
from flatland.plotting import textbook as pt
from flatland.plotting import tutorials as ptu
from tests.figure_checks import figure_defects
from tests.tiers import sweep

RNG = np.random.default_rng(20191117)
METHOD_TITLES = {
    "naive": "naive",
    "boundary": "boundary",
    "reparam": "reparam",
    "finite differences": "finite_difference",
}


def _captured(monkeypatch, module) -> list[Figure]:
    """The figures ``module`` writes through ``save_png``, in order."""
    figures = []
    original = films.save_png

    def keep(fig, path):
        figures.append(fig)
        return original(fig, path)

    monkeypatch.setattr(module, "save_png", keep)
    return figures


# ---------------------------------------------------------------------------------------- command line
@pytest.fixture(scope="module")
def flatland_films():
    """The demo's renders at small settings: the primal and every method's derivative of ``shadow``."""
    scene = fl.load_scene("shadow")
    param = "occluder.translate.x"
    primal = fl.render(scene, spp=16, seed=0)
    gradients = {
        title: fl.render_gradient(scene, param, method=m, spp=16, seed=0)
        for title, m in METHOD_TITLES.items()
    }
    return scene, param, primal, gradients


def _sphere_films():
    """Images of a sphere3d film's shape and range (24 × 32: a box's outline moving sideways)."""
    y, x = np.mgrid[0:24, 0:32]
    box = ((np.abs(x - 16) < 7) & (np.abs(y - 12) < 5)).astype(float)
    edge = np.gradient(box, axis=1) * 40.0
    primal = Image(
        value=0.2 + 0.6 * box, stderr=np.full(box.shape, 0.01), spp=4, seed=0, batches=4, scene="shadow"
    )
    gradients = {}
    for title, method in METHOD_TITLES.items():
        noise = RNG.standard_normal(box.shape) * (3.0 if method == "finite_difference" else 0.5)
        value = (0.0 if method == "naive" else 1.0) * edge + noise
        gradients[title] = GradientImage(
            value=primal.value,
            derivative=value,
            value_stderr=primal.stderr,
            derivative_stderr=np.full(box.shape, 0.5),
            param="occluder.translate.x",
            method=method,
            spp=4,
            seed=0,
            batches=4,
            scene="shadow",
        )
    return primal, gradients


def cli_flatland_films(tmp_path, monkeypatch, flatland_films):
    scene, param, primal, gradients = flatland_films
    figures = _captured(monkeypatch, films)
    sketch = {"sketch": lambda ax: PACKAGE.sketch(ax, scene, param)}
    plot.plot_panel(
        primal, gradients, tmp_path / "demo_panel.png", title=f"shadow: d/d {param}, 16 spp", **sketch
    )
    plot.plot_image(primal, tmp_path / "shadow.png", title="shadow, 16 spp", sketch=sketch["sketch"])
    for title, g in gradients.items():
        plot.plot_gradient(
            g, tmp_path / f"{title}.png", title=f"shadow: d/d {param}, {title}, 16 spp", **sketch
        )
    return figures


def cli_sphere3d_films(tmp_path, monkeypatch, flatland_films):
    primal, gradients = _sphere_films()
    figures = _captured(monkeypatch, films)
    plot.plot_panel(primal, gradients, tmp_path / "demo_panel.png", title="shadow: d/d occluder.translate.x")
    plot.plot_image(primal, tmp_path / "shadow.png", title="shadow, 64 spp")
    for title, g in gradients.items():
        plot.plot_gradient(
            g, tmp_path / f"{title}.png", title=f"shadow: d/d occluder.translate.x, {title}, 64 spp"
        )
    return figures


def cli_textbook_study(tmp_path, monkeypatch, flatland_films):
    """The built-in ``kappa`` study's cells at small sample counts."""
    config = {
        "name": "kappa",
        "problem": {"integral": "two_steps", "theta": 1.0},
        "methods": [
            {"method": "naive", "n": [500, 2000]},
            {"method": "boundary", "n": [500, 2000]},
            {"method": "finite_difference", "h": [0.01, 0.1], "n": [500, 2000]},
            {
                "method": "reparam",
                "kappa": [1, 10, 100, 1000, 10000],
                "paired": [False, True],
                "n": [500, 2000],
            },
        ],
        "trials": 4,
        "seed": 3,
        "level": LEVEL,
    }
    figures = _captured(monkeypatch, study)
    plot.plot_study(run_study(StudyConfig.from_dict(config, package=PACKAGE), progress=False), tmp_path)
    return figures


def cli_scene_study(tmp_path, monkeypatch, flatland_films):
    """The built-in ``shadow`` study's cells on a 16-pixel film at a few samples per pixel."""
    scene = tmp_path / "shadow.json"
    scene.write_text(json.dumps(fl.load_scene("shadow").with_camera(pixels=16).to_dict()), encoding="utf-8")
    config = {
        "name": "shadow",
        "problem": {"scene": str(scene), "param": "occluder.translate.x"},
        "methods": [
            {"method": "naive", "spp": [2, 8]},
            {"method": "boundary", "spp": [2, 8]},
            {"method": "finite_difference", "h": 0.01, "spp": [2, 8]},
            {"method": "reparam", "kappa": [10, 100, 1000, 10000, 100000], "spp": 4},
            {"method": "reparam", "kappa": 1000, "spp": [2, 8]},
        ],
        "trials": 3,
        "seed": 1,
        "reference": {"spp": 256},
    }
    figures = _captured(monkeypatch, study)
    result = run_study(StudyConfig.from_dict(config, package=PACKAGE), progress=False)
    plot.plot_study(result, tmp_path)
    return figures


# ---------------------------------------------------------------------------------------- tutorials
def _estimate(mean, stderr):
    return (float(mean), float(stderr))


def tutorials_textbook(tmp_path, monkeypatch, flatland_films):
    """Tutorials 1-3: integrands, Leibniz terms, variances, histograms, estimates."""
    x = np.linspace(-0.5, 6.0, 401)
    seed = fl.get_integral("leibniz_seed")
    figs = []
    fig = pt.plot_integrand(
        x,
        fl.detach(seed.f(x, 1.0)),
        seed.discontinuities(fl.variable(1.0)),
        label="θ = 1",
        title="seed example: f = 1 on (2θ, 4θ)",
    )
    pt.plot_integrand(
        x,
        fl.detach(seed.f(x, 1.25)),
        seed.discontinuities(fl.variable(1.25)),
        label="θ = 1.25",
        annotate=False,
        ax=fig.axes[0],
    )
    figs.append(fig)
    names = list(fl.INTEGRALS)
    figs.append(
        pt.plot_terms(
            names,
            {
                "interior ∫ ∂f/∂θ dx": [0.3, 0, 0, 0, 0, 0],
                "discontinuities Σ [f(c⁻) − f(c⁺)] c'": [0, -0.4, 2, -1.3, 0.8, 1.1],
            },
            totals=[0.3, -0.4, 2, -1.3, 0.8, 1.1],
            title="Leibniz terms",
        )
    )
    n = np.array([100, 1000, 10000, 100000])
    figs.append(
        pt.plot_variance(
            n,
            {"uniform": 0.3 / n, "importance": 0.05 / n},
            predicted={"uniform": 0.3 / n, "importance": 0.05 / n},
        )
    )
    runs = RNG.normal(1.0, 0.01, 400)
    figs.append(pt.plot_histogram_vs_normal(runs, 1.0, 0.01, label="naive dI/dθ", level=LEVEL))
    figs.append(
        pt.plot_estimates(
            {
                "uniform": _estimate(0.52, 0.01),
                "importance": _estimate(0.5, 0.002),
                "control variate": _estimate(0.501, 0.001),
            },
            0.5,
            of="value",
            level=LEVEL,
        )
    )
    fig = ptu.plot_grid(
        3, titles=["fixed sampler (v = 0)", "translated with the jump (v = 1)", "truncated at θ"]
    )
    u = np.linspace(0, 1, 200)
    for ax in fig.axes:
        pt.plot_curves(
            u,
            {"h(u, θ)": u**2, "h(u, θ + δ)": u**2 + 0.1},
            marks=[0.5],
            ax=ax,
            xlabel="u",
            ylabel="x = h(u, θ)",
        )
    figs.append(fig)
    figs.append(
        pt.plot_histogram(
            RNG.exponential(size=4000),
            np.linspace(0, 8, 200),
            np.exp(-np.linspace(0, 8, 200)),
            range=(0, 8),
            label="κ (1 − μ·ω), vMF samples",
            density_label="e^(−x)",
            xlabel="κ (1 − μ·ω)",
            title="vMF sampling",
        )
    )
    return figs


def tutorials_kernels(tmp_path, monkeypatch, flatland_films):
    """Tutorial 7: one translation's bias, the κ trade-off on a symmetric-log axis, errors for a budget."""
    kappas = 4.0 ** np.arange(8)
    grid = np.geomspace(kappas[0], kappas[-1], 200)
    figs = []
    for name, sign in (("two_steps", -1.0), ("arc_stretch", 1.0)):
        bias = sign * 2.0 / (1.0 + kappas) + RNG.normal(0.0, 1e-3, kappas.size)
        stderr = 1e-3 * np.sqrt(kappas)
        figs.append(
            pt.plot_kappa_tradeoff(
                kappas,
                bias,
                normal_quantile(LEVEL) * stderr,
                0.3 * np.sqrt(kappas),
                predicted_bias=(grid, sign * 2.0 / (1.0 + grid)),
                predicted_std=(grid, 0.3 * np.sqrt(grid)),
                level=LEVEL,
                title=f"{name} at θ = 1.0, N = 200,000",
            )
        )
    # a scene study's sweep (flatland study shadow): few decades, intervals wider than most biases
    shadow_kappa = np.array([10.0, 100.0, 1000.0, 10000.0, 100000.0])
    figs.append(
        pt.plot_kappa_tradeoff(
            shadow_kappa,
            [-7.0, 3.0, 0.2, -4.0, -30.0],
            [13.0, 9.0, 16.0, 20.0, 8.0],
            [460.0, 300.0, 650.0, 880.0, 1500.0],
            level=LEVEL,
            title="study 'shadow': dI/dθ of shadow:occluder.translate.x",
        )
    )
    rmse = {f"N = {n:,}": np.sqrt((2.0 / (1 + kappas)) ** 2 + 0.09 * kappas / n) for n in (10_000, 1_000_000)}
    figs.append(
        pt.plot_curves(
            kappas,
            rmse,
            logx=True,
            logy=True,
            styles={k: {"marker": "o"} for k in rmse},
            xlabel="κ",
            ylabel="expected error of dI/dθ",
            title="two_steps",
        )
    )
    x = np.linspace(-3, 3, 400)
    figs.append(
        pt.plot_curves(
            x,
            {
                "closed form": np.exp(-x * x),
                "one translation, nearest jump": 0.8 * np.exp(-x * x),
                "reparam κ = 10": 0.95 * np.exp(-x * x),
            },
            xlabel="θ",
            ylabel="dI/dθ",
        )
    )
    return figs


def tutorials_films(tmp_path, monkeypatch, flatland_films):
    """Tutorials 4-6, 9, 10: staircases, panels with the scene, films with bands, the 2D panel."""
    scene, param, primal, gradients = flatland_films
    figs = [
        ptu.plot_gradient_panel(
            primal, gradients, title=f"shadow: d/d {param}", scene=scene, param=param, level=LEVEL
        )
    ]
    figs.append(
        ptu.plot_film(
            {m: gradients[m] for m in ("boundary", "reparam")},
            level=LEVEL,
            scene=scene,
            param=param,
            title="penumbra",
        )
    )
    fig = ptu.plot_grid(3, titles=["the scene", "fade 0", "fade 0.2"])
    ptu.plot_scene(scene, param, ax=fig.axes[0])
    for ax in fig.axes[1:]:
        ptu.plot_film(
            {"boundary": gradients["boundary"], "reparam": gradients["reparam"]}, level=LEVEL, ax=ax
        )
    figs.append(fig)
    theta = np.linspace(0.4, 0.6, 200)
    fig = ptu.plot_grid(2, titles=["∫ 1[x > θ] K(x) dx, N = 40", "pixel 13 of the black bar, 16 samples"])
    for ax in fig.axes:
        pt.plot_curves(
            theta,
            {"closed form": 0.5 - theta, "naive estimate": np.floor(40 * (0.5 - theta)) / 40},
            ax=ax,
            xlabel="θ",
            ylabel="I(θ)",
        )
    figs.append(fig)
    fig = ptu.plot_grid(2, titles=["in x: f(x, θ)", "in y: f(y + θ − θ0, θ)"])
    step = fl.get_integral("step")
    xs = np.linspace(-2.0, 3.0, 401)
    for th in (0.5, 1.1):
        pt.plot_integrand(xs, fl.detach(step.f(xs, th)), [th], label=f"θ = {th}", ax=fig.axes[0])
        pt.plot_integrand(
            xs,
            fl.detach(step.f(xs + th - 0.5, th)),
            [0.5],
            label=f"θ = {th}",
            ax=fig.axes[1],
            xlabel="y",
            ylabel="f(y + θ − θ0, θ)",
        )
    figs.append(fig)
    s_primal, s_gradients = _sphere_films()
    figs.append(
        ptu.plot_gradient_panel(s_primal, s_gradients, title="sphere3d silhouette: d/d box.translate.x")
    )
    figs.append(
        pt.plot_estimates(
            {
                "naive": (0.0, 0.0),
                "reparam κ = 100": (-0.31, 0.01),
                "reparam κ = 1000": (-0.3, 0.02),
                "finite differences": (-0.29, 0.05),
            },
            -0.3,
            title="black triangle under the sky: dE/dθ on S²",
            ylabel="dE/dθ",
            level=LEVEL,
        )
    )
    return figs


def tutorials_probes(tmp_path, monkeypatch, flatland_films):
    """Tutorial 8: probe rays, pairs, brackets, tangent lines and the chosen point, two panels a row."""
    segments = np.array([[[-1.0, 1.0], [0.0, 1.0]], [[-1.0, 2.0], [1.0, 2.0]]])
    ends = np.array([[-0.3, 1.0], [-0.1, 1.0], [0.2, 2.0], [0.6, 2.0]])
    fig = ptu.plot_grid(2, titles=["step 3: the occluder is followed", "step 6: nothing to follow"])
    for ax in fig.axes:
        prb.plot_probes(
            segments,
            [0.0, 0.0],
            ends,
            [0, 0, 1, 1],
            pair=(0, 3),
            bracket=(1, 2),
            point=[0.0, 1.0],
            tangents=[(ends[0], np.array([0.0, -1.0])), (ends[3], np.array([0.0, -1.0]))],
            moving=[0],
            ax=ax,
        )
    return [
        fig,
        prb.plot_probes(
            segments,
            [0.0, 0.0],
            ends,
            [0, 0, 1, 1],
            pair=(0, 3),
            point=[0.0, 1.0],
            title="step 3: the occluder is followed",
        ),
    ]


def tutorials_error_time(tmp_path, monkeypatch, flatland_films):
    """Tutorial 11: error against CPU seconds (a decade or less of time), with bias floors."""
    figs = []
    for seconds in ((0.8, 2.9), (1.7, 6.5, 24.0)):
        series = {
            label: (np.array(seconds) * f, 0.5 / np.sqrt(np.array(seconds) * f) + floor)
            for label, f, floor in (
                ("reparam", 1.0, 0.05),
                ("boundary", 2.2, 0.0),
                ("finite differences", 1.1, 0.002),
            )
        }
        figs.append(
            convergence.plot_error_time(
                series,
                {"reparam": 0.05, "finite differences": 0.002},
                title="hard_shadow: error against time",
            )
        )
    labels = [f"{m} {s} px" for m in ("reparam", "boundary") for s in (1, 2, 20)]
    figs.append(
        pt.plot_estimates(
            {k: (RNG.normal(0, 0.05), 0.02) for k in labels},
            0.0,
            of="value",
            reference_label="unbiased",
            ylabel="share of dI/dθ lost",
            title="black triangle, sideways: silhouette term lost",
            level=LEVEL,
        )
    )
    regions = ("penumbra", "silhouette", "occluder")
    fig = ptu.plot_grid(len(regions), titles=[f"{r}: fraction kept" for r in regions])
    for ax in fig.axes:
        pt.plot_estimates(
            {"reparam": (0.93, 0.01), "boundary": (1.0, 0.02), "finite differences": (1.01, 0.03)},
            1.0,
            of="value",
            ax=ax,
            level=LEVEL,
        )
    figs.append(fig)
    return figs


def _history(method: str, steps: int, views: int, k: int, floor: float) -> OptimizeResult:
    """A run of the shape tutorial 12 draws: the loss falling from about 3 to ``floor`` (naive: to 1),
    θ approaching its target, images of 64-pixel views at the first and the last step."""
    t = np.arange(steps + 1)
    level = 1.0 if method == "naive" else floor
    loss = level + (3.0 - level) * np.exp(-t / 8.0) + RNG.normal(0, 0.3 * level, steps + 1).clip(-0.5 * level)
    truth = RNG.uniform(-0.3, 0.3, k)
    theta = truth * (1 - np.exp(-t / 10.0))[:, None] * (1 + 0.2 * np.sin(t / 6.0))[:, None]
    pixels = np.arange(64)
    target = np.stack([(np.abs(pixels - 32 - 3 * v) > 14).astype(float) for v in range(views)])
    start = np.stack([(np.abs(pixels - 30 - 2 * v) > 10).astype(float) for v in range(views)])
    return OptimizeResult(
        params=tuple(f"p{i}" for i in range(k)), theta=theta, loss=loss, gradient=np.zeros((steps, k)),
        seconds=np.full(steps, {"naive": 0.02, "finite_difference": 0.05}.get(method, 0.04)),
        images={0: start, steps: target + RNG.normal(0, 0.02, target.shape)}, targets=target,
        lower=np.full(k, -np.inf), upper=np.full(k, np.inf), lr=np.full(k, 0.03), decay=0.05,
        method=method, spp=64, seed=0,
    )  # fmt: skip


def tutorials_descent(tmp_path, monkeypatch, flatland_films):
    """Tutorial 12: Adam's runs (images, history, loss curves of four methods) and gradient descent
    over a dozen iterations."""
    run = _history("reparam", 100, 1, 3, 0.08)
    blob = _history("reparam", 100, 4, 5, 0.08)
    runs = {m: _history(m, 100, 1, 3, 0.08) for m in ("reparam", "naive", "boundary", "finite_difference")}
    figs = [
        pto.plot_optimize_images(
            run, labels=["shadow, the camera's view"], title="target, initial, optimised"
        ),
        pto.plot_optimize_images(
            blob, labels=[f"view at {a}°" for a in (0, 45, 90, 135)], title="silhouettes"
        ),
        pto.plot_history(run, truth=run.theta[-1], labels=["x", "y", "albedo"], title="loss and parameters"),
        pto.plot_history(runs["naive"], truth=run.theta[-1], labels=["x", "y", "albedo"], title="naive"),
        pto.plot_loss_curves(runs, title="the four gradient methods"),
    ]
    for steps in (12, 20):
        k = np.arange(steps)
        figs.append(
            ptu.plot_descent(
                {"naive": np.full(steps, 0.4), "reparam": 0.4 * 0.6**k},
                {"naive": np.zeros(steps), "reparam": 0.3 * (1 - 0.6**k)},
                target=0.3,
                title="gradient descent on the occluder's position",
            )
        )
    return figs


CASES = {
    "cli_flatland_films": cli_flatland_films,
    "cli_sphere3d_films": cli_sphere3d_films,
    "cli_textbook_study": cli_textbook_study,
    "cli_scene_study": cli_scene_study,
    "tutorials_textbook": tutorials_textbook,
    "tutorials_kernels": tutorials_kernels,
    "tutorials_films": tutorials_films,
    "tutorials_probes": tutorials_probes,
    "tutorials_error_time": tutorials_error_time,
    "tutorials_descent": tutorials_descent,
}


def _label(fig: Figure) -> str:
    title = fig._suptitle.get_text() if fig._suptitle is not None else ""
    return title or next((ax.get_title() for ax in fig.axes if ax.get_title()), "untitled")


def test01_the_checks_find_each_defect_they_name():
    """A figure made with every defect: overlapping tick labels, a title into another Axes, a legend over
    a curve, and a legend entry with nothing drawn; and the same figure made readable, with none."""
    fig = Figure(figsize=(3, 2.5))
    ax = fig.add_subplot()
    ax.set_yticks(np.linspace(0, 1, 40), [f"{v:.3f}" for v in np.linspace(0, 1, 40)])
    x = np.linspace(0, 1, 50)
    ax.plot(x, np.full_like(x, 0.9), label="curve under the legend")
    ax.plot([], [], label="nothing drawn")
    ax.legend(loc="upper right")
    ax.set_ylim(0.0, 1.0)
    ax.set_title("a long title that runs into the colour bar on its right")
    colorbar = fig.add_axes((0.8, 0.1, 0.05, 0.9))
    defects = "\n".join(figure_defects(fig))
    assert "tick labels" in defects
    assert "runs into the Axes" in defects
    assert "legend covers the line 'curve under the legend'" in defects
    assert "legend entry 'nothing drawn' has nothing drawn" in defects
    clean = Figure(figsize=(5, 3), layout="constrained")
    ax = clean.add_subplot()
    ax.plot(x, x**2, label="curve")
    ax.legend(loc="upper left")
    ax.set_title("short")
    assert figure_defects(clean) == []
    assert isinstance(colorbar, Axes)


@pytest.mark.parametrize("case", sweep(CASES, ["tutorials_probes"]))
def test02_no_figure_has_overlapping_labels_or_a_legend_over_data(
    case, tmp_path, monkeypatch, flatland_films
):
    figures = CASES[case](tmp_path, monkeypatch, flatland_films)
    assert figures, f"{case} drew no figure"
    found = {f"{case} figure {i} ({_label(fig)!r})": figure_defects(fig) for i, fig in enumerate(figures)}
    found = {name: defects for name, defects in found.items() if defects}
    assert not found, "\n".join(f"{name}:\n  " + "\n  ".join(d) for name, d in found.items())


def test03_an_estimates_legend_never_covers_a_bar_whatever_the_values():
    """plot_estimates puts its legend in the upper right and raises the y range under it: estimates whose
    last (rightmost) value is the largest, where a legend in that corner would sit on it, and the
    reverse order, both without a defect; on the same values a legend placed there with the range
    left alone covers the bar (the check can fail)."""
    from flatland.plotting.textbook_estimates import plot_estimates

    values = {"naive": (0.2, 0.01), "reparam": (0.6, 0.02), "boundary": (1.0, 0.01)}
    for order in (values, dict(reversed(values.items()))):
        fig = plot_estimates(order, 0.5, of="value")
        assert figure_defects(fig) == []
    fig = plot_estimates(values, 0.5, of="value")
    ax = fig.axes[0]
    ax.relim()
    ax.autoscale_view()
    ax.legend(loc="upper right", fontsize=8)
    ax.set_ylim(0.0, 1.05)
    assert any("legend covers" in d for d in figure_defects(fig))
