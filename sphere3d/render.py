"""Images and gradient images on the sphere: :func:`render`, :func:`render_gradient`, :func:`irradiance`.

The same entry points as flatland's renderer. Every pixel is the integral of its
filter times the radiance through the film (:mod:`sphere3d.integrator`); standard
errors come from ``batches`` independent batches of ``spp / batches`` samples. The
gradient methods are in :data:`GRADIENT_METHODS` (``naive``, ``finite_difference``,
``reparam``, ``boundary``); given the same seed they all see the same primary samples.
Every entry point takes ``progress``: a tqdm bar on standard error, advanced per chunk of
samples, shown after a couple of seconds when stderr is a terminal (None, the default),
always (True) or never (False); it changes no number (:mod:`flatland.core.progress`).

:func:`render`, :func:`render_gradient` and :func:`irradiance` also take ``scheduler``, the address of
a ``dask.distributed`` scheduler (as a study's ``scheduler``; the optional ``cluster`` extra): the
memory chunks of the image (or of the point's samples) then run as tiles on that cluster's workers,
each building its own scene state and tracer from the pickled scene, and the image (or estimate) is
assembled here, bit for bit that of a local run (:func:`sphere3d.execution.cluster`,
:meth:`sphere3d.tasks.ImageTask._on_cluster`, :meth:`sphere3d.tasks.PointTask._on_cluster`); the
progress bar then advances per finished tile.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from flatland.core.budget import IMAGE_BYTES_PER_PIXEL, Request, check_request, rays_per_sample
from flatland.core.contract import Estimate
from flatland.core.image import GradientImage, GradientImages, Image, resolve_batches
from flatland.core.progress import run as _bar
from flatland.core.validate import ValidationError, check_int, check_seed
from sphere3d import execution, tasks
from sphere3d.methods import GRADIENT_METHODS
from sphere3d.methods._common import MEMORY_MODELS
from sphere3d.scene import check_vector, load_scene
from sphere3d.state import scene_term
from sphere3d.tasks import ImageTask, PointTask
from sphere3d.world import COORD_MAX

__all__ = ["GRADIENT_METHODS", "irradiance", "render", "render_gradient"]


def render(
    scene: Any,
    spp: int = 64,
    seed: int = 0,
    batches: int | None = None,
    film: str = "splat",
    progress: bool | None = None,
    scheduler: str | None = None,
    max_depth: int = 1,
) -> Image:
    r"""Render ``scene`` (a built-in name, a .json path, a dict or a Scene).

    Parameters
    ----------
    spp : int
        Samples per pixel, >= 1.
    seed : int
        Same seed, same image; the primary samples are those of every gradient method.
    batches : int, optional
        Independent batches behind the standard errors (must divide ``spp``);
        default: the largest divisor of ``spp`` up to 16 (:func:`~flatland.core.image.resolve_batches`).
    film : {"splat", "pixel"}
        ``"splat"`` (default): each sample counts in every pixel its filter covers, with
        multi-sample MIS weights over the pixels' samplers (:mod:`sphere3d.film`); ``"pixel"``:
        only in the pixel that drew it.
    progress : bool, optional
        A progress bar per chunk on stderr: None (default) when stderr is a terminal, True
        always, False never (:mod:`flatland.core.progress`); it changes no number.
    scheduler : str, optional
        Address of a ``dask.distributed`` scheduler, e.g. ``"tcp://10.0.0.5:8786"`` (needs the
        ``cluster`` extra): the chunks run as tiles on its workers and the image is bit for bit
        that of a local run (module docstring); None (default): on this machine's threads.
    max_depth : int
        Vertices per path, an integer >= 1: 1 (default) is direct illumination, bit for bit; d
        gives $L = Σ_{i=0}^{d} \mathcal{T}^i L_e$, each vertex's MIS estimate of the light it reflects and
        the path continued along its cosine sample, or at a glossy shape its BSDF sample
        (:mod:`sphere3d.paths`, :mod:`sphere3d.glossy`).

    Returns
    -------
    Image
        ``value`` and ``stderr`` of shape (height, width).

    Raises
    ------
    ValidationError
        One error naming the field and value: unknown scene field, spp < 1, batches not dividing
        spp, film not one of "pixel", "splat", max_depth not an integer >= 1, a scheduler address that
        is malformed or where no scheduler answers (or dask.distributed missing).
    """
    scene = load_scene(scene)
    spp = check_int("spp", spp)
    seed = check_seed("seed", seed)
    batches = resolve_batches(spp, batches)
    task = ImageTask(scene, None, spp, seed, batches, film=film, max_depth=check_int("max_depth", max_depth))
    _check_budget(task, {})
    with execution.cluster(scheduler), _bar(f"render {scene.name}", progress):
        tally = task.evaluate(0.0)
    return Image.from_batches(tally.value, spp=spp, seed=seed, scene=scene.name)


def _request(task: ImageTask | PointTask, options: dict[str, Any], method: str | None = None) -> Request:
    """What the call will hold and trace (:class:`~flatland.core.budget.Request`): the image
    (:meth:`~sphere3d.tasks.ImageTask.pixel_bytes`) and its film's working set
    (:meth:`~sphere3d.tasks.ImageTask.film_terms`), the rays, and what the method's options add (its
    memory model, :data:`~sphere3d.methods._common.MEMORY_MODELS`), and the scene's per-triangle tables
    (:func:`~sphere3d.state.scene_term`)."""
    model = MEMORY_MODELS.get(method or "")
    terms = (*(model(task, options) if model else ()), scene_term(task.scene))  # and the scene's tables
    rays = 3 if model else rays_per_sample(options)  # a model counts its options' rays itself
    rays *= task.max_depth  # each vertex of a path traces them again (sphere3d.paths.PATH_RAYS: 3 a vertex)
    if isinstance(task, ImageTask):
        pixels, spp, field = task.scene.camera.width * task.scene.camera.height, task.spp, "spp"
        chunk, pixel_bytes = task.chunk_pixels * task.spp, task.pixel_bytes()
        terms = (*terms, *task.film_terms())  # the splat film's tile of stencils
    else:
        pixels, spp, field, chunk, pixel_bytes = 1, task.n, "n", tasks.CHUNK, IMAGE_BYTES_PER_PIXEL
    large = field if chunk > tasks.CHUNK else ""  # a chunk holds a whole pixel: all its samples at once
    return Request(
        pixels, spp, task.batches, rays, chunk, "camera.width", field, "probes", pixel_bytes, terms, large
    )


def _check_budget(task: ImageTask | PointTask, options: dict[str, Any], method: str | None = None) -> None:
    """Refuse a request too large for memory or time (:mod:`flatland.core.budget`) before it starts."""
    check_request(_request(task, options, method))


def _param(scene: Any, param: Any) -> str | tuple[str, ...]:
    """One checked parameter name, or for a list or tuple the checked tuple of k distinct names."""
    return scene.check_params(param) if isinstance(param, list | tuple) else scene.check_param(param)


def _run(spec: Any, task: ImageTask | PointTask, resolved: dict[str, Any]) -> Any:
    """``spec.func(task, **resolved)``, refusing a method that gives one derivative for k parameters."""
    tally = spec.func(task, **resolved)
    if task.k is not None and np.shape(tally.derivative)[:1] != (task.k,):
        raise ValidationError(
            "param",
            f"method {spec.name!r} gives one derivative, not one per parameter of {list(task.param)!r} "
            "(it does not evaluate at task.dual_offset()): pass one name per call",
        )
    return tally


def _resolve(method: str, task: ImageTask | PointTask, options: dict[str, Any]) -> tuple[Any, dict[str, Any]]:
    """The method's table entry and its checked options, once the request fits (:func:`_check_budget`)."""
    spec = GRADIENT_METHODS.lookup(method)
    resolved = GRADIENT_METHODS.resolve_options(spec.name, options)
    _check_budget(task, resolved, spec.name)
    return spec, resolved


