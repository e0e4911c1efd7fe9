r"""Bias of a derivative image against a reference, measured from independent batches.

A method renders B independent batches of a derivative image, shape (B, ...): the
batches share no sample, the pixels of one batch may (a splatted film counts each
sample in every pixel its filter covers), so every standard error here comes from the
spread over the batches, with Student's t at B - 1 degrees of freedom
(:func:`sidak_t`). The reference $r$ (a closed form, or a stored Richardson finite
difference with per-pixel standard errors $s_r$, its pixels independent) is the same
for every batch. Tutorial 11 measures where reparameterization is biased on the sphere
with these functions (Loubet et al. 2019, Sec. 4.1).

========================  ===================================================================
:func:`mean_se`           mean image and its per-pixel standard error over the batches
:func:`over_batches`      mean and standard error of a statistic computed once per batch
:func:`fractions`         per batch, the least-squares fraction of the reference kept in a region
:func:`kept`              that fraction's mean, with the batches' and the reference's errors
:func:`floor_along`       RMS bias along the reference: a lower bound of the RMS bias
:func:`squared_bias`      unbiased mean squared bias over the pixels, jackknife standard error
:func:`sidak_t`           two-sided Student-t quantile, Šidák-corrected over the comparisons
========================  ===================================================================
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import special

from flatland.core.stats import sidak
from flatland.core.validate import ValidationError

__all__ = ["floor_along", "fractions", "kept", "mean_se", "over_batches", "sidak_t", "squared_bias"]


def sidak_t(alpha: float, comparisons: int, dof: int) -> float:
    """Two-sided Student-t quantile with ``dof`` degrees of freedom at family-wise level ``alpha``,
    Šidák-corrected over ``comparisons``: each comparison at $1 - (1 - α)^{1/m}$."""
    if dof < 1:
        raise ValidationError("dof", f"must be >= 1, got {dof!r}")
    return float(special.stdtrit(dof, 1.0 - sidak(alpha, comparisons) / 2.0))  # Student t quantile


def _batches(batches: Any) -> np.ndarray:
    b = np.asarray(batches, dtype=np.float64)
    if b.ndim < 2 or b.shape[0] < 2:
        raise ValidationError("batches", f"must be (batches >= 2, pixels...), got shape {b.shape}")
    return b


def mean_se(batches: Any) -> tuple[np.ndarray, np.ndarray]:
    """Mean image over the batches and its standard error per pixel, $\\mathrm{std}_b / \\sqrt{B}$."""
    b = _batches(batches)
    return b.mean(axis=0), b.std(axis=0, ddof=1) / np.sqrt(len(b))


def over_batches(values: Any) -> tuple[float, float]:
    """Mean of a statistic computed once per batch, shape (B,), and its standard error from the
    batches' spread (independent batches; Student's t with B - 1 degrees of freedom)."""
    v = np.asarray(values, dtype=np.float64).ravel()
    if v.size < 2:
        raise ValidationError("values", f"need one value per batch, at least 2, got {v.size}")
    return float(v.mean()), float(v.std(ddof=1) / np.sqrt(v.size))


def fractions(batches: Any, ref: Any, ref_se: Any, mask: Any) -> np.ndarray:
    r"""Per batch, the least-squares fraction of ``ref`` the batch's image keeps in ``mask``:

    $k_b = \sum_p d_{b,p} r_p / \sum_p (r_p^2 - s_{r,p}^2)$, the reference's own noise taken
    out of $\sum r^2$ (its expectation is $\sum r^2 + \sum s_r^2$). 1 for an unbiased method;
    linear in the image, so the mean of the $k_b$ is the mean image's fraction.
    """
    b, mask = _batches(batches), np.asarray(mask, dtype=bool)
    r, rse = np.asarray(ref, dtype=np.float64)[mask], np.asarray(ref_se, dtype=np.float64)[mask]
    denominator = np.sum(r**2 - rse**2)
    if not denominator > 0.0:
        raise ValidationError("mask", "the reference has no derivative above its noise there")
    return b[:, mask] @ r / denominator


def kept(batches: Any, ref: Any, ref_se: Any, mask: Any) -> tuple[float, float]:
    r"""The mean of :func:`fractions` and its standard error.

    Two independent parts in quadrature: the batches' spread (:func:`over_batches`), and
    the reference's per-pixel errors propagated to first order,
    $\sqrt{\sum_p d_p^2 s_{r,p}^2} / \sum_p (r_p^2 - s_{r,p}^2)$ (its pixels independent).
    """
    k, se = over_batches(fractions(batches, ref, ref_se, mask))
    mask = np.asarray(mask, dtype=bool)
    r, rse = np.asarray(ref, dtype=np.float64)[mask], np.asarray(ref_se, dtype=np.float64)[mask]
    d = _batches(batches).mean(axis=0)[mask]
    return k, float(np.hypot(se, np.sqrt(np.sum(d**2 * rse**2)) / np.sum(r**2 - rse**2)))


def floor_along(kept_fractions: Sequence[tuple[float, float]], ref: Any, masks: Sequence[Any]) -> float:
    r"""RMS per pixel of the bias along the reference, $(k - 1)\,r$ in each region (``masks``, with
    their ``kept_fractions`` $(k, \mathrm{se})$): a lower bound of the RMS bias, as the part of the
    bias orthogonal to the reference is not counted."""
    r = np.asarray(ref, dtype=np.float64)
    total = sum((k - 1.0) ** 2 * np.sum(r[np.asarray(m, dtype=bool)] ** 2)
                for (k, _), m in zip(kept_fractions, masks, strict=True))  # fmt: skip
    return float(np.sqrt(total / r.size))


def squared_bias(batches: Any, ref: Any, ref_se: Any = 0.0) -> tuple[float, float]:
    r"""Mean over pixels of $(d - r)^2 - \mathrm{se}^2 - s_r^2$, an unbiased estimate of the mean
    squared bias ($d$, se: the batches' mean image and its standard error), and its standard error.

    Nonlinear in the batches, so the error is the jackknife's: the estimate without batch
    b, b = 1..B, and $\mathrm{se}^2 = (B - 1)/B \sum_b (x_{(b)} - \bar x)^2$, Student's t at
    B - 1 degrees of freedom. The reference is the same in every $x_{(b)}$; its own noise e
    ($s_r$ per pixel, independent pixels, normal) adds
    $\operatorname{Var} \sum_p ((b_p - e_p)^2 - s_r^2) / P^2 = \sum_p (4 b_p^2 s_r^2 + 2 s_r^4) / P^2$
    in quadrature, $b_p^2$ estimated by the pixel's own term. B images of the film's size
    are made (one per left-out batch).
    """
    b = _batches(batches)
    ref = np.asarray(ref, dtype=np.float64)
    ref_se = np.broadcast_to(np.asarray(ref_se, dtype=np.float64), ref.shape)

    def estimate(x: np.ndarray) -> float:
        return float(np.mean((x.mean(axis=0) - ref) ** 2 - x.var(axis=0, ddof=1) / len(x) - ref_se**2))

    n = len(b)
    leave_one_out = np.array([estimate(np.delete(b, i, axis=0)) for i in range(n)])
    jackknife = (n - 1) / n * np.sum((leave_one_out - leave_one_out.mean()) ** 2)
    d, se = mean_se(b)
    per_pixel = (d - ref) ** 2 - se**2 - ref_se**2
    reference = max(0.0, float(np.sum(4.0 * per_pixel * ref_se**2 + 2.0 * ref_se**4))) / d.size**2
    return estimate(b), float(np.sqrt(jackknife + reference))
