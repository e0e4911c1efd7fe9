"""Rendering flatland scenes: images, gradient images and point estimates with every method.

Entry points:

- :func:`render` ``(scene, spp, seed, batches) -> Image``: the pixel integrals.
- :func:`render_gradient` ``(scene, param, method, spp, seed, batches, **options)
  -> GradientImage``: the image and its derivative with respect to one parameter; given a
  list of k parameters, ``-> GradientImages``: their k derivatives from one pass.
- :func:`irradiance` ``(scene, point, normal, param, method, n, seed, ...) ->
  Estimate``: the cosine-weighted incident radiance E(x) at a point, the shading
  integral on its own (the closed forms of theory/radiometry are stated for it).

``scene`` is anything :func:`flatland.scene.load_scene` accepts. The gradient
methods live in :data:`GRADIENT_METHODS` (one module each in
:mod:`flatland.methods`):

=====================  ====================================================================
``naive``              differentiate the estimator (misses every moving discontinuity)
``finite_difference``  central difference with common random numbers; option ``h``
``boundary``           naive interior term + exact discontinuity terms at every segment
                       endpoint and circle tangent point, seen from the camera and from
                       every shading point (the unbiased reference)
``reparam``            translations of the film coordinate and of the shading angle
                       chosen by probe rays, with convolution kernels; options
                       ``kappa``, ``kappa_film``, ``probes``, ``spread``, ``refine``,
                       ``paired``
=====================  ====================================================================

Standard errors come from ``batches`` independent batches of ``spp / batches``
samples per pixel (default: the largest divisor of ``spp`` up to 16,
:func:`flatland.core.image.resolve_batches`).

Every entry point takes ``max_depth``, the vertices per path (1, the default: direct
illumination; :func:`flatland.integrator.trace_paths`); ``reparam`` and ``boundary`` refuse more than 1.

Every entry point takes ``progress``: a tqdm bar on standard error, advanced per chunk of
samples, shown after a couple of seconds when stderr is a terminal (None, the default),
always (True) or never (False); it changes no number (:mod:`flatland.core.progress`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flatland import tasks
from flatland.core.budget import Request, check_request, rays_per_sample
from flatland.core.contract import Estimate
from flatland.core.image import GradientImage, GradientImages, Image, resolve_batches
from flatland.core.progress import run as _bar
from flatland.core.validate import ValidationError, check_int, check_seed
from flatland.methods import GRADIENT_METHODS
from flatland.scene import Scene, check_direction, check_point, load_scene
from flatland.state import parse_parameter, parse_parameters
from flatland.tasks import ImageTask, PointTask, Tally

__all__ = ["GRADIENT_METHODS", "irradiance", "render", "render_gradient"]


def _task(
    scene: Any, param: Any, spp: Any, seed: Any, batches: Any, max_depth: Any, **point: Any
) -> ImageTask | PointTask:
    """An :class:`~flatland.tasks.ImageTask`, or given ``point`` and ``normal`` a
    :class:`~flatland.tasks.PointTask`."""
    scene = load_scene(scene)
    spp = check_int("spp", spp)
    seed = check_seed("seed", seed)
    depth = check_int("max_depth", max_depth)
    p: Any = None
    if isinstance(param, list | tuple):
        p = parse_parameters(scene, param)
    elif param is not None:
        p = parse_parameter(scene, param)
    if point:
        batches = resolve_batches(spp, batches)
        return PointTask(scene, p, point["point"], point["normal"], spp, seed, batches, depth)
    return ImageTask(scene, p, spp, seed, resolve_batches(spp, batches), depth)


def _check_budget(task: ImageTask | PointTask, options: dict[str, Any]) -> None:
    """Refuse a request too large for memory or time (:mod:`flatland.core.budget`) before it starts."""
    image = isinstance(task, ImageTask)
    check_request(
        Request(
            pixels=task.pixels,
            spp=task.spp if image else task.n,
            batches=task.batches,
            rays=rays_per_sample(options) * task.max_depth,  # 3 rays per vertex bound 1 + 2 d
            chunk=tasks.CHUNK,
            pixels_field="camera.pixels",
            spp_field="spp" if image else "n",
        )
    )


def _gradient(
    task: ImageTask | PointTask, method: Any, options: dict[str, Any]
) -> tuple[Tally, dict[str, Any]]:
    spec = GRADIENT_METHODS.lookup(method)
    resolved = GRADIENT_METHODS.resolve_options(spec.name, options)
    _check_budget(task, resolved)
    tally = spec.func(task, **resolved)
    if task.k is not None and np.shape(tally.derivative) != (task.k, task.batches, task.pixels):
        names = [p.name for p in task.param]
        raise ValidationError(
            "param",
            f"method {spec.name!r} gives one derivative, not one per parameter of {names!r} "
            "(it does not evaluate at task.dual_offset()): pass one name per call",
        )
    return tally, resolved


def render(
    scene: Scene | str | dict,
    spp: int = 64,
    seed: int = 0,
    batches: int | None = None,
    progress: bool | None = None,
    max_depth: int = 1,
) -> Image:
    r"""Render the scene's pixels: $I_j = ∫ k_j(t) L(t) dt$ with ``spp`` samples per pixel.

    ``progress``: a progress bar per chunk (None: when stderr is a terminal; see the module docstring).
    ``max_depth``: vertices per path (diffuse or glossy), an integer >= 1; 1 is direct illumination, d gives
    $L = Σ_{i=0}^{d} \mathcal{T}^i L_e$ (:func:`flatland.integrator.trace_paths`).

    Raises
    ------
    ValidationError
        Naming the field and value (bad scene field, spp < 1, batches not dividing spp, ...).
    """
    task = _task(scene, None, spp, seed, batches, max_depth)
    _check_budget(task, {})
    with _bar(f"render {task.scene.name}", progress):
        result = task.evaluate(0.0)
    return Image.from_batches(result.value, spp=task.spp, seed=task.seed, scene=task.scene.name)


def render_gradient(
    scene: Scene | str | dict,
    param: str | list[str] | tuple[str, ...],
    method: str = "reparam",
    spp: int = 64,
    seed: int = 0,
    batches: int | None = None,
    progress: bool | None = None,
    max_depth: int = 1,
    **options: Any,
) -> GradientImage | GradientImages:
    """Render the image and its derivative with respect to ``param`` (at offset θ = 0) by ``method``.

    Parameters
    ----------
    scene : Scene, str or dict
        A scene, built-in name, ``.json`` path or dict.
    param : str, or list or tuple of str
        Parameter name, e.g. ``"occluder.translate.x"`` (see :mod:`flatland.scene`), or k >= 1
        distinct names: then the k derivatives come from one pass (every ray, probe and
        sample shared; forward mode carries k tangents, :mod:`flatland.core.dual`), except
        ``finite_difference``, which renders 2k + 1 times.
    method : {"naive", "finite_difference", "boundary", "reparam"}
        The gradient method.
    spp : int
        Primary samples per pixel, >= 1.
    seed : int
        Seed; every method draws the same primary samples from it, so the ``reparam``
        image value equals the ``naive`` one bit for bit.
    batches : int, optional
        Independent batches behind the standard errors (must divide spp).
    progress : bool, optional
        A progress bar per chunk on stderr: None (default) when stderr is a terminal, True
        always, False never (:mod:`flatland.core.progress`); it changes no number.
    max_depth : int
        Vertices per path, >= 1 (1: direct illumination), as in :func:`render`. Every method takes
        any depth: ``reparam`` changes variables at every vertex and ``boundary`` adds every vertex's
        jump terms, their sides' radiance estimated along paths (:func:`flatland.methods.reparam.reparam`,
        :func:`flatland.methods.boundary.boundary`); ``reparam``'s paired kernel samples only at 1.
    **options
        Method options: ``h`` (finite_difference); ``kappa``, ``kappa_film``,
        ``probes``, ``spread``, ``refine``, ``paired`` (reparam, see
        :func:`flatland.methods.reparam.reparam`).

    Returns
    -------
    GradientImage or GradientImages
        For one name, its :class:`~flatland.core.image.GradientImage`, the same numbers whether
        or not other calls pass lists. For a list, a
        :class:`~flatland.core.image.GradientImages`: ``images[name]`` is that parameter's
        GradientImage. With the same seed, parameter i's derivative equals the single call's
        bit for bit when the other parameters leave the geometry's values unchanged at θ0
        (translations, vertices, emission, albedo; ``finite_difference``: always); a
        rotation or a scale in the list changes them by rounding (``c + (p - c)`` is not
        always p), and the other parameters then agree with their single calls to rounding
        (tests/flatland/test_multi_param.py).

    Raises
    ------
    ValidationError
        One error naming the field and value: unknown method, option or parameter,
        an empty list or a repeated name, spp < 1, kappa <= 0, a box filter with ``reparam``, ...
    """
    if param is None:
        raise ValidationError("param", "is required (a parameter name like 'occluder.translate.x')")
    task = _task(scene, param, spp, seed, batches, max_depth)
    with _bar(f"{method} {task.scene.name}", progress):
        result, resolved = _gradient(task, method, options)
    run = dict(method=method, spp=task.spp, seed=task.seed, options=resolved, scene=task.scene.name)
    if task.k is not None:
        names = tuple(p.name for p in task.param)
        return GradientImages.from_batches(result.value, result.derivative, params=names, **run)
    return GradientImage.from_batches(result.value, result.derivative, param=task.param.name, **run)


def irradiance(
    scene: Scene | str | dict,
    point: Any,
    normal: Any,
    param: str | list[str] | tuple[str, ...] | None = None,
    method: str = "naive",
    n: int = 4096,
    seed: int = 0,
    batches: int | None = None,
    progress: bool | None = None,
    max_depth: int = 1,
    **options: Any,
) -> Estimate | dict[str, Estimate]:
    r"""Estimate $E(x) = ∫ L_i(x, φ) \max(0, \cos(φ - φ_n))\, dφ$ at a fixed point and its derivative.

    The shading integral of the renderer on its own (same samplers, same methods),
    at a point that does not move with θ. Closed forms (theory/radiometry): a uniform emitter
    of radiance L between angles $φ_a < φ_b$ from the normal gives $L (\sin φ_b - \sin φ_a)$;
    the unoccluded sky of radiance 1 gives 2. With ``param=None`` only the value is
    estimated (derivative 0). Given a list of k parameters, a dict from each name to its
    Estimate (all with the same value), the k derivatives from one pass as in
    :func:`render_gradient`. ``progress``: a progress bar per chunk, as in :func:`render`.
    ``max_depth`` d: $L_i$ carries paths of up to d - 1 further vertices (1: emission only).
    """
    point, normal = check_point("point", point), check_direction("normal", normal)
    task = _task(scene, param, n, seed, batches, max_depth, point=point, normal=normal)
    with _bar(f"irradiance {method if param is not None else ''}".rstrip(), progress):
        if param is None:
            _check_budget(task, {})
            result, resolved = task.evaluate(0.0), {}
        else:
            result, resolved = _gradient(task, method, options)
    if task.k is not None:
        return {
            p.name: Estimate.from_batches(result.value[:, 0], d[:, 0], task.n, method, resolved)
            for p, d in zip(task.param, result.derivative, strict=True)
        }
    return Estimate.from_batches(
        result.value[:, 0], result.derivative[:, 0], task.n, method if param is not None else "", resolved
    )
