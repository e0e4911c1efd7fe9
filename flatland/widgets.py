r"""Interactive views for the tutorials: sliders for θ, the kernel's κ and the number of probe rays.

Each view is a plain function that computes what it shows with the library and returns a
:class:`~matplotlib.figure.Figure` (made without pyplot), so it can be called, tested and
timed without a notebook; :func:`explore` puts it behind ipywidgets sliders, redrawing on
every change. Every view costs a few hundredths of a second at its default settings.

=========================  ===========================================================
:func:`translation_view`   tutorial 6: the step in x and in y = x − (θ − θ0), for θ
:func:`kernel_view`        tutorial 7: a translation per sample inside a kernel of
                           concentration κ on ``two_steps``, and the estimate it gives
:func:`probes_view`        tutorial 8: probe rays around a sample near an occluder's end,
                           their number, and the point the rule of Sec. 4.3 chooses
=========================  ===========================================================

ipywidgets is imported only by :func:`explore`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from flatland.core.dual import detach, tangent, variable
from flatland.core.validate import ValidationError
from flatland.integrals import get_integral
from flatland.plotting import textbook as pt
from flatland.plotting.probe_rays import plot_probes
from flatland.plotting.style import legend_outside
from flatland.plotting.tutorials import plot_grid
from flatland.reparam.probes import select_points
from flatland.scene import load_scene
from flatland.state import build_state
from flatland.textbook import estimate
from flatland.tracing import attached_points, cast, film_direction

__all__ = ["explore", "kernel_view", "probes_view", "translation_view"]

GRID = np.linspace(-2.0, 3.0, 801)
"""Abscissae of the integrands drawn by the views."""


def translation_view(theta: float, theta0: float = 0.5) -> Figure:
    r"""The textbook step $f(x, θ) = 1_{x > θ} K(x)$ at $θ_0$ and at θ, in x and in $y = x − (θ − θ_0)$.

    In x the jump moves with θ; in y (the translation $T(y, θ) = y + θ − θ_0$ of tutorial 6,
    Loubet et al. 2019, Sec. 3.2) it stays at $θ_0$ and the smooth factor slides under it.
    """
    step = get_integral("step")
    fig = plot_grid(2, titles=["in x: f(x, θ)", "in y: f(y + θ − θ0, θ)"])
    for th in dict.fromkeys((theta0, float(theta))):
        label = f"θ = {th:g}"
        pt.plot_integrand(GRID, detach(step.f(GRID, th)), [th], label=label, ax=fig.axes[0])
        pt.plot_integrand(
            GRID,
            detach(step.f(GRID + (th - theta0), th)),
            [theta0],
            label=label,
            ax=fig.axes[1],
            xlabel="y",
            ylabel="f(y + θ − θ0, θ)",
        )
    return fig


def kernel_view(kappa: float, theta: float = 1.0, n: int = 20_000, seed: int = 1) -> Figure:
    r"""``two_steps`` at θ with a kernel of concentration κ around one sample, and reparam's estimate.

    Left: the integrand, its two jumps (moving at different speeds) and the Gaussian kernel of
    standard deviation $1/\sqrt{κ}$ around the sample midway between them. A wide kernel (small
    κ) reaches both jumps, and the one translation per kernel follows only the nearer: bias; a
    narrow one (large κ) reaches neither for most samples, and the kernel weight's derivative
    grows like $\sqrt{κ}$: variance (Loubet et al. 2019, Sec. 4.2). Right: the estimate with its
    99 % interval beside naive, boundary and the closed form, from ``n`` samples.
    """
    if not kappa > 0:
        raise ValidationError("kappa", f"must be > 0, got {kappa!r}")
    integral = get_integral("two_steps")
    jumps = integral.discontinuities(variable(theta))
    where = [float(detach(d.location)) for d in jumps]
    x = np.linspace(min(where) - 2.0, max(where) + 2.0, 801)
    fig = plot_grid(
        2, titles=[f"two_steps at θ = {theta:g}, kernel κ = {kappa:g}", f"dI/dθ from {n:,} samples"]
    )
    pt.plot_integrand(x, detach(integral.f(x, theta)), jumps, label="f(x, θ)", annotate=False, ax=fig.axes[0])
    centre, width = 0.5 * (where[0] + where[-1]), 1.0 / np.sqrt(kappa)
    kernel = np.exp(-0.5 * ((x - centre) / width) ** 2)
    scale = float(np.max(np.abs(detach(integral.f(x, theta))))) or 1.0
    pt.plot_curves(
        x,
        {"kernel around a sample": scale * kernel},
        ax=fig.axes[0],
        xlabel="x",
        ylabel="f(x, θ)",
        styles={"kernel around a sample": {"linestyle": ":"}},
    )
    estimates = {
        "naive": estimate("two_steps", theta, method="naive", n=n, seed=seed),
        "boundary": estimate("two_steps", theta, method="boundary", n=n, seed=seed),
        f"reparam κ = {kappa:g}": estimate("two_steps", theta, method="reparam", n=n, seed=seed, kappa=kappa),
    }
    legend_outside(fig.axes[0], "below", ncols=2)
    pt.plot_estimates(estimates, integral.derivative(theta), ax=fig.axes[1])
    return fig


def probes_view(probes: int = 4, offset: float = 0.0, spread: float = 3.0, sigma: float = 0.1) -> Figure:
    r"""Probe rays around one film sample near an occluder's end, and the point the rule chooses.

    A camera at the origin looks along +y at an occluder from (-1, 1) to (0, 1) in front of a
    wall at y = 2 (tutorial 8's first scene, the occluder moving along x). ``probes`` rays at
    film coordinates ``offset`` + σ · spread · linspace(-1, 1) are traced and handed to
    :func:`~flatland.reparam.probes.select_points` (Loubet et al. 2019, Sec. 4.3). With too
    few probes, or probes too far from the occluder's end, none brackets it and the point
    chosen is not the end (or nothing is chosen).
    """
    if int(probes) < 2:
        raise ValidationError("probes", f"must be >= 2, got {probes!r}")
    camera = {"position": [0.0, 0.0], "direction": [0.0, 1.0], "fov": 1.0, "pixels": 4}
    shapes = [
        {"name": "near", "type": "segment", "points": [[-1.0, 1.0], [0.0, 1.0]]},
        {"name": "wall", "type": "segment", "points": [[-1.0, 2.0], [1.0, 2.0]]},
    ]
    scene = load_scene({"name": "probes", "camera": camera, "shapes": shapes})
    geom = build_state(scene, "near.translate.x", variable(0.0))
    geom0 = geom.detached()
    origin = np.zeros(2)
    t = offset + sigma * spread * np.linspace(-1.0, 1.0, int(probes))
    hits = cast(geom0, origin, film_direction(geom0, t))
    choice = select_points(
        geom, origin[None], hits.prim[None], hits.coord[None], film_direction(geom0, np.array([offset]))
    )
    hit = hits.prim >= 0
    points, _ = attached_points(geom0, np.maximum(hits.prim, 0), hits.coord)
    ends = np.where(hit[:, None], points, origin + 3.5 * film_direction(geom0, t))
    shape = np.where(hit, geom.prim_shape[np.maximum(hits.prim, 0)], -1)
    differs = np.flatnonzero(shape != shape[0])
    switch = np.flatnonzero(shape[1:] != shape[:-1])
    chosen = int(choice.code[0])
    point = detach(choice.point)[0] if chosen >= 0 else None
    velocity = tangent(choice.point)[0] if chosen >= 0 else None
    segments = np.stack([detach(geom.seg_a), detach(geom.seg_b)], axis=1)
    what = (
        "nothing followed"
        if point is None
        else f"point ({point[0]:.2f}, {point[1]:.2f}), dp/dθ = {velocity[0]:.2f}"
    )
    return plot_probes(
        segments,
        origin,
        ends,
        hits.prim,
        pair=(0, int(differs[-1])) if differs.size else None,
        bracket=(int(switch[0]), int(switch[0]) + 1) if switch.size else None,
        point=point,
        moving=[0],
        title=f"{int(probes)} probes around t = {offset:+.2f}: {what}",
    )


def explore(view: Callable[..., Figure], **sliders: tuple[float, float, float] | tuple[int, int, int]) -> Any:
    """``view`` behind one ipywidgets slider per keyword, ``name=(min, max, start)``: a widget box whose
    figure is redrawn by ``view(**values)`` whenever a slider moves (integer bounds: an integer slider).
    Returns the box; its ``update()`` redraws for the sliders' current values (what a change calls)."""
    import ipywidgets as widgets
    from IPython.display import display

    controls = {}
    for name, (low, high, start) in sliders.items():
        if all(isinstance(v, int) for v in (low, high, start)):
            controls[name] = widgets.IntSlider(value=start, min=low, max=high, description=name)
        else:
            step = (high - low) / 100.0
            controls[name] = widgets.FloatSlider(value=start, min=low, max=high, step=step, description=name)
    output = widgets.Output()

    def update(*_: Any) -> Figure:
        fig = view(**{name: c.value for name, c in controls.items()})
        output.clear_output(wait=True)
        with output:
            display(fig)
        return fig

    for control in controls.values():
        control.observe(update, names="value")
    box = widgets.VBox([*controls.values(), output])
    box.update = update
    update()
    return box
