"""Sampling on the sphere, on triangles and on the film, as ``sample_x(u, ...)`` / ``pdf_x(x, ...)`` pairs.

Each ``sample_x`` maps uniform numbers ``u`` in [0, 1) (last axis: as many as the
sampler needs) deterministically to samples, so a seed fixes the samples and every
method that reads the same uniforms sees the same samples. Each ``pdf_x`` is the
density of what ``sample_x`` produces; a chi-square test per pair checks that claim.

Densities on S² are per steradian (solid angle); on triangles and meshes per unit
area; on the film per pixel² (offsets from the pixel centre in pixel units).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import special

from flatland.core.validate import ValidationError, check_choice, check_positive
from sphere3d.vector import cross, dot, frame, norm, normalize

__all__ = [
    "FILTERS",
    "FILTER_STD",
    "EmitterDirections",
    "emitter_directions",
    "filter_radius",
    "filter_value",
    "filter_value_1d",
    "log_filter_value",
    "log_filter_value_1d",
    "log_vmf",
    "pdf_cosine_hemisphere",
    "pdf_filter",
    "pdf_filter_1d",
    "pdf_mesh",
    "pdf_triangle",
    "pdf_uniform_sphere",
    "pdf_vmf",
    "sample_cosine_hemisphere",
    "sample_filter",
    "sample_mesh",
    "sample_triangle",
    "sample_uniform_sphere",
    "sample_vmf",
    "solid_angle_pdf",
    "triangle_area",
    "triangle_barycentrics",
    "vmf_hemisphere_fraction",
]

FOUR_PI = 4.0 * np.pi
FILTERS = ("box", "tent", "gaussian")
GAUSSIAN_SIGMA = 0.5
"""Standard deviation of the ``gaussian`` pixel filter, in pixels."""
GAUSSIAN_RADIUS = 3.0 * GAUSSIAN_SIGMA
"""Where the ``gaussian`` filter (shifted to be continuous) reaches 0, in pixels."""
FILTER_STD = {"box": math.sqrt(1.0 / 12.0), "tent": math.sqrt(1.0 / 6.0), "gaussian": GAUSSIAN_SIGMA}
"""Per-axis standard deviation of each pixel filter, in pixels (the gaussian's before truncation)."""


def _from_frame(local: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Local (x, y, z) coordinates about the unit ``axis`` (z) to world directions."""
    axis = np.asarray(axis, dtype=np.float64)
    t, b = frame(axis)  # one frame per axis, broadcast over the samples that share it
    return local[..., 0:1] * t + local[..., 1:2] * b + local[..., 2:3] * axis


# --------------------------------------------------------------------- sphere
def sample_uniform_sphere(u: np.ndarray) -> np.ndarray:
    """Uniform direction on S²: $z = 1 - 2u_0$, $φ = 2π u_1$."""
    u = np.asarray(u, dtype=np.float64)
    z = 1.0 - 2.0 * u[..., 0]
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * u[..., 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def pdf_uniform_sphere(omega: np.ndarray) -> np.ndarray:
    """$1 / 4π$."""
    return np.full(np.shape(omega)[:-1], 1.0 / FOUR_PI)


def sample_cosine_hemisphere(u: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Cosine-weighted direction about the unit ``normal`` (Malley: a uniform disk lifted up)."""
    u = np.asarray(u, dtype=np.float64)
    r = np.sqrt(u[..., 0])
    phi = 2.0 * np.pi * u[..., 1]
    z = np.sqrt(np.maximum(0.0, 1.0 - u[..., 0]))
    local = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)
    return _from_frame(local, normal)


def pdf_cosine_hemisphere(omega: np.ndarray, normal: np.ndarray) -> np.ndarray:
    r"""$\max(0, n·ω) / π$."""
    return np.maximum(0.0, dot(omega, normal)) / np.pi


def _check_kappa(kappa: float) -> float:
    return check_positive("kappa", kappa)


def _check_kappas(kappa: Any) -> np.ndarray:
    """Per-row concentrations: a float array, every entry finite and > 0."""
    out = np.asarray(kappa, dtype=np.float64)
    bad = ~(np.isfinite(out) & (out > 0.0))
    if bad.any():
        raise ValidationError("kappa", f"must be finite and > 0 in every row, got {out[bad][0]!r}")
    return out


def sample_vmf(u: np.ndarray, mu: np.ndarray, kappa: float | np.ndarray) -> np.ndarray:
    r"""Von Mises–Fisher direction about the unit ``mu`` with concentration κ (Loubet et al. 2019, Sec. 4.2).

    $\cos θ = 1 + \log(ξ + (1 - ξ) e^{-2κ}) / κ$ is evaluated as
    $s = 1 - \cos θ = -\mathrm{log1p}((1 - ξ) \mathrm{expm1}(-2κ)) / κ$ and $\sin θ = \sqrt{s (2 - s)}$,
    which keeps full relative precision of small angles: stable from κ → 0 to κ = 1e6 and beyond.
    ``kappa`` is one float, or one per row (shape ``u.shape[:-1]``, each > 0: a kernel per point).
    """
    u = np.asarray(u, dtype=np.float64)
    if np.ndim(kappa) == 0:
        kappa = _check_kappa(kappa)
        scale = math.expm1(-2.0 * kappa)
    else:
        kappa = _check_kappas(kappa)
        scale = np.expm1(-2.0 * kappa)
    with np.errstate(divide="ignore"):
        s = -np.log1p((1.0 - u[..., 0]) * scale) / kappa
    s = np.clip(s, 0.0, 2.0)
    sin_t = np.sqrt(s * (2.0 - s))
    phi = 2.0 * np.pi * u[..., 1]
    local = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), 1.0 - s], axis=-1)
    return _from_frame(local, mu)


