r"""Real spherical harmonics of degree <= 3 and the radial deformation of a mesh they define.

The shape coefficients ``NAME.shape.K`` (:mod:`sphere3d.scene`) deform a mesh along the
directions from its centre (the origin of its own coordinates): a vertex v moves to

    $F(v) = v\,(1 + g(\hat v))$,   $g(\hat v) = Σ_K θ_K Y_K(\hat v)$,   $\hat v = v / |v|$,

with $Y_K$ the real spherical harmonics of degree l and order m, $K = l^2 + l + m$ ($l \le 3$:
16 of them), scaled so that $Y_0 = 1$ and every $Y_K$ has mean square 1 over the sphere (the
orthonormal harmonics times $\sqrt{4π}$): $θ_K$ is a relative displacement (of the distance to the
centre), $θ_0$ a uniform scale. $F$ is linear in θ, so offsets add exactly, and a vertex at the
centre stays there. A normal n at v is carried by the inverse transpose of F's Jacobian
$J = (1 + g) I + v ∇g^T$; $∇g ⊥ v$ (g is homogeneous of degree 0), so by Sherman-Morrison

    $J^{-T} n ∝ n - ∇g\,(v·n) / (1 + g)$,   $∇g = (I - \hat v \hat v^T) ∇P(\hat v) / |v|$,

with P the harmonic as a homogeneous polynomial in the coordinates. The carried normal is not
renormalized: smooth shading interpolates the corner normals and normalizes their mix
(:meth:`sphere3d.state.SceneState.shading_normals`), and at θ = 0 the normal is n bit for bit.
For an icosphere (radial vertex normals) it is the normal of the deformed smooth surface
$r(\hat v)(1 + g(\hat v))$ at the vertex.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = ["DEGREE", "TERMS", "deform", "harmonic", "harmonic_gradient"]

DEGREE = 3
"""The highest degree of the shape coefficients."""
TERMS = (DEGREE + 1) ** 2
"""How many shape coefficients a mesh has (16)."""

_S3, _S15, _S105 = math.sqrt(3.0), math.sqrt(15.0), math.sqrt(105.0)
_A, _B = 0.5 * math.sqrt(17.5), 0.5 * math.sqrt(10.5)  # (1/2) sqrt(35/2), (1/2) sqrt(21/2)
_C = 0.5 * math.sqrt(7.0)
# Each Y_K as a homogeneous polynomial: (coefficient, (powers of x, y, z)) terms; on the unit
# sphere the standard real harmonics times sqrt(4 pi) (r^2 = 1 replaced by x^2 + y^2 + z^2).
_POLYNOMIALS: tuple[tuple[tuple[float, tuple[int, int, int]], ...], ...] = (
    ((1.0, (0, 0, 0)),),  # l = 0
    ((_S3, (0, 1, 0)),),  # l = 1, m = -1: y
    ((_S3, (0, 0, 1)),),  # m = 0: z
    ((_S3, (1, 0, 0)),),  # m = 1: x
    ((_S15, (1, 1, 0)),),  # l = 2, m = -2: xy
    ((_S15, (0, 1, 1)),),  # m = -1: yz
    ((math.sqrt(5.0), (0, 0, 2)), (-0.5 * math.sqrt(5.0), (2, 0, 0)), (-0.5 * math.sqrt(5.0), (0, 2, 0))),
    ((_S15, (1, 0, 1)),),  # m = 1: xz
    ((0.5 * _S15, (2, 0, 0)), (-0.5 * _S15, (0, 2, 0))),  # m = 2: x^2 - y^2
    ((3.0 * _A, (2, 1, 0)), (-_A, (0, 3, 0))),  # l = 3, m = -3: y (3x^2 - y^2)
    ((_S105, (1, 1, 1)),),  # m = -2: xyz
    ((4.0 * _B, (0, 1, 2)), (-_B, (2, 1, 0)), (-_B, (0, 3, 0))),  # m = -1: y (4z^2 - x^2 - y^2)
    ((2.0 * _C, (0, 0, 3)), (-3.0 * _C, (2, 0, 1)), (-3.0 * _C, (0, 2, 1))),  # m = 0: z (2z^2 - 3x^2 - 3y^2)
    ((4.0 * _B, (1, 0, 2)), (-_B, (3, 0, 0)), (-_B, (1, 2, 0))),  # m = 1: x (4z^2 - x^2 - y^2)
    ((0.5 * _S105, (2, 0, 1)), (-0.5 * _S105, (0, 2, 1))),  # m = 2: z (x^2 - y^2)
    ((_A, (3, 0, 0)), (-3.0 * _A, (1, 2, 0))),  # m = 3: x (x^2 - 3y^2)
)


def _monomial(u: np.ndarray, powers: tuple[int, int, int]) -> np.ndarray:
    return u[:, 0] ** powers[0] * u[:, 1] ** powers[1] * u[:, 2] ** powers[2]


def harmonic(index: int, directions: np.ndarray) -> np.ndarray:
    """$Y_K$ (K = ``index``) at unit ``directions`` (n, 3): shape (n,)."""
    u = np.asarray(directions, dtype=np.float64)
    return sum((c * _monomial(u, p) for c, p in _POLYNOMIALS[index]), np.zeros(len(u)))


def harmonic_gradient(index: int, points: np.ndarray) -> np.ndarray:
    r"""The gradient in space of $x \mapsto Y_K(x / |x|)$ at ``points`` (n, 3), none at the origin:
    $(I - \hat x \hat x^T) ∇P(\hat x) / |x|$ (0 at the origin). Shape (n, 3)."""
    x = np.asarray(points, dtype=np.float64)
    length = np.linalg.norm(x, axis=1)
    u = x / np.where(length > 0.0, length, 1.0)[:, None]
    grad = np.zeros_like(u)
    for c, p in _POLYNOMIALS[index]:
        for axis in range(3):
            if p[axis]:
                lower = tuple(q - (i == axis) for i, q in enumerate(p))
                grad[:, axis] += c * p[axis] * _monomial(u, lower)
    tangential = grad - u * np.sum(grad * u, axis=1)[:, None]
    return np.where(length[:, None] > 0.0, tangential / np.where(length > 0.0, length, 1.0)[:, None], 0.0)


def deform(vertices: np.ndarray, normals: np.ndarray, coefficients: Mapping[int, Any]) -> tuple[Any, Any]:
    r"""The vertices and vertex normals moved by the coefficients ``{K: θ_K}`` (floats or Duals): $F(v)$
    and the carried normals of the module docstring. Linear in θ in the vertices; no coefficient:
    the arrays themselves."""
    if not coefficients:
        return vertices, normals
    v = np.asarray(vertices, dtype=np.float64)
    length = np.linalg.norm(v, axis=1)
    u = v / np.where(length > 0.0, length, 1.0)[:, None]
    g: Any = 0.0
    grad: Any = 0.0
    for index in sorted(coefficients):  # a fixed order: the same sum for the same offsets
        theta = coefficients[index]
        g = g + theta * harmonic(index, u)
        grad = grad + theta * harmonic_gradient(index, v)
    moved = v + v * g[..., None]  # v (1 + g): linear in θ
    along = np.sum(np.asarray(normals) * v, axis=1)  # v · n
    carried = normals - grad * (along / (1.0 + g))[..., None]
    return moved, carried
