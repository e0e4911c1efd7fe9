"""What a method estimates: the pixels of an image, or the irradiance at one point, in independent batches.

A task fixes the scene, the parameter, the sample count, the seed and the batches;
``task.evaluate(theta, transforms)`` binds the scene at θ (a float, or a Dual for
the gradient, :func:`~flatland.state.build_state`), runs the integrator
(:mod:`flatland.integrator`) once under the method's
:class:`~flatland.integrator.Transforms`, and returns a :class:`Tally` of per-batch,
per-pixel means. A task's ``param`` may be a tuple of k parameters: the gradient
methods then bind the scene at :meth:`ImageTask.dual_offset` (k seeds e_i) and the
derivative has a leading axis of k, one slot per parameter. Methods
(:mod:`flatland.methods`) differ only in the ``theta`` and the transforms they pass,
so they share every primary sample: sample j of pixel p
has the global index ``p * spp + j`` (batch ``j // (spp / batches)``), and every
number drawn for it is keyed on that index (:class:`flatland.core.rng.Draws`), so
results do not depend on :data:`CHUNK`. The same names as :mod:`sphere3d.tasks`.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core import progress
from flatland.core.dual import detach, tangent, variable, variables
from flatland.core.rng import Draws
from flatland.integrator import (
    PRIMARY_UNIFORMS,
    Context,
    Identity,
    Transforms,
    cosine_ratio,
    pixel_samples,
    shade,
    trace_paths,
)
from flatland.lights import Lights
from flatland.scene import Scene
from flatland.state import Parameter, SceneState, build_state

__all__ = ["CHUNK", "ImageTask", "PointTask", "Tally"]

CHUNK = 1 << 15
"""Primary samples processed together (bounds memory; results do not depend on it, up to the
rounding of the per-pixel sums, which add the same numbers in another grouping)."""


@dataclass(frozen=True)
class Tally:
    """Per-batch, per-pixel estimates of the value and the derivative, shape (batches, pixels); for
    k parameters the derivative has a leading axis of k, (k, batches, pixels)."""

    value: np.ndarray
    derivative: np.ndarray


@dataclass(frozen=True)
class ImageTask:
    """Every pixel of the scene's camera: ``spp`` samples per pixel in ``batches`` batches of
    ``spp // batches``, which give the standard errors; paths of up to ``max_depth`` vertices
    (1: direct illumination, :func:`~flatland.integrator.trace_paths`)."""

    scene: Scene
    param: Parameter | tuple[Parameter, ...] | None
    spp: int
    seed: int
    batches: int
    max_depth: int = 1

    @property
    def pixels(self) -> int:
        return self.scene.camera.pixels

    @property
    def k(self) -> int | None:
        """The number of parameters of a tuple ``param``; None for one parameter (or none)."""
        return _k(self.param)

    def dual_offset(self) -> Any:
        """The offset θ0 = 0 as forward-mode seed(s): ``variable(0.0)``, or for k parameters
        ``variables(k)`` (parameter i with the unit tangent e_i)."""
        return _dual_offset(self.param)

    def parameters(self) -> tuple[Parameter, ...]:
        """The parameters, as a tuple (one for a single parameter)."""
        return _parameters(self.param)

    @property
    def per_batch(self) -> int:
        return self.spp // self.batches

    def state(self, theta: Any) -> SceneState:
        """The scene bound at parameter offset ``theta`` (float or Dual)."""
        return build_state(self.scene, self.param, theta)

    def evaluate(self, theta: Any, transforms: Transforms | None = None) -> Tally:
        """Estimate every pixel in every batch at offset ``theta`` under ``transforms`` (default: identity).

        After the sums, ``transforms.pixel_extra`` may add a derivative-only term per
        batch and pixel (2D only, the boundary method).
        """
        state = self.state(theta)
        transforms = transforms or Identity()
        value, deriv = _sums(self, state, transforms, pixel_samples)
        extra = transforms.pixel_extra(self, state)
        if extra is not None:
            deriv = deriv + extra
        return Tally(value, deriv)


@dataclass(frozen=True)
class PointTask:
    r"""The irradiance $E(x) = ∫ L_i(x, φ) \max(0, \cos(φ - φ_n))\, dφ$
    at a fixed ``point`` with unit ``normal``: ``n`` samples in ``batches`` batches (one "pixel"). With
    ``max_depth`` d > 1, $L_i$ is the radiance of paths of up to d - 1 further vertices."""

    scene: Scene
    param: Parameter | tuple[Parameter, ...] | None
    point: tuple[float, float]
    normal: tuple[float, float]
    n: int
    seed: int
    batches: int
    max_depth: int = 1

    pixels = 1

    @property
    def k(self) -> int | None:
        """The number of parameters of a tuple ``param``; None for one parameter (or none)."""
        return _k(self.param)

    def dual_offset(self) -> Any:
        """The offset θ0 = 0 as forward-mode seed(s), as :meth:`ImageTask.dual_offset`."""
        return _dual_offset(self.param)

    def parameters(self) -> tuple[Parameter, ...]:
        """The parameters, as a tuple (one for a single parameter)."""
        return _parameters(self.param)

    @property
    def per_batch(self) -> int:
        return self.n // self.batches

    def state(self, theta: Any) -> SceneState:
        """The scene bound at parameter offset ``theta`` (float or Dual)."""
        return build_state(self.scene, self.param, theta)

    def evaluate(self, theta: Any, transforms: Transforms | None = None) -> Tally:
        """Estimate E at the point in every batch at offset ``theta`` under ``transforms``."""

        def estimate(ctx: Context, pixel: np.ndarray, u: np.ndarray, draws: Draws) -> Any:
            n = pixel.size
            x = np.tile(np.array(self.point, dtype=np.float64), (n, 1))
            normal = np.tile(np.array(self.normal, dtype=np.float64), (n, 1))
            if ctx.max_depth == 1:
                return shade(ctx, x, normal, np.full(n, -1), u[:, 1:], draws)
            e, bounce = shade(ctx, x, normal, np.full(n, -1), u[:, 1:], draws, True)
            # the indirect part of E by the cosine sample: L_i cos / p_cos = 2 L_i cos_θ / cos_θ0
            beta = 2.0 * cosine_ratio(bounce.cosine)
            beta = beta if bounce.weight is None else beta * bounce.weight  # the transforms' kernel weight
            return trace_paths(ctx, e, np.arange(n), beta, bounce, draws, 2)

        value, deriv = _sums(self, self.state(theta), transforms, estimate)
        return Tally(value, deriv)


def _k(param: Any) -> int | None:
    return len(param) if isinstance(param, tuple) else None


def _dual_offset(param: Any) -> Any:
    return variables(len(param)) if isinstance(param, tuple) else variable(0.0)


def _parameters(param: Any) -> tuple[Parameter, ...]:
    return param if isinstance(param, tuple) else () if param is None else (param,)


def _chunks(total: int) -> Iterator[np.ndarray]:
    """Global sample indices ``pixel * spp + j`` in consecutive ranges of at most :data:`CHUNK`."""
    for lo in range(0, total, CHUNK):
        yield np.arange(lo, min(lo + CHUNK, total), dtype=np.int64)


def _sums(
    task: ImageTask | PointTask,
    state: SceneState,
    transforms: Transforms | None,
    estimate: Any,
) -> tuple[np.ndarray, np.ndarray]:
    """Per-batch, per-pixel means of ``estimate(ctx, pixel, u, draws)`` (values and tangents), one pass of
    the call's progress bar (:mod:`flatland.core.progress`) advanced per chunk."""
    spp = task.spp if isinstance(task, ImageTask) else task.n
    pixels, batches, seed = task.pixels, task.batches, task.seed
    state0 = state.detached()
    ctx = Context(state, state0, Lights.of(state0), transforms or Identity(), task.max_depth)
    per_batch = spp // batches
    size = batches * pixels
    k = state.k
    sums_v = np.zeros(size)
    sums_t = np.zeros(size if k is None else (k, size))
    progress.start(-(-pixels * spp // CHUNK))
    for index in _chunks(pixels * spp):
        pixel, j = np.divmod(index, spp)
        batch = j // per_batch
        draws = Draws.of(seed, index)
        u = draws.uniforms("samples", PRIMARY_UNIFORMS)  # the primary sample, the same for every method
        est = estimate(ctx, pixel, u, draws)
        key = batch * pixels + pixel
        sums_v += np.bincount(key, weights=detach(est), minlength=size)
        if k is None:
            sums_t += np.bincount(key, weights=tangent(est), minlength=size)
        else:  # each parameter's slot summed as a single tangent would be
            t_dot = tangent(est, k)
            for i in range(k):
                sums_t[i] += np.bincount(key, weights=t_dot[i], minlength=size)
        progress.advance()
    value = (sums_v / per_batch).reshape(batches, pixels)
    deriv = (sums_t / per_batch).reshape((*sums_t.shape[:-1], batches, pixels))
    return value, deriv