def render_gradient(
    scene: Any,
    param: str | list[str] | tuple[str, ...],
    method: str = "reparam",
    spp: int = 64,
    seed: int = 0,
    batches: int | None = None,
    film: str = "splat",
    progress: bool | None = None,
    scheduler: str | None = None,
    max_depth: int = 1,
    **options: Any,
) -> GradientImage | GradientImages:
    """Render ``scene`` and its derivative with respect to ``param`` by ``method``.

    Parameters
    ----------
    param : str, or list or tuple of str
        A parameter of the scene (``Scene.parameters``), e.g. ``"occluder.translate.x"``, or k >= 1
        distinct names: their k derivatives from one pass (every traced ray, probe and sample
        shared; forward mode carries k tangents, :mod:`flatland.core.dual`), except
        ``finite_difference``, which renders 2k + 1 times.
    method : {"naive", "finite_difference", "boundary", "reparam"}
    spp, seed, batches, film, progress, scheduler
        As in :func:`render`; the film (default ``"splat"``) applies to every method alike (their
        values stay equal). With ``scheduler`` every render a method makes (finite differences:
        three) runs on the cluster, its per-image term (boundary's edges on the film) as one more task.
    max_depth : int
        Vertices per path, >= 1, as in :func:`render`. ``naive``, ``finite_difference`` and ``reparam``
        take any depth (``reparam``'s paired kernel samples and its paper variant only 1; on paths it
        changes variables at every vertex, :mod:`sphere3d.path_changes`); ``boundary`` adds the edge
        terms of every vertex, their sides' radiance estimated along paths
        (:mod:`sphere3d.boundary.indirect`).
    **options
        ``h`` (finite_difference, default 1e-2); ``kappa``, ``probes``, ``spread``,
        ``refine`` (bisection rays toward a silhouette, default 3), ``paired`` (reparam,
        see :func:`sphere3d.methods.reparam.reparam`); ``rate``
        (boundary: edge points per pixel of projected edge length and sample),
        ``secondary`` (boundary: edge samples per shading point) and ``indirect`` (boundary on
        paths: edge samples per vertex of the reflected radiance's jump).

    Returns
    -------
    GradientImage or GradientImages
        For one name: value and derivative with standard errors, arrays of shape (height, width), the
        same numbers whether or not other calls pass lists. For a list, a
        :class:`~flatland.core.image.GradientImages`: ``images[name]`` is that parameter's GradientImage
        (``derivative`` of shape (k, height, width)); with the same seed each equals the single call's
        where the parameters move the same things (tests/sphere3d/test_multi_param.py says where and how
        exactly).

    Raises
    ------
    ValidationError
        One error naming the field and value: unknown scene field, method, option or
        parameter, an empty list or a repeated name, spp < 1, κ outside (0, 1e15], h <= 0 (or h >= 1 on
        a scale), batches not dividing spp, film not one of "pixel", "splat", a bad ``scheduler`` (as in
        :func:`render`).
    """
    scene = load_scene(scene)
    param = _param(scene, param)
    GRADIENT_METHODS.lookup(method)
    spp = check_int("spp", spp)
    seed = check_seed("seed", seed)
    batches = resolve_batches(spp, batches)
    task = ImageTask(scene, param, spp, seed, batches, film=film, max_depth=check_int("max_depth", max_depth))
    spec, resolved = _resolve(method, task, options)  # every argument checked before a cluster is reached
    with execution.cluster(scheduler), _bar(f"{method} {scene.name}", progress):
        tally = _run(spec, task, resolved)
    run = dict(method=method, spp=spp, seed=seed, options=resolved, scene=scene.name)
    if task.k is not None:
        return GradientImages.from_batches(tally.value, tally.derivative, params=param, **run)
    return GradientImage.from_batches(tally.value, tally.derivative, param=param, **run)