def log_vmf(omega, mu, kappa: float):
    r"""log of the vMF density, $\log(κ / (2π (1 - e^{-2κ}))) + κ (μ·ω - 1)$; Dual-aware in ω and μ."""
    return math.log(kappa / (2.0 * np.pi * -math.expm1(-2.0 * kappa))) + kappa * (dot(omega, mu) - 1.0)


@functools.lru_cache(maxsize=16)
def _hemisphere_table(kappa: float, nodes: int = 512, grid: int = 2049) -> tuple[np.ndarray, np.ndarray]:
    z = np.linspace(-1.0, 1.0, grid)
    # quadrature in the vMF's radial CDF v (so the nodes follow the density for every κ):
    # s = 1 - cos(angle to the axis) = -log1p(v expm1(-2κ)) / κ
    x, w = np.polynomial.legendre.leggauss(nodes)
    v, w = 0.5 * (x + 1.0), 0.5 * w
    s = -np.log1p(v * math.expm1(-2.0 * kappa)) / kappa
    t = 1.0 - s
    sin_t = np.sqrt(np.maximum(s * (2.0 - s), 0.0))
    sin_z = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    # on the circle at angle t around the axis, n·ω = t z + sin_t sin_z cos φ > 0 for a fraction acos(a)/π
    with np.errstate(divide="ignore", invalid="ignore"):
        a = -t[None, :] * z[:, None] / (sin_t[None, :] * sin_z[:, None])
    a = np.where(np.isfinite(a), a, np.where(t[None, :] * z[:, None] >= 0.0, -1.0, 1.0))
    fraction = np.arccos(np.clip(a, -1.0, 1.0)) / np.pi
    return z, fraction @ w


def vmf_hemisphere_fraction(z, kappa: float):
    r"""$C(z) = P(n·ω > 0)$ for $ω \sim \mathrm{vMF}(y, κ)$ with $z = n·y$: the kernel's mass above a horizon.

    A convolution whose kernel centres are restricted to a hemisphere (an outer
    cosine sample) loses the mass $1 - C$ of the kernel near the horizon; dividing by
    $C(n·μ)$ restores $∫ k(μ, ω) dω = 1$ over the hemisphere (the authors tabulate the
    same correction). Tabulated per κ (Gauss–Legendre in the radial CDF, 2049 values
    of z) and interpolated linearly; ``z`` may be a Dual.
    """
    grid, table = _hemisphere_table(float(_check_kappa(kappa)))
    return np.interp(z, grid, table)


