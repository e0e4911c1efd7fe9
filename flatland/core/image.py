"""Named results of the renderers, shared by flatland (1D film) and sphere3d (2D film).

Pixel arrays have the film's shape: ``(width,)`` in flatland, ``(height, width)``
in sphere3d. Standard errors come from independent batches of samples per pixel:
a renderer estimates every pixel once per batch and :meth:`Image.from_batches` /
:meth:`GradientImage.from_batches` turn the per-batch arrays into the mean and its
standard error ``std(ddof=1) / sqrt(batches)``.

A sum over pixels takes its standard error from the batches too (:class:`FilmSum`,
:func:`film_sum_stderr`): the pixels of one batch may share samples (sphere3d's
splatted film counts each camera sample in every pixel its filter covers; an edge
point of ``boundary`` reaches several pixels), so their errors are correlated and
adding the pixels' standard errors in quadrature is wrong; the batches share none.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flatland.core.stats import spread
from flatland.core.validate import ValidationError, check_choice, check_int

__all__ = [
    "DEFAULT_MAX_BATCHES",
    "BatchSummary",
    "FilmSum",
    "GradientImage",
    "GradientImages",
    "Image",
    "Options",
    "check_finite_result",
    "film_sum_stderr",
    "relative_error",
    "resolve_batches",
    "summarize_batches",
]

DEFAULT_MAX_BATCHES = 16
"""Default number of batches: the largest divisor of the sample count up to this."""


def resolve_batches(samples: int, batches: Any, field: str = "spp") -> int:
    """Number of independent batches: ``batches`` if it divides ``samples``, else the default.

    The default is the largest divisor of ``samples`` not above
    :data:`DEFAULT_MAX_BATCHES`. ``field`` names the sample count in the error.
    """
    if batches is None:
        return max(b for b in range(1, min(samples, DEFAULT_MAX_BATCHES) + 1) if samples % b == 0)
    b = check_int("batches", batches)
    if samples % b:
        raise ValidationError("batches", f"must divide {field}={samples} (equal batches), got {batches!r}")
    return b


@dataclass(frozen=True)
class BatchSummary:
    """Mean over independent batches and its standard error (infinite with one batch)."""

    mean: np.ndarray
    stderr: np.ndarray


def check_finite_result(what: str, estimates: np.ndarray) -> None:
    """Raise FloatingPointError if an estimator produced NaN or inf: no such value leaves a public function.

    Validation keeps the user's input finite and in range, so a non-finite estimate
    is a defect of the renderer, reported as an internal error (never as a usage
    error); the message says how many entries and where, for the bug report.
    """
    bad = ~np.isfinite(estimates)
    if np.any(bad):
        where = np.argwhere(bad)[:3].tolist()
        raise FloatingPointError(
            f"internal error: {int(bad.sum())} of {bad.size} {what} are not finite (first at {where}); "
            "please report the scene, method, options and seed"
        )


def summarize_batches(per_batch: np.ndarray) -> BatchSummary:
    """Mean and standard error over axis 0 of per-batch estimates."""
    per_batch = np.asarray(per_batch, dtype=np.float64)
    b = per_batch.shape[0]
    mean = per_batch.mean(axis=0)
    if b < 2:
        return BatchSummary(mean, np.full_like(mean, np.inf))
    # rounding-level spread between batches is no variance (one policy: flatland.core.stats.spread)
    return BatchSummary(mean, spread(per_batch.std(axis=0, ddof=1), mean) / np.sqrt(b))


def film_sum_stderr(per_batch: np.ndarray) -> float:
    """Standard error of the sum over all pixels, from per-batch estimates of shape ``(batches, *film)``.

    Each batch's film sum is an i.i.d. sample (the batches share no samples), so the
    mean's standard error is ``std(ddof=1) / sqrt(batches)`` of the per-batch sums,
    whatever the correlation between one batch's pixels; infinite with one batch.
    Rounding-level spread is no variance (:func:`flatland.core.stats.spread`, the
    rule of :func:`summarize_batches`), at the scale of the summed magnitudes.
    """
    per_batch = np.asarray(per_batch, dtype=np.float64)
    b = per_batch.shape[0]
    if b < 2:
        return math.inf
    flat = per_batch.reshape(b, -1)
    sums = flat.sum(axis=1)
    # a sum's rounding grows with Σ_j |x_j|, not |Σ_j x_j| (a derivative's signed pixels cancel); at
    # this scale pixels with zero spread (each under ROUNDING |mean_j|) give a sum with zero spread
    scale = float(np.abs(flat).sum(axis=1).mean())
    return float(spread(sums.std(ddof=1), scale)) / math.sqrt(b)


@dataclass(frozen=True)
class FilmSum:
    """The sum of an image over all pixels (Σ_j I_j or Σ_j dI_j/dθ) and its standard error.

    Attributes
    ----------
    total : float
        Σ over the film's pixels of the per-pixel estimates.
    stderr : float
        Its standard error: from the per-batch sums (:func:`film_sum_stderr`) when
        ``from_batches``, else the pixels' standard errors added in quadrature.
    from_batches : bool
        False for an image built by hand without its batches' sums: the quadrature
        is correct only when the pixels are estimated independently.
    """

    total: float
    stderr: float
    from_batches: bool


def relative_error(g: np.ndarray, g_ref: np.ndarray) -> float:
    r"""The gradient-image error metric $\mathrm{mean}|g - g_{ref}| / \max|g_{ref}|$.

    Scale-free, so one bound can be stated per scene; 0 for a perfect match.
    """
    g = np.asarray(g, dtype=np.float64)
    g_ref = np.asarray(g_ref, dtype=np.float64)
    if g.shape != g_ref.shape:
        raise ValueError(f"g: shape {g.shape} does not match g_ref's {g_ref.shape}")
    scale = np.max(np.abs(g_ref))
    if scale == 0.0:
        raise ValueError("g_ref: all zero, the relative error is undefined")
    return float(np.mean(np.abs(g - g_ref)) / scale)


class Options(Mapping[str, Any]):
    """A result's options, read-only: a copy of the mapping it was given.

    Unlike ``types.MappingProxyType`` it pickles, so results cross process boundaries (a study's
    workers send theirs back pickled). Equal to any mapping with the same items.
    """

    __slots__ = ("_items",)

    def __init__(self, mapping: Mapping[str, Any] | None = None) -> None:
        self._items = dict(mapping or {})

    def __getitem__(self, key: str) -> Any:
        return self._items[key]

    def __iter__(self) -> Any:
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __repr__(self) -> str:
        return f"Options({self._items!r})"

    def __reduce__(self) -> tuple[type, tuple[dict[str, Any]]]:
        return Options, (self._items,)


@dataclass(frozen=True)
class Image:
    """A rendered image: per-pixel estimate and its standard error.

    Attributes
    ----------
    value : ndarray
        Pixel values (radiance integrated against the pixel filter).
    stderr : ndarray
        Standard error of each pixel, from ``batches`` independent batches.
    spp : int
        Samples per pixel.
    seed : int
        Seed the image was rendered with (same seed, same image).
    batches : int
        Number of independent batches behind ``stderr``.
    scene : str
        Name of the scene.

    The pixels' errors may be correlated (a splatted film), so ``stderr`` in quadrature is
    no sum's standard error; the film sum of I with its own, from the batches, is
    ``GradientImage.film_sum("value")`` (:meth:`GradientImage.film_sum`).
    """

    value: np.ndarray
    stderr: np.ndarray
    spp: int
    seed: int
    batches: int
    scene: str = ""

    @property
    def shape(self) -> tuple[int, ...]:
        """Film shape."""
        return self.value.shape

    @classmethod
    def from_batches(cls, per_batch: np.ndarray, *, spp: int, seed: int, scene: str = "") -> Image:
        """The image from per-batch pixel estimates of shape ``(batches, *film)``."""
        check_finite_result("per-batch pixel values", np.asarray(per_batch))
        summary = summarize_batches(per_batch)
        return cls(summary.mean, summary.stderr, spp, seed, np.shape(per_batch)[0], scene)


class _OptionsFilm:
    """What the gradient results share: their ``options`` kept read-only, their film's shape."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "options", Options(self.options))

    @property
    def shape(self) -> tuple[int, ...]:
        """Film shape."""
        return self.value.shape


