r"""Inverse rendering in flatland: recover parameter offsets from target images seen by one or more cameras.

:func:`optimize` checks its inputs and runs the shared optimiser :func:`flatland.core.optimize.descend`
(Adam on $L(θ) = Σ_v Σ_j (I_{vj}(θ) - I^*_{vj})^2$) with flatland's renderer injected: the scene at θ
is :func:`flatland.state.moved_scene` (the scene's ``offsets``, so the derivative of
:func:`~flatland.render.render_gradient` there is the derivative at θ for every kind of parameter),
and a view is a :class:`~flatland.scene.Camera` put in place of the scene's. :func:`render_targets`
renders the targets of a known θ, :func:`silhouette_iou` compares a shape's silhouettes.

A parameter's default bounds keep the scene valid: an albedo offset keeps the albedo in [0, 1], an
emission offset keeps the emission >= 0, a scale offset keeps the factor $1 + θ >= 0.05$, a roughness
offset keeps α in [0.01, 1]; the others
are unbounded unless ``bounds`` says otherwise.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from flatland.core.optimize import (
    OptimizeResult,
    Views,
    check_bounds,
    check_schedule,
    check_step_sizes,
    check_targets,
    descend,
    narrow_bounds,
)
from flatland.core.validate import ValidationError, check_int, check_seed
from flatland.methods import GRADIENT_METHODS
from flatland.render import render, render_gradient
from flatland.scene import Camera, Scene, load_scene
from flatland.state import moved_scene, parse_parameters

__all__ = ["film_interval", "optimize", "render_targets", "silhouette_iou"]

MIN_SCALE = 0.05
"""The smallest scale factor $1 + θ$ a scale parameter's default bounds allow."""
MIN_ROUGHNESS = 0.01
"""Smallest roughness α the default bounds allow (α = 0 is a perfect mirror, refused by the scene)."""


def _cameras(scene: Scene, views: Any) -> tuple[Camera, ...]:
    """The views as cameras: None -> the scene's; else a non-empty list of Cameras or camera dicts."""
    if views is None:
        return (scene.camera,)
    if isinstance(views, Camera | Mapping | str) or not isinstance(views, Sequence) or not views:
        raise ValidationError("views", f"must be a non-empty list of cameras, got {views!r}")
    cameras = []
    for i, view in enumerate(views):
        if isinstance(view, Camera):
            cameras.append(view)
        elif isinstance(view, Mapping):
            d = scene.to_dict()
            d["camera"] = dict(view)
            try:
                cameras.append(load_scene(d).camera)
            except ValidationError as e:
                raise ValidationError(f"views[{i}]", str(e)) from None
        else:
            raise ValidationError(f"views[{i}]", f"must be a Camera or a camera dict, got {view!r}")
    return tuple(cameras)


def _bounds(scene: Scene, params: tuple[Any, ...], bounds: Any) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of each offset: ``bounds[name] = (lo, hi)``, or the module docstring's."""
    names = [p.name for p in params]
    bounds = check_bounds(bounds, names)
    lower, upper = np.full(len(params), -np.inf), np.full(len(params), np.inf)
    for i, p in enumerate(params):
        shape = scene.shape(p.target) if p.target != "camera" else None
        if p.kind == "albedo":
            lower[i], upper[i] = -shape.albedo, 1.0 - shape.albedo
        elif p.kind == "emission":
            lower[i] = -shape.emission
        elif p.kind == "roughness":  # α stays in [MIN_ROUGHNESS, 1]: 0 would be a mirror
            lower[i], upper[i] = MIN_ROUGHNESS - shape.roughness, 1.0 - shape.roughness
        elif p.kind == "scale":
            lower[i] = MIN_SCALE - 1.0
    return narrow_bounds(bounds, names, lower, upper)


