r"""Inverse rendering by Adam on an L2 image loss over one or more views, for any renderer.

The loss of the parameter offsets θ (k of them) against target images $I^*_v$, one per view v, is

    $L(θ) = Σ_v Σ_j (I_{vj}(θ) - I^*_{vj})^2$,    $∂L/∂θ_i = 2 Σ_v Σ_j (I_{vj} - I^*_{vj})\, ∂I_{vj}/∂θ_i$,

the derivative images $∂I_{vj}/∂θ_i$ coming from one gradient render per view (k parameters per
pass). Each step estimates the residual $I_{vj} - I^*_{vj}$ from a render of its own seed,
independent of the derivative's samples: the expectation of the product of two independent
unbiased estimates is the product of their means, so the gradient estimate is unbiased whenever the
derivative images are. (Taking the residual from the derivative's own render would add
$2 Σ_{vj} \mathrm{Cov}(\hat I_{vj}, \hat D_{vj})$, of order 1/spp, which shifts the point the descent
settles at.) The reported loss is $Σ (\hat I - I^*)^2$ of that render: above L(θ) by the images'
variance (its noise floor). The steps are :mod:`flatland.core.adam`'s.

The renderer is injected (:class:`Views`): a function from θ to the scene moved by θ, one from a
scene and a view to the scene seen by that view, and the package's ``render`` and
``render_gradient`` (taking a list of parameters). Nothing here knows the scene's dimension.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flatland.core import progress as _progress
from flatland.core.adam import AdamState, adam_step
from flatland.core.rng import stream
from flatland.core.validate import ValidationError, check_finite, check_int, check_positive

__all__ = [
    "OptimizeResult",
    "Views",
    "check_bounds",
    "check_schedule",
    "check_step_sizes",
    "check_targets",
    "descend",
    "l2_gradient",
    "l2_loss",
    "narrow_bounds",
    "step_seeds",
]


def l2_loss(values: np.ndarray, targets: np.ndarray) -> float:
    r"""$L = Σ_v Σ_j (I_{vj} - I^*_{vj})^2$ over every view and pixel (arrays of the same shape)."""
    r = np.asarray(values, dtype=np.float64) - np.asarray(targets, dtype=np.float64)
    return float(np.sum(r * r))


def l2_gradient(residuals: np.ndarray, derivatives: np.ndarray) -> np.ndarray:
    r"""$∂L/∂θ_i = 2 Σ_v Σ_j r_{vj} D_{ivj}$: residuals ``(V, *film)``, derivatives ``(k, V, *film)``."""
    r = np.asarray(residuals, dtype=np.float64)
    d = np.asarray(derivatives, dtype=np.float64)
    return 2.0 * np.tensordot(d, r, axes=r.ndim)


def step_seeds(seed: int, steps: int, views: int) -> np.ndarray:
    """Seeds of shape ``(steps + 1, views, 2)``: per step and view, one for the residual's render and one
    for the derivative's (step ``steps`` renders the final image only); a function of ``seed`` alone,
    drawn from its stream ``"optimize"``, so a run is reproducible and no two renders share samples."""
    return stream(seed, "optimize").integers(0, 2**62, size=(steps + 1, views, 2))


def _numeric(x: Any) -> bool:
    try:
        return np.asarray(x).dtype.kind in "iuf"
    except (TypeError, ValueError):
        return False


def _describe(x: Any) -> str:
    shape = np.shape(x) if _numeric(x) else None
    return f"an array of shape {shape}" if shape is not None else repr(x)[:80]


def check_targets(targets: Any, shapes: Sequence[tuple[int, ...]]) -> np.ndarray:
    """One finite image per view, view v of shape ``shapes[v]`` (the views' films): shape ``(V, *film)``.
    A single array is the one view's when there is one view. One ValidationError naming ``targets``
    (the count) or ``targets[v]`` (a wrong shape, NaN or inf) otherwise."""
    if isinstance(targets, np.ndarray) and targets.ndim == len(shapes[0]) and len(shapes) == 1:
        targets = [targets]
    if isinstance(targets, str | Mapping) or not hasattr(targets, "__len__") or len(targets) != len(shapes):
        raise ValidationError(
            "targets", f"must hold one image per view ({len(shapes)} views), got {_describe(targets)}"
        )
    images = []
    for i, (target, shape) in enumerate(zip(targets, shapes, strict=True)):
        image = np.asarray(target, dtype=np.float64) if _numeric(target) else None
        if image is None or image.shape != tuple(shape):
            size = " x ".join(str(n) for n in shape)
            raise ValidationError(
                f"targets[{i}]", f"must be an image of the view's {size} pixels, got {_describe(target)}"
            )
        if not np.all(np.isfinite(image)):
            raise ValidationError(f"targets[{i}]", "must be finite (it holds NaN or inf)")
        images.append(image)
    if len({im.shape for im in images}) > 1:
        raise ValidationError("targets", "views of different sizes cannot share one loss array")
    return np.stack(images)


def check_step_sizes(lr: Any, k: int) -> np.ndarray:
    """The first step size of each of k parameters: one positive number for all, or k of them."""
    values = np.atleast_1d(np.asarray(lr, dtype=np.float64)) if _numeric(lr) else None
    if values is None or values.ndim != 1 or values.size not in (1, k):
        raise ValidationError("lr", f"must be a positive step size or one per parameter ({k}), got {lr!r}")
    for v in values:
        check_positive("lr", float(v))
    return np.broadcast_to(values, (k,)).copy()


def check_bounds(bounds: Any, names: Sequence[str]) -> Mapping[str, Any]:
    """The user's ``bounds``, a mapping (None: empty) whose keys are among the parameters ``names``."""
    bounds = {} if bounds is None else bounds
    if not isinstance(bounds, Mapping):
        raise ValidationError("bounds", f"must map parameter names to (low, high), got {bounds!r}")
    for name in bounds:
        if name not in names:
            raise ValidationError("bounds", f"{name!r} is not one of the parameters {list(names)}")
    return bounds


def narrow_bounds(
    bounds: Mapping[str, Any], names: Sequence[str], lower: np.ndarray, upper: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``lower``, ``upper`` (the widest valid offsets of each parameter) with the user's ``bounds[name] =
    (low, high)`` put in, each checked to keep the offset 0 and to stay within the valid ones."""
    lower, upper = lower.copy(), upper.copy()
    for i, name in enumerate(names):
        if name not in bounds:
            continue
        pair = bounds[name]
        if not isinstance(pair, Sequence) or len(pair) != 2:
            raise ValidationError(f"bounds[{name!r}]", f"must be a pair (low, high), got {pair!r}")
        lo, hi = (check_finite(f"bounds[{name!r}]", v) for v in pair)
        if not lower[i] <= lo <= 0.0 <= hi <= upper[i]:
            raise ValidationError(
                f"bounds[{name!r}]",
                f"must satisfy {lower[i]:g} <= low <= 0 <= high <= {upper[i]:g} (offsets from the scene),"
                f" got {pair!r}",
            )
        lower[i], upper[i] = lo, hi
    return lower, upper


def check_schedule(steps: Any, decay: Any, record: Any) -> tuple[int, float, tuple[int, ...]]:
    """``steps`` >= 1, ``decay`` in (0, 1] and the recorded steps (default: the first and the last), each
    in 0..steps; one ValidationError naming the field otherwise."""
    steps = check_int("steps", steps)
    decay = check_finite("decay", decay)
    if not 0.0 < decay <= 1.0:
        raise ValidationError("decay", f"must lie in (0, 1], got {decay!r}")
    record = (0, steps) if record is None else tuple(check_int("record", r, minimum=0) for r in record)
    if any(r > steps for r in record):
        raise ValidationError("record", f"steps must lie in 0..{steps}, got {list(record)}")
    return steps, decay, record


@dataclass(frozen=True)
class Views:
    """How to render the problem at offsets θ: the package's callables, injected.

    Attributes
    ----------
    scene_at : callable
        ``scene_at(theta)``: the scene moved by the offsets θ (an array of k), such that
        ``render_gradient(scene_at(theta), params)`` is the derivative at θ.
    with_view : callable
        ``with_view(scene, view)``: the scene seen by one view (e.g. with that camera).
    render, render_gradient : callable
        ``render(scene, spp=, seed=, progress=)`` with ``.value``, and ``render_gradient(scene, params,
        method=, spp=, seed=, progress=, **options)`` with ``.derivative`` of shape ``(k, *film)``.
    views : tuple
        The views (at least one).
    params : tuple of str
        The k parameters.
    method, spp, options
        Passed to ``render_gradient`` (``spp`` to ``render`` too).
    """

    scene_at: Callable[[np.ndarray], Any]
    with_view: Callable[[Any, Any], Any]
    render: Callable[..., Any]
    render_gradient: Callable[..., Any]
    views: tuple[Any, ...]
    params: tuple[str, ...]
    method: str
    spp: int
    options: Mapping[str, Any] = field(default_factory=dict)

    def values(self, theta: np.ndarray, seeds: np.ndarray) -> np.ndarray:
        """The images at θ, one per view (view v from seed ``seeds[v]``): shape ``(V, *film)``."""
        scene = self.scene_at(theta)
        return np.stack(
            [
                np.asarray(
                    self.render(self.with_view(scene, view), spp=self.spp, seed=int(s), progress=False).value
                )
                for view, s in zip(self.views, seeds, strict=True)
            ]
        )

    def derivatives(self, theta: np.ndarray, seeds: np.ndarray) -> np.ndarray:
        """The k derivative images at θ per view: shape ``(k, V, *film)``."""
        scene = self.scene_at(theta)
        per_view = [
            self.render_gradient(
                self.with_view(scene, view), list(self.params), method=self.method, spp=self.spp,
                seed=int(s), progress=False, **self.options,
            ).derivative
            for view, s in zip(self.views, seeds, strict=True)
        ]  # fmt: skip
        return np.stack(per_view, axis=1)


@dataclass(frozen=True)
class OptimizeResult:
    """The history of a run of :func:`descend` (its arrays read-only).

    Attributes
    ----------
    params : tuple of str
        The k parameters; θ are offsets from the scene as given.
    theta : ndarray, shape (steps + 1, k)
        θ before each step, the last row the result.
    loss : ndarray, shape (steps + 1,)
        The loss of the residual render at each row of ``theta`` (the last from a final render).
    gradient : ndarray, shape (steps, k)
        The loss gradient estimate of each step.
    seconds : ndarray, shape (steps,)
        Wall time of each step (its renders and the update).
    images : Mapping[int, ndarray]
        The residual renders ``(V, *film)`` at the recorded steps (row indices of ``theta``).
    targets : ndarray
        The target images, shape ``(V, *film)``.
    lower, upper : ndarray, shape (k,)
        The bounds θ was kept in.
    lr : ndarray, shape (k,)
        The first step size of each parameter; ``decay`` the factor it shrinks by over the run.
    method : str
        The gradient method; ``spp`` and ``seed`` as given.
    """

    params: tuple[str, ...]
    theta: np.ndarray
    loss: np.ndarray
    gradient: np.ndarray
    seconds: np.ndarray
    images: Mapping[int, np.ndarray]
    targets: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    lr: np.ndarray
    decay: float
    method: str
    spp: int
    seed: int

    def __post_init__(self) -> None:
        for name in ("theta", "loss", "gradient", "seconds", "targets", "lower", "upper", "lr"):
            getattr(self, name).flags.writeable = False

    @property
    def steps(self) -> int:
        """The number of Adam steps taken."""
        return self.gradient.shape[0]

    @property
    def final(self) -> dict[str, float]:
        """The last θ by parameter name."""
        return dict(zip(self.params, self.theta[-1].tolist(), strict=True))


def descend(
    views: Views,
    targets: np.ndarray,
    theta0: np.ndarray,
    *,
    steps: int,
    lr: np.ndarray,
    seed: int,
    lower: np.ndarray,
    upper: np.ndarray,
    decay: float = 0.1,
    record: Sequence[int] = (),
    progress: bool | None = None,
) -> OptimizeResult:
    r"""Minimise the L2 loss over the views by ``steps`` Adam steps from ``theta0`` (inputs already checked).

    Step t (0-based) renders the residual images and the k derivative images at $θ_t$ (seeds from
    :func:`step_seeds`), forms $∂L/∂θ$ (:func:`l2_gradient`) and takes an Adam step of size
    $η_t = \mathrm{lr} · \mathrm{decay}^{t / (\mathrm{steps} - 1)}$ (geometric, from lr to lr · decay:
    under noisy gradients a constant step leaves θ jittering by about one step around the optimum),
    projected onto [lower, upper]. A final render at $θ_{\mathrm{steps}}$ gives the last loss. ``record``:
    the rows of θ whose images the result keeps. A progress bar counts the steps and shows the loss.
    """
    k, n_views = len(views.params), len(views.views)
    seeds = step_seeds(seed, steps, n_views)
    targets = np.asarray(targets, dtype=np.float64)
    state = AdamState.start(theta0)
    thetas, losses = [state.theta], []
    gradients, seconds, images = np.zeros((steps, k)), np.zeros(steps), {}
    with _progress.steps(f"optimize {views.method}", steps, progress) as tick:
        for t in range(steps):
            start = time.perf_counter()
            values = views.values(state.theta, seeds[t, :, 0])
            derivatives = views.derivatives(state.theta, seeds[t, :, 1])
            gradients[t] = l2_gradient(values - targets, derivatives)
            losses.append(l2_loss(values, targets))
            eta = lr * decay ** (t / max(steps - 1, 1))
            state = adam_step(state, gradients[t], eta, lower, upper)
            thetas.append(state.theta)
            seconds[t] = time.perf_counter() - start
            if t in record:
                images[t] = values
            tick(f"loss {losses[-1]:.4g}")
    values = views.values(state.theta, seeds[steps, :, 0])
    losses.append(l2_loss(values, targets))
    if steps in record:
        images[steps] = values
    for image in images.values():
        image.flags.writeable = False
    return OptimizeResult(
        params=tuple(views.params),
        theta=np.array(thetas),
        loss=np.array(losses),
        gradient=gradients,
        seconds=seconds,
        images=images,
        targets=targets.copy(),
        lower=np.array(lower, dtype=np.float64).copy(),
        upper=np.array(upper, dtype=np.float64).copy(),
        lr=np.array(lr, dtype=np.float64).copy(),
        decay=float(decay),
        method=views.method,
        spp=views.spp,
        seed=seed,
    )