def pdf_vmf(omega: np.ndarray, mu: np.ndarray, kappa: float) -> np.ndarray:
    """vMF density $κ / (2π (1 - e^{-2κ})) e^{κ (μ·ω - 1)}$, without overflow for any κ."""
    kappa = _check_kappa(kappa)
    return np.exp(log_vmf(np.asarray(omega, dtype=np.float64), np.asarray(mu, dtype=np.float64), kappa))


# ------------------------------------------------------------------ triangles
def triangle_barycentrics(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""Barycentrics (b1, b2) of v1, v2 of the uniform triangle sample:
    $b1 = 1 - \sqrt{u_0}$, $b2 = u_1 \sqrt{u_0}$.
    """
    u = np.asarray(u, dtype=np.float64)
    root = np.sqrt(u[..., 0])
    return 1.0 - root, u[..., 1] * root


def sample_triangle(u: np.ndarray, v0: np.ndarray, v1: np.ndarray, v2: np.ndarray) -> np.ndarray:
    """Uniform point on the triangle (v0, v1, v2) (:func:`triangle_barycentrics` of ``u``)."""
    b1, b2 = triangle_barycentrics(u)
    corners = (np.asarray(v0), np.asarray(v1), np.asarray(v2))
    return _barycentric_point(b1, b2, lambda i, j: corners[i][..., j])


def _barycentric_point(b1: np.ndarray, b2: np.ndarray, corner: Callable[[int, int], Any]) -> np.ndarray:
    """$(1 - b_1 - b_2) v_0 + b_1 v_1 + b_2 v_2$ one coordinate at a time (``corner(i, j)``: coordinate j of
    corner i, broadcastable against the barycentrics), without broadcasting them over the short last axis."""
    b0 = 1.0 - b1 - b2
    points = np.empty((*np.broadcast_shapes(b0.shape, np.shape(corner(0, 0))), 3))
    for j in range(3):  # x, y, z
        points[..., j] = b0 * corner(0, j) + b1 * corner(1, j) + b2 * corner(2, j)
    return points


def triangle_area(v0: np.ndarray, v1: np.ndarray, v2: np.ndarray) -> np.ndarray:
    """Area of each triangle, $|(v1 - v0) × (v2 - v0)| / 2$."""
    return 0.5 * norm(cross(v1 - v0, v2 - v0))


def pdf_triangle(x: np.ndarray, v0: np.ndarray, v1: np.ndarray, v2: np.ndarray) -> np.ndarray:
    """$1 / area$ (per unit area, for points on the triangle)."""
    return np.broadcast_to(1.0 / triangle_area(v0, v1, v2), np.shape(x)[:-1]).copy()


def sample_mesh(u: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Uniform point on a triangle mesh (per unit area): a triangle ∝ its area, then a point on it.

    Parameters
    ----------
    u : ndarray, shape (..., 3)
        Uniforms: $u_0$ picks the triangle (inverse CDF of the areas), $(u_1, u_2)$ the point.
    triangles : ndarray, shape (T, 3, 3)
        Vertex positions.

    Returns
    -------
    points : ndarray, shape (..., 3)
    index : ndarray of int, shape (...)
        Which triangle each point lies on.
    """
    u = np.asarray(u, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.float64)
    areas = triangle_area(triangles[:, 0], triangles[:, 1], triangles[:, 2])
    cdf = np.cumsum(areas)
    index = np.minimum(np.searchsorted(cdf, u[..., 0] * cdf[-1], side="right"), len(areas) - 1)
    b1, b2 = triangle_barycentrics(u[..., 1:3])
    return _barycentric_point(b1, b2, lambda i, j: np.take(triangles[:, i, j], index)), index


@dataclass(frozen=True)
class EmitterDirections:
    """Points drawn on the emitters (:func:`sample_mesh`) as seen from shading points: the triangle of
    each (``index``, into the emitter triangles), the unit direction ``w`` and distance ``dist`` to it,
    the cosine ``cos_y`` at the emitter (its front faces w's origin where > 0) and ``cos_x`` at the point."""

    index: np.ndarray
    w: np.ndarray
    dist: np.ndarray
    cos_y: np.ndarray
    cos_x: np.ndarray


def emitter_directions(
    u: np.ndarray, emitters: np.ndarray, x: np.ndarray, n: np.ndarray
) -> EmitterDirections:
    """One point uniform on the emitter triangles ``emitters`` (T, 3, 3) per shading point ``x`` (m, 3)
    with normal ``n`` (uniforms ``u`` (m, 3)), and the geometry of the emitter sample from there: the
    first step of the emitter strategy of every shading integral (diffuse and glossy)."""
    y, index = sample_mesh(u, emitters)
    to = y - x
    dist = norm(to)
    w = to / np.where(dist > 0.0, dist, 1.0)[:, None]
    normals = normalize(
        cross(emitters[..., 1, :] - emitters[..., 0, :], emitters[..., 2, :] - emitters[..., 0, :])
    )
    return EmitterDirections(index, w, dist, -dot(normals[index], w), dot(n, w))


def pdf_mesh(x: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    r"""$1 / \text{total area}$ for points on the mesh."""
    triangles = np.asarray(triangles, dtype=np.float64)
    total = triangle_area(triangles[:, 0], triangles[:, 1], triangles[:, 2]).sum()
    return np.full(np.shape(x)[:-1], 1.0 / total)


def solid_angle_pdf(pdf_area, distance, cos_light):
    r"""Area density to solid-angle density seen from a point: $p_A d^2 / |\cos θ_y|$."""
    return pdf_area * distance * distance / np.abs(cos_light)


# ----------------------------------------------------------------------- film
def filter_radius(kind: str) -> float:
    """Half-width of the filter's support, in pixels."""
    kind = check_choice("filter", kind, FILTERS)
    return {"box": 0.5, "tent": 1.0, "gaussian": GAUSSIAN_RADIUS}[kind]


def _gauss_1d(x):
    return np.exp(-0.5 * (x / GAUSSIAN_SIGMA) ** 2)


_G_EDGE = math.exp(-0.5 * (GAUSSIAN_RADIUS / GAUSSIAN_SIGMA) ** 2)
_PHI_EDGE = float(special.ndtr(GAUSSIAN_RADIUS / GAUSSIAN_SIGMA))
# ∫_{-R}^{R} (g(x) - g(R)) dx and ∫_{-R}^{R} g(x) dx, the two 1D normalizations
_Z_FILTER = (
    GAUSSIAN_SIGMA * math.sqrt(2.0 * math.pi) * (2.0 * _PHI_EDGE - 1.0) - 2.0 * GAUSSIAN_RADIUS * _G_EDGE
)
_Z_TRUNC = GAUSSIAN_SIGMA * math.sqrt(2.0 * math.pi) * (2.0 * _PHI_EDGE - 1.0)


def _filter_1d(x, kind: str):
    """The normalized 1D filter profile $k_1$ ($k(x, y) = k_1(x) k_1(y)$); Dual-aware."""
    if kind == "box":
        return np.where(np.abs(x) <= 0.5, 1.0, 0.0) + 0.0 * x
    if kind == "tent":
        return np.maximum(1.0 - np.abs(x), 0.0)
    # shifted so it is continuous (zero) at the truncation radius
    return np.maximum(_gauss_1d(x) - _G_EDGE, 0.0) / _Z_FILTER


def filter_value(s, kind: str):
    """The pixel filter k(s) at offsets ``s`` (..., 2) from the pixel centre (integrates to 1).

    ``box``: 1 on $[-½, ½]^2$; ``tent``: $(1 - |x|)(1 - |y|)$ on $[-1, 1]^2$; ``gaussian``:
    the product of $(e^{-x^2/2σ^2} - e^{-R^2/2σ^2}) / Z$ with σ = ½, R = 3σ, continuous at R.
    Tent and gaussian are continuous, which the reparameterized pixel integral needs
    (theory/pixel_filters); a Dual ``s`` gives the filter's derivative.
    """
    return _filter_1d(s[..., 0], kind) * _filter_1d(s[..., 1], kind)


def filter_value_1d(x, kind: str):
    """The 1D profile $k_1$ of :func:`filter_value` ($k(x, y) = k_1(x) k_1(y)$) at ``x``; Dual-aware."""
    return _filter_1d(x, check_choice("filter", kind, FILTERS))


def log_filter_value_1d(x, kind: str):
    r"""$\log k_1(x)$, one axis's term of :func:`log_filter_value` (finite inside the support); Dual-aware."""
    kind = check_choice("filter", kind, FILTERS)
    if kind == "box":
        return 0.0 * x
    return np.log(1.0 - np.abs(x)) if kind == "tent" else np.log(_gauss_1d(x) - _G_EDGE)


def log_filter_value(s, kind: str):
    r"""$\log k(s)$ (finite inside the support); Dual-aware. Used for weights $k / \mathrm{detach}(k)$."""
    if kind == "box":
        return 0.0 * s[..., 0]
    if kind == "tent":
        return np.log(1.0 - np.abs(s[..., 0])) + np.log(1.0 - np.abs(s[..., 1]))
    return np.log(_gauss_1d(s[..., 0]) - _G_EDGE) + np.log(_gauss_1d(s[..., 1]) - _G_EDGE)


def _sample_filter_1d(u: np.ndarray, kind: str) -> np.ndarray:
    if kind == "box":
        return u - 0.5
    if kind == "tent":
        # density (3/4) √(1 - |x|) ∝ √k₁: k₁'/p stays bounded, so the reparameterized
        # filter weight has a finite variance (sampling ∝ k₁ would not)
        left = np.power(2.0 * np.minimum(u, 0.5), 2.0 / 3.0) - 1.0
        right = 1.0 - np.power(2.0 - 2.0 * np.maximum(u, 0.5), 2.0 / 3.0)
        return np.where(u < 0.5, left, right)
    # truncated normal on [-R, R] by the inverse CDF
    lo = 1.0 - _PHI_EDGE
    return GAUSSIAN_SIGMA * special.ndtri(lo + u * (_PHI_EDGE - lo))


def _pdf_filter_1d(x: np.ndarray, kind: str) -> np.ndarray:
    r = filter_radius(kind)
    inside = np.abs(x) <= r
    if kind == "box":
        return np.where(inside, 1.0, 0.0)
    if kind == "tent":
        return np.where(inside, 0.75 * np.sqrt(np.maximum(1.0 - np.abs(x), 0.0)), 0.0)
    return np.where(inside, _gauss_1d(x) / _Z_TRUNC, 0.0)


def sample_filter(u: np.ndarray, kind: str) -> np.ndarray:
    r"""Film offsets (..., 2) in pixels for the pixel filter ``kind``, by the inverse CDF per axis.

    ``box`` samples k exactly; ``tent`` samples $∝ \sqrt{k}$ (see :func:`_sample_filter_1d`);
    ``gaussian`` samples the truncated normal. The estimator weights each sample by
    $k / p$ (:func:`filter_value` / :func:`pdf_filter`).
    """
    kind = check_choice("filter", kind, FILTERS)
    u = np.asarray(u, dtype=np.float64)
    return np.stack([_sample_filter_1d(u[..., 0], kind), _sample_filter_1d(u[..., 1], kind)], axis=-1)


def pdf_filter_1d(x: np.ndarray, kind: str) -> np.ndarray:
    """One axis's factor of :func:`pdf_filter` at offsets ``x`` (per pixel)."""
    return _pdf_filter_1d(np.asarray(x, dtype=np.float64), check_choice("filter", kind, FILTERS))


def pdf_filter(s: np.ndarray, kind: str) -> np.ndarray:
    """Density (per pixel²) of :func:`sample_filter`."""
    kind = check_choice("filter", kind, FILTERS)
    s = np.asarray(s, dtype=np.float64)
    return _pdf_filter_1d(s[..., 0], kind) * _pdf_filter_1d(s[..., 1], kind)