def optimize(
    scene: Scene | str | dict,
    params: str | Sequence[str],
    targets: Any,
    method: str = "reparam",
    steps: int = 100,
    lr: float | Sequence[float] = 0.02,
    spp: int = 64,
    seed: int = 0,
    views: Sequence[Camera | Mapping[str, Any]] | None = None,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    decay: float = 0.1,
    record: Sequence[int] | None = None,
    progress: bool | None = None,
    **options: Any,
) -> OptimizeResult:
    r"""Recover the offsets θ of ``params`` that make the scene's images match ``targets``, by Adam.

    Parameters
    ----------
    scene : Scene, str or dict
        The scene at the start (θ = 0): a scene, built-in name, ``.json`` path or dict.
    params : str or list of str
        The k parameters (:mod:`flatland.scene`), e.g. ``["occluder.translate.x", "occluder.albedo"]``.
    targets : array or list of arrays
        One target image per view, each of its camera's pixels.
    method : str
        The gradient method of :func:`~flatland.render.render_gradient`.
    steps : int
        Adam steps, >= 1 (each: a render for the residual and a gradient render, per view).
    lr : float or list of float
        The first step size, in each parameter's units (one for all, or one per parameter);
        it shrinks geometrically to ``lr * decay`` at the last step (0 < decay <= 1).
    spp, seed : int
        Samples per pixel of every render; the seed the run's seeds are derived from (a different
        one per render, the same run for the same seed).
    views : list of Camera or camera dicts, optional
        The cameras (default: the scene's); a dict as the scene's ``camera``.
    bounds : mapping, optional
        ``{name: (low, high)}`` on the offset (``low <= 0 <= high``), within the defaults.
    record : list of int, optional
        Steps (0 to ``steps``) whose images the result keeps (default: the first and the last).
    progress : bool, optional
        A bar over the steps showing the loss (None: when stderr is a terminal).
    **options
        Options of the method (e.g. ``kappa``, ``h``).

    Returns
    -------
    OptimizeResult
        The history: θ, loss and gradient per step, wall times, images at ``record``.

    Raises
    ------
    ValidationError
        One error naming the field and value: an unknown parameter or method, a target of the
        wrong size or count, an empty view list, steps < 1, a step size <= 0, bad bounds, ...
    """
    scene = load_scene(scene)
    names = [params] if isinstance(params, str) else params
    parsed = parse_parameters(scene, list(names) if isinstance(names, tuple) else names, field="params")
    spec = GRADIENT_METHODS.lookup(method)
    GRADIENT_METHODS.resolve_options(spec.name, options)  # an unknown or bad option: one error now
    cameras = _cameras(scene, views)
    images = check_targets(targets, [(c.pixels,) for c in cameras])
    steps, decay, record = check_schedule(steps, decay, record)
    spp, seed = check_int("spp", spp), check_seed("seed", seed)
    k = len(parsed)
    step_sizes = check_step_sizes(lr, k)
    lower, upper = _bounds(scene, parsed, bounds)
    names = tuple(p.name for p in parsed)
    problem = Views(
        scene_at=lambda theta: moved_scene(scene, names, theta),
        with_view=lambda s, camera: replace(s, camera=camera),
        render=render,
        render_gradient=render_gradient,
        views=cameras,
        params=names,
        method=spec.name,
        spp=spp,
        options=dict(options),
    )
    return descend(
        problem, images, np.zeros(k), steps=steps, lr=step_sizes, seed=seed, lower=lower, upper=upper,
        decay=decay, record=record, progress=progress,
    )  # fmt: skip


def render_targets(
    scene: Scene | str | dict,
    params: str | Sequence[str],
    theta: Any,
    views: Sequence[Camera | Mapping[str, Any]] | None = None,
    spp: int = 1024,
    seed: int = 1,
) -> np.ndarray:
    """The images of the scene moved by the offsets ``theta`` of ``params`` seen by each view, shape
    ``(V, pixels)``: targets of a known answer (give them a seed no run of :func:`optimize` uses)."""
    scene = load_scene(scene)
    names = [params] if isinstance(params, str) else list(params)
    moved = moved_scene(scene, names, theta)
    return np.stack(
        [render(replace(moved, camera=c), spp=spp, seed=seed).value for c in _cameras(scene, views)]
    )


def film_interval(scene: Scene | str | dict, shape: str, camera: Camera | None = None) -> tuple[float, float]:
    r"""The film interval $[t_a, t_b]$ a shape covers seen by ``camera`` (default the scene's), clipped to
    the film $[-\tan(\mathrm{fov}/2), \tan(\mathrm{fov}/2)]$: its points' (a circle's tangent points')
    smallest and largest film coordinates. A shape is connected, so it covers the whole interval;
    occlusion by other shapes is ignored. The shape must lie in front of the camera."""
    from flatland.state import build_state

    scene = load_scene(scene)
    camera = camera or scene.camera
    seen = replace(scene, camera=camera)
    state = build_state(seen)
    target = scene.shape(shape)
    k = next(i for i, s in enumerate(scene.shapes) if s.name == shape)
    o, f, r = np.asarray(state.cam_o), np.asarray(state.cam_f), np.asarray(state.cam_r)
    if target.type == "circle":
        c = np.asarray(state.circ_c)[state.prim_shape[state.n_seg :] == k][0] - o
        radius = float(np.asarray(state.circ_r)[state.prim_shape[state.n_seg :] == k][0])
        beta = math.asin(min(radius / float(np.hypot(*c)), 1.0))
        turn = np.array([[math.cos(beta), -math.sin(beta)], [math.sin(beta), math.cos(beta)]])
        v = np.stack([turn @ c, turn.T @ c])
    else:
        segs = np.flatnonzero(state.prim_shape[: state.n_seg] == k)
        v = np.concatenate([np.asarray(state.seg_a)[segs], np.asarray(state.seg_b)[segs]]) - o
    depth = v @ f
    if np.any(depth <= 0.0):
        raise ValidationError("shape", f"{shape!r} is not entirely in front of the camera")
    t = (v @ r) / depth
    h = camera.half_width
    return float(np.clip(t.min(), -h, h)), float(np.clip(t.max(), -h, h))


def silhouette_iou(a: tuple[float, float], b: tuple[float, float]) -> float:
    """Intersection over union of two film intervals (:func:`film_interval`): $|A ∩ B| / |A ∪ B|$, 1 for
    two empty intervals."""
    inter = max(0.0, min(a[1], b[1]) - max(a[0], b[0]))
    union = (a[1] - a[0]) + (b[1] - b[0]) - inter
    return 1.0 if union <= 0.0 else inter / union
