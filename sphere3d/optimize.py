r"""Inverse rendering in sphere3d: recover parameter offsets from target images seen by one or more cameras.

:func:`optimize` checks its inputs and runs the shared optimiser :func:`flatland.core.optimize.descend`
(Adam on $L(θ) = Σ_v Σ_j (I_{vj}(θ) - I^*_{vj})^2$) with sphere3d's renderer injected: the scene at θ
is :func:`sphere3d.state.moved_scene` (the scene's ``offsets``, so the derivative of
:func:`~sphere3d.render.render_gradient` there is the derivative at θ for every kind of parameter),
and a view is a :class:`~sphere3d.scene.Camera` put in place of the scene's. :func:`render_targets`
renders the targets of a known θ; :func:`silhouette` and :func:`silhouette_iou` compare a shape's
silhouettes.

A parameter's default bounds keep the scene valid: an albedo offset keeps the albedo in [0, 1], an
emission offset keeps the emission >= 0, a scale offset keeps the factor $1 + θ >= 0.05$, a roughness
offset keeps a glossy shape's α in [0.01, 1] (:data:`MIN_ROUGHNESS`; 0 is a mirror, refused); the others
(translations, rotations, shape coefficients) are unbounded unless ``bounds`` says otherwise.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from flatland.core.microfacet import ALPHA_MAX
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
from sphere3d.render import GRADIENT_METHODS, render, render_gradient
from sphere3d.scene import Camera, Scene, load_scene
from sphere3d.state import build_state, moved_scene

__all__ = ["optimize", "render_targets", "silhouette", "silhouette_iou"]

MIN_SCALE = 0.05
"""The smallest scale factor $1 + θ$ a scale parameter's default bounds allow."""
MIN_ROUGHNESS = 0.01
"""The smallest GGX α a roughness parameter's default bounds allow (α > 0: a mirror is refused)."""


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
            try:
                cameras.append(Camera.from_dict(dict(view)))
            except ValidationError as e:
                raise ValidationError(f"views[{i}]", str(e)) from None
        else:
            raise ValidationError(f"views[{i}]", f"must be a Camera or a camera dict, got {view!r}")
    return tuple(cameras)


def _params(scene: Scene, params: Any) -> tuple[str, ...]:
    """The k parameter names, checked (one error naming ``params``)."""
    names = [params] if isinstance(params, str) else params
    try:
        return scene.check_params(list(names) if isinstance(names, tuple) else names)
    except ValidationError as e:
        raise ValidationError("params", str(e).partition(": ")[2] or str(e)) from None