@dataclass(frozen=True)
class GradientImage(_OptionsFilm):
    """A rendered image and its derivative with respect to one scene parameter.

    Attributes
    ----------
    value, derivative : ndarray
        Per-pixel estimates of I and dI/dθ.
    value_stderr, derivative_stderr : ndarray
        Their standard errors from ``batches`` independent batches.
    param : str
        The parameter θ (e.g. ``"occluder.translate.x"``).
    method : str
        The method that produced the derivative.
    options : Mapping
        The method's options (read-only).
    spp, seed, batches : int
        Samples per pixel, seed, number of batches.
    scene : str
        Name of the scene.
    value_sum_stderr, derivative_sum_stderr : float or None
        Standard errors of the film sums Σ_j I_j and Σ_j dI_j/dθ from the per-batch
        sums (:func:`film_sum_stderr`), set by :meth:`from_batches`; None for an image
        built without its batches: then :meth:`film_sum` adds the pixels' standard
        errors in quadrature, which holds only for independently estimated pixels.
    """

    value: np.ndarray
    derivative: np.ndarray
    value_stderr: np.ndarray
    derivative_stderr: np.ndarray
    param: str
    method: str
    spp: int
    seed: int
    batches: int
    options: Mapping[str, Any] = field(default_factory=dict)
    scene: str = ""
    value_sum_stderr: float | None = None
    derivative_sum_stderr: float | None = None

    @classmethod
    def from_batches(
        cls,
        values: np.ndarray,
        derivatives: np.ndarray,
        *,
        param: str,
        method: str,
        spp: int,
        seed: int,
        options: Mapping[str, Any] | None = None,
        scene: str = "",
    ) -> GradientImage:
        """The gradient image from per-batch estimates of shape ``(batches, *film)``."""
        check_finite_result("per-batch pixel values", np.asarray(values))
        check_finite_result(f"per-batch pixel derivatives ({method})", np.asarray(derivatives))
        v, d = summarize_batches(values), summarize_batches(derivatives)
        return cls(
            value=v.mean,
            derivative=d.mean,
            value_stderr=v.stderr,
            derivative_stderr=d.stderr,
            param=param,
            method=method,
            spp=spp,
            seed=seed,
            batches=np.shape(values)[0],
            options=options or {},
            scene=scene,
            value_sum_stderr=film_sum_stderr(values),
            derivative_sum_stderr=film_sum_stderr(derivatives),
        )

    def film_sum(self, of: str = "derivative") -> FilmSum:
        """Σ over the film of ``of`` ("derivative": dI/dθ, or "value": I) with its standard error.

        The standard error is the one :meth:`from_batches` computed from the per-batch
        sums, valid however the pixels are correlated. An image built by hand without
        it (``*_sum_stderr`` None) gets the pixels' standard errors in quadrature,
        ``sqrt(Σ_j se_j²)``, flagged ``from_batches=False``: correct only when the pixels
        are estimated independently (never NaN: infinite when a pixel's is).
        """
        if check_choice("of", of, ("value", "derivative")) == "value":
            pixels, pixel_se, sum_se = self.value, self.value_stderr, self.value_sum_stderr
        else:
            pixels, pixel_se, sum_se = self.derivative, self.derivative_stderr, self.derivative_sum_stderr
        total = float(np.sum(pixels))
        if sum_se is not None:
            return FilmSum(total, float(sum_se), True)
        return FilmSum(total, float(np.sqrt(np.sum(np.square(pixel_se)))), False)

    def error_vs(self, reference: GradientImage | np.ndarray) -> float:
        """:func:`relative_error` of this derivative against a reference gradient image."""
        ref = reference.derivative if isinstance(reference, GradientImage) else reference
        return relative_error(self.derivative, ref)


