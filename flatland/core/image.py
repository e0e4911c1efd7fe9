"""Named results of the renderers, shared by flatland (1D film) and sphere3d (2D film).

Pixel arrays have the film's shape: ``(width,)`` in flatland, ``(height, width)``
in sphere3d. Standard errors come from independent batches of samples per pixel.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

__all__ = ["GradientImage", "Image", "relative_error"]


def relative_error(g: np.ndarray, g_ref: np.ndarray) -> float:
    """The gradient-image error metric ``mean|g - g_ref| / max|g_ref|``.

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


def _frozen(mapping: Mapping[str, Any]) -> Mapping[str, Any]:
    return MappingProxyType(dict(mapping))


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


@dataclass(frozen=True)
class GradientImage:
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

    def __post_init__(self) -> None:
        object.__setattr__(self, "options", _frozen(self.options))

    @property
    def shape(self) -> tuple[int, ...]:
        """Film shape."""
        return self.value.shape

    def error_vs(self, reference: GradientImage | np.ndarray) -> float:
        """:func:`relative_error` of this derivative against a reference gradient image."""
        ref = reference.derivative if isinstance(reference, GradientImage) else reference
        return relative_error(self.derivative, ref)