def _bounds(scene: Scene, names: tuple[str, ...], bounds: Any) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of each offset: ``bounds[name] = (lo, hi)``, or the module docstring's
    (from the scene as given, its own offsets included)."""
    bounds = check_bounds(bounds, names)
    lower, upper = np.full(len(names), -np.inf), np.full(len(names), np.inf)
    offsets = dict(scene.offsets)
    for i, name in enumerate(names):
        owner, _, kind = name.partition(".")
        base = offsets.get(name, 0.0)
        if kind == "albedo":
            albedo = scene.shapes[scene.shape_index(owner)].albedo + base
            lower[i], upper[i] = -albedo, 1.0 - albedo
        elif kind == "emission":
            lower[i] = (
                -(scene.sky if owner == "sky" else scene.shapes[scene.shape_index(owner)].emission) - base
            )
        elif kind == "scale":
            lower[i] = MIN_SCALE - 1.0 - base  # the total factor 1 + base + θ >= MIN_SCALE
        elif kind == "roughness":
            alpha = scene.shapes[scene.shape_index(owner)].roughness + base
            lower[i], upper[i] = MIN_ROUGHNESS - alpha, ALPHA_MAX - alpha
    return narrow_bounds(bounds, names, lower, upper)


def optimize(
    scene: Scene | str | dict,
    params: str | Sequence[str],
    targets: Any,
    method: str = "reparam",
    steps: int = 100,
    lr: float | Sequence[float] = 0.02,
    spp: int = 16,
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
        The k parameters (:mod:`sphere3d.scene`), e.g. ``["occluder.translate.x", "occluder.albedo"]``.
    targets : array or list of arrays
        One target image per view, each of its camera's (height, width).
    method : str
        The gradient method of :func:`~sphere3d.render.render_gradient`.
    steps : int
        Adam steps, >= 1 (each: a render for the residual and a gradient render, per view).
    lr : float or list of float
        The first step size, in each parameter's units (one for all, or one per parameter); it
        shrinks geometrically to ``lr * decay`` at the last step (0 < decay <= 1).
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
        The history: θ, loss and gradient per step, wall times, images ``(V, height, width)`` at
        ``record``.

    Raises
    ------
    ValidationError
        One error naming the field and value: an unknown parameter or method, a target of the wrong
        size or count, an empty view list, steps < 1, a step size <= 0, bad bounds, ...
    """
    scene = load_scene(scene)
    names = _params(scene, params)
    spec = GRADIENT_METHODS.lookup(method)
    GRADIENT_METHODS.resolve_options(spec.name, options)  # an unknown or bad option: one error now
    cameras = _cameras(scene, views)
    images = check_targets(targets, [(c.height, c.width) for c in cameras])
    steps, decay, record = check_schedule(steps, decay, record)
    spp, seed = check_int("spp", spp), check_seed("seed", seed)
    step_sizes = check_step_sizes(lr, len(names))
    lower, upper = _bounds(scene, names, bounds)
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
        problem, images, np.zeros(len(names)), steps=steps, lr=step_sizes, seed=seed, lower=lower,
        upper=upper, decay=decay, record=record, progress=progress,
    )  # fmt: skip


def render_targets(
    scene: Scene | str | dict,
    params: str | Sequence[str],
    theta: Any,
    views: Sequence[Camera | Mapping[str, Any]] | None = None,
    spp: int = 256,
    seed: int = 1,
) -> np.ndarray:
    """The images of the scene moved by the offsets ``theta`` of ``params`` seen by each view, shape
    ``(V, height, width)``: targets of a known answer (give them a seed no run of :func:`optimize` uses)."""
    scene = load_scene(scene)
    moved = moved_scene(scene, _params(scene, params), theta)
    return np.stack(
        [
            render(replace(moved, camera=c), spp=spp, seed=seed, progress=False).value
            for c in _cameras(scene, views)
        ]
    )


def silhouette(scene: Scene | str | dict, shape: str, camera: Camera | None = None) -> np.ndarray:
    """The pixels a shape covers seen by ``camera`` (default the scene's), boolean ``(height, width)``:
    where the primary ray through the pixel's centre first hits the shape (occlusion by other shapes
    counts; the scene's offsets apply). A pixel's coverage is read at its centre only, so a silhouette
    is exact to within the pixels its outline crosses."""
    scene = load_scene(scene)
    camera = camera or scene.camera
    if shape not in [s.name for s in scene.shapes]:
        raise ValidationError(
            "shape", f"unknown shape {shape!r}; the scene has {[s.name for s in scene.shapes]}"
        )
    state = build_state(replace(scene, camera=camera))
    cam = state.camera
    y, x = np.mgrid[0 : cam.height, 0 : cam.width] + 0.5
    directions = cam.directions(x.ravel(), y.ravel())
    origins = np.broadcast_to(np.asarray(cam.origin, dtype=np.float64), directions.shape)
    hits = state.tracer.intersect(np.ascontiguousarray(origins), directions)
    return (hits.shape == scene.shape_index(shape)).reshape(cam.height, cam.width)


def silhouette_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two silhouettes (:func:`silhouette`, boolean arrays of one shape):
    $|A ∩ B| / |A ∪ B|$ in pixels, 1 for two empty silhouettes."""
    a, b = np.asarray(a, dtype=bool), np.asarray(b, dtype=bool)
    if a.shape != b.shape:
        raise ValidationError("b", f"must have the shape of a, {a.shape}, got {b.shape}")
    union = np.count_nonzero(a | b)
    return 1.0 if union == 0 else np.count_nonzero(a & b) / union