@dataclass(frozen=True, eq=False)
class GradientImages(_OptionsFilm, Mapping[str, GradientImage]):
    """A rendered image and its derivatives with respect to k scene parameters, from one pass.

    A read-only mapping from each parameter's name to its :class:`GradientImage`
    (``images["occluder.translate.x"]``), in the order the parameters were given, with
    the arrays of all of them at hand.

    Attributes
    ----------
    value, value_stderr : ndarray
        Per-pixel I and its standard error (shared by every parameter).
    derivative, derivative_stderr : ndarray
        Per-pixel dI/dθ_i and their standard errors, shape ``(k, *film)``: row i is
        parameter ``params[i]``.
    params : tuple of str
        The k parameters.
    method, spp, seed, batches, options, scene
        As in :class:`GradientImage`.
    value_sum_stderr : float
        Standard error of the film sum of I from the per-batch sums.
    derivative_sum_stderr : tuple of float
        Per parameter, the standard error of the film sum of its derivative.
    """

    value: np.ndarray
    derivative: np.ndarray
    value_stderr: np.ndarray
    derivative_stderr: np.ndarray
    params: tuple[str, ...]
    method: str
    spp: int
    seed: int
    batches: int
    options: Mapping[str, Any] = field(default_factory=dict)
    scene: str = ""
    value_sum_stderr: float | None = None
    derivative_sum_stderr: tuple[float, ...] | None = None

    @classmethod
    def from_batches(
        cls,
        values: np.ndarray,
        derivatives: np.ndarray,
        *,
        params: tuple[str, ...],
        method: str,
        spp: int,
        seed: int,
        options: Mapping[str, Any] | None = None,
        scene: str = "",
    ) -> GradientImages:
        """The images from per-batch estimates: values ``(batches, *film)``, derivatives
        ``(k, batches, *film)``; parameter i's summary is exactly :meth:`GradientImage.from_batches`
        of ``derivatives[i]``."""
        run = dict(method=method, spp=spp, seed=seed, options=options, scene=scene)
        images = [
            GradientImage.from_batches(values, d, param=p, **run)
            for p, d in zip(params, derivatives, strict=True)
        ]
        first = images[0]
        return cls(
            value=first.value,
            derivative=np.stack([g.derivative for g in images]),
            value_stderr=first.value_stderr,
            derivative_stderr=np.stack([g.derivative_stderr for g in images]),
            params=tuple(params),
            batches=first.batches,
            value_sum_stderr=first.value_sum_stderr,
            derivative_sum_stderr=tuple(float(g.derivative_sum_stderr) for g in images),
            **run,  # type: ignore[arg-type]
        )

    def __getitem__(self, name: str) -> GradientImage:
        """The :class:`GradientImage` of parameter ``name`` (KeyError if it is not one of ``params``)."""
        if name not in self.params:
            raise KeyError(f"{name!r} is not one of the parameters {list(self.params)}")
        i = self.params.index(name)
        return GradientImage(
            value=self.value,
            derivative=self.derivative[i],
            value_stderr=self.value_stderr,
            derivative_stderr=self.derivative_stderr[i],
            param=name,
            method=self.method,
            spp=self.spp,
            seed=self.seed,
            batches=self.batches,
            options=self.options,
            scene=self.scene,
            value_sum_stderr=self.value_sum_stderr,
            derivative_sum_stderr=None
            if self.derivative_sum_stderr is None
            else self.derivative_sum_stderr[i],
        )

    def __iter__(self) -> Iterator[str]:
        return iter(self.params)

    def __len__(self) -> int:
        return len(self.params)