def irradiance(
    scene: Any,
    point: Any,
    normal: Any,
    param: str | list[str] | tuple[str, ...] | None = None,
    method: str = "naive",
    n: int = 4096,
    seed: int = 0,
    batches: int | None = None,
    progress: bool | None = None,
    scheduler: str | None = None,
    max_depth: int = 1,
    **options: Any,
) -> Estimate | dict[str, Estimate]:
    r"""Irradiance $E = ∫ L_i(ω) \cos θ\, dω$ at a fixed point and normal, and its derivative.

    The integral the renderer evaluates at every diffuse hit (there multiplied by
    $\mathrm{albedo} / π$), by the same emitter/cosine MIS estimator and the same methods; the
    point and normal do not move with θ. Used for closed-form checks (a black
    triangle under a constant sky: $E = L (π - \mathrm{Lambert's\ polygon\ formula})$).

    Parameters
    ----------
    point, normal : sequence of 3 floats
        The point (within ±:data:`~sphere3d.world.COORD_MAX`) and its normal (not zero; normalized here).
    param : str, or list or tuple of str, optional
        A parameter of the scene to differentiate by; None (default): the value only (derivative 0).
        A list of k distinct names: their derivatives from one pass, as in :func:`render_gradient`.
    method : {"naive", "finite_difference", "boundary", "reparam"}
        The gradient method (with ``param``), and ``**options`` its options, as in :func:`render_gradient`.
    n : int
        Samples, >= 1.
    seed, batches, progress
        As in :func:`render`, ``batches`` dividing ``n``; the bar advances per chunk (per tile on a cluster).
    scheduler : str, optional
        Address of a ``dask.distributed`` scheduler, e.g. ``"tcp://10.0.0.5:8786"`` (needs the
        ``cluster`` extra): the chunks run as tiles on its workers and the estimate is bit for bit
        that of a local run (module docstring); None (default): on this machine's threads.
    max_depth : int
        As in :func:`render`: $L_i$ carries paths of up to d - 1 further diffuse vertices (1: emission
        and sky only, the default).

    Returns
    -------
    Estimate or dict of str to Estimate
        Value and derivative with standard errors over ``batches`` batches of ``n / batches``.
        With ``param=None`` only the value is estimated (derivative 0). For a list of names, a dict
        from each name to its Estimate (all with the same value), as flatland's.

    Raises
    ------
    ValidationError
        One error naming the field and value: unknown scene field, parameter, method or option, a
        point out of range, a zero normal, n < 1, batches not dividing n, a bad ``scheduler`` (as in
        :func:`render`).
    """
    scene = load_scene(scene)
    param = _param(scene, param) if param is not None else None
    point = check_vector("point", point)
    if max(map(abs, point)) > COORD_MAX:
        raise ValidationError(
            "point", f"must lie within ±{COORD_MAX:g} (rays are traced in float32), got {list(point)}"
        )
    normal = check_vector("normal", normal)
    length = math.hypot(*normal)
    if length == 0.0:
        raise ValidationError("normal", f"must not be zero, got {list(normal)}")
    normal = tuple(x / length for x in normal)
    n = check_int("n", n)
    seed = check_seed("seed", seed)
    batches = resolve_batches(n, batches, "n")
    task = PointTask(
        scene, param, point, normal, n, seed, batches, max_depth=check_int("max_depth", max_depth)
    )
    if param is None:
        _check_budget(task, {})
        spec, resolved = None, {}
    else:
        spec, resolved = _resolve(method, task, options)  # every argument checked before a cluster is reached
    with execution.cluster(scheduler), _bar(f"irradiance {method if spec else ''}".rstrip(), progress):
        tally = task.evaluate(0.0) if spec is None else _run(spec, task, resolved)
    if task.k is not None:
        return {
            name: Estimate.from_batches(tally.value, d, n, method, resolved)
            for name, d in zip(param, tally.derivative, strict=True)
        }
    return Estimate.from_batches(tally.value, tally.derivative, n, method if spec else "", resolved)
