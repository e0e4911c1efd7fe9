r"""A moving corner beside a static edge on the film: one field that keeps every line in the kernel.

A film kernel (:mod:`sphere3d.reparam.film_kernel`) that holds a moving silhouette vertex V (a box's
corner, the fan of :mod:`sphere3d.reparam.film_corners`) and a static edge L (the ground's far edge
behind it) holds three or more discontinuity lines with different motions: the corner's edges, which
turn and move with V, and L, which stays. The corner's fan keeps its edges and drags L; the one
affine map keeping all of them exists, but the triangle the three lines cut scales with V's distance
h from L, and its $\dot B$ grows as 1 / h over the whole kernel (a variance growing as $1 / h^2$).

Here the film velocity is a moving least-squares field (Loubet et al. 2019, Sec. 4.3: a refinement
of the heuristic). At each film point u it is the v that minimises
$\sum_j w_j(u) (n_j · v - c_j(u))^2 + μ |v|^2$ with $w_j = 1 / d_j(u)^2$, over the lines j: the
corner's edges as rays from V along their images, and L as a line; $n_j$ is line j's unit normal,
$d_j(u)$ the distance from u to it, and $c_j(u) = n_j · (\dot q_j + s \dot e_j)$ the normal
velocity of the line's point $q_j + s e_j$ nearest u (s clamped to the ray). On line j its weight is
infinite, so $n_j · v = c_j$ there: every line stays on its moved line to first order, which is all
the derivative needs; where two lines meet (V, or an edge crossing L at X) both conditions hold and v
is the meeting point's velocity. The field is Lipschitz away from a meeting of three lines (its
residual on a line falls as $d_j^2$, its weight's gradient grows as $1 / d_j^3$, and the normal
equations' inverse takes $d_j^2$ back), so the change of variables it makes is valid and the
estimate unbiased. The strain $|\dot V| / h$ is confined to the triangle the lines cut and decays as
$|\dot V| / r$ away from it: $∫ |∇v|^2$ over the kernel grows as $\log(σ / h)$, not as
$σ^2 / h^2$. The prior $μ = 1 / r^2$, r the ring's radius, holds the film still (v = 0) where no
line is within about r: the only constant, the kernel's own scale.

The value and gradient at each sample's own film point are returned (the kernel's map about that
point, :class:`~sphere3d.film.AffineFilm`), computed as the mean of the pairs of conditions'
solutions weighted by their squared determinants (:func:`line_field`), which stays exact next to a
line, where the normal equations' matrix is singular to rounding.

Biased where the kernel holds a line not among these (a second static line, an edge of another
shape), as the other rules; the lines are straight to first order. The closed form
:func:`~sphere3d.closed_form.corner_junction_scene` checks it pixel by pixel
(tests/sphere3d/test_junctions.py).
"""

from __future__ import annotations

import numpy as np

from sphere3d.film import AffineFilm
from sphere3d.reparam.film_corners import NearCorners, corner_table
from sphere3d.reparam.film_lines import FilmLines, static_lines
from sphere3d.state import SceneState

__all__ = ["corner_line_maps", "line_field"]

EPSILON = 1e-9
"""Pixels added in quadrature to a sample's distance from a line in its weight: a sample exactly on a
line (probability zero) gets a finite weight."""


def corner_line_maps(
    state: SceneState, near: NearCorners, centre: np.ndarray, at: np.ndarray, reach: float
) -> tuple[np.ndarray, AffineFilm]:
    r"""The corner rows ``near`` (of kernel centres (n, 2), pixels) whose ring of radius ``reach`` also
    holds a static discontinuity edge, and their maps: the field of :func:`line_field` over the
    corner's edges and the nearest static line, its value and gradient at each sample's film point
    ``at`` (n, 2).

    Returns
    -------
    rows : ndarray of int
        Rows (of the n) with a map, ascending.
    maps : AffineFilm
        Their maps (every mask True), each about its sample's own point.
    """
    static = static_lines(state, centre[near.rows], reach)
    pick = static.rows  # rows of near.rows with a static line
    rows = near.rows[pick]
    k = state.k
    if not rows.size:
        return rows, AffineFilm.none(0, k)
    corners = corner_table(state)
    index = near.index[pick]
    count = corners.count[index]
    # one (row, line) pair per edge of the corner, then the static line of each row
    edge_row = np.repeat(np.arange(rows.size), count)
    half = np.repeat(corners.start[index] - np.cumsum(count) + count, count) + np.arange(edge_row.size)
    vertex, vertex_dot = corners.point[index[edge_row]], corners.a_dot[index[edge_row]]
    lines = FilmLines(
        np.concatenate([edge_row, np.arange(rows.size)]),
        np.concatenate([vertex, static.point]),
        np.concatenate([corners.edge[half], static.direction]),
        np.concatenate([vertex_dot, static.point_dot]),
        np.concatenate([corners.edge_dot[half], static.direction_dot]),
    )
    ray = np.concatenate([np.ones(edge_row.size, dtype=bool), np.zeros(rows.size, dtype=bool)])
    v, grad = line_field(at[rows], lines, ray, (1.0 / reach) ** 2)  # 0 for an absurd reach, not an overflow
    return rows, AffineFilm(np.ones(rows.size, dtype=bool), v, grad, at[rows].copy())


def line_field(
    at: np.ndarray,
    lines: FilmLines,
    ray: np.ndarray,
    mu: float,
    end: np.ndarray | None = None,
    gradient: str = "full",
) -> tuple[np.ndarray, np.ndarray | None]:
    r"""The moving least-squares velocity field keeping ``lines`` (module docstring), at points ``at``
    (m, 2): its value (m, 2) and gradient (m, 2, 2), ``[i, l]`` = $∂ v_i / ∂ u_l$ (for k parameters
    (m, k, 2) and (m, k, 2, 2)).

    ``lines.rows`` (P,) gives each line's point row; a line is $q + s e$ (``point``, ``direction``)
    moving at $\dot q + s \dot e$, a ray from q (s >= 0) where ``ray`` (P,), the segment s in [0, 1] where
    also ``end`` (P,), a whole line elsewhere; ``mu`` the prior's weight, $\mathrm{pixels}^{-2}$.
    ``gradient``: "full" (the gradient), "trace" ($\mathrm{tr}\, ∇v$ alone, (m,) or (m, k): a change of
    variables' Jacobian needs no more) or "none" (None: the value alone). Off a
    ray's or segment's ends the condition is the nearest end's normal velocity (bounded however short
    the segment, where a whole line's far points move with its turn times their distance).

    The weighted least-squares solution in two unknowns is the mean of the solutions of its pairs of
    conditions weighted by their squared determinants (Cauchy-Binet): two lines i, j give their
    meeting point's velocity $x_{ij}$ with weight $w_i w_j (n_i × n_j)^2$, a line and the prior the
    least-norm $c_j n_j$ with weight $μ w_j$, the prior alone 0 with weight $μ^2$. A mean of positive
    weights: no cancellation, however large the weight of a line the point lies next to (inverting
    $M$ loses every digit there). Its gradient is
    $∇v = \sum_π (∇W_π ⊗ (x_π - v) + W_π ∇x_π) / \sum_π W_π$.
    """
    m, k = len(at), lines.point_dot.ndim == 3
    # dense per point: slot j of row r holds its j-th line (a few per point: a corner's edges and L)
    order = np.argsort(lines.rows, kind="stable")
    row = lines.rows[order]
    slot = np.arange(row.size) - np.searchsorted(row, row)
    width = int(slot.max(initial=-1)) + 1
    valid = np.zeros((m, width), dtype=bool)
    valid[row, slot] = True

    def dense(a: np.ndarray) -> np.ndarray:
        out = np.zeros((m, width, *a.shape[1:]))
        out[row, slot] = a[order]
        return out

    q, e = dense(lines.point), dense(lines.direction)
    q_dot, e_dot = dense(lines.point_dot), dense(lines.direction_dot)
    is_ray = dense(ray.astype(float)) > 0.0
    is_segment = is_ray & (dense(end.astype(float)) > 0.0) if end is not None else np.zeros_like(is_ray)
    e = np.where(valid[..., None], e, 1.0)  # empty slots: any line, weight 0 below
    l2 = np.sum(e * e, axis=-1)
    n = np.stack([-e[..., 1], e[..., 0]], axis=-1) / np.sqrt(l2)[..., None]  # (m, J, 2)
    rel = at[:, None] - q
    s = np.sum(rel * e, axis=-1) / l2
    clamped = (is_ray & (s < 0.0)) | (is_segment & (s > 1.0))
    s = np.where(clamped, np.minimum(np.maximum(s, 0.0), 1.0), s)
    ds = np.where(clamped[..., None], 0.0, e / l2[..., None])  # ∇s: zero where the foot is an end
    off = rel - s[..., None] * e  # from the foot to the point
    soft = np.sum(off * off, axis=-1) + EPSILON**2
    w = np.where(valid, 1.0 / soft, 0.0)
    grad_w = np.where(valid[..., None], -2.0 * off / soft[..., None] ** 2, 0.0)  # -2 d ∇d / (d² + ε²)²
    # the normal velocity of the foot point, c = n · (q_dot + s e_dot), and ∇c = (n · e_dot) ∇s
    kx = (lambda a: a[:, :, None]) if k else (lambda a: a)  # a (m, J, ...) array before the k axis
    c = np.sum((q_dot + kx(s[..., None]) * e_dot) * kx(n), axis=-1)  # (m, J) or (m, J, k)
    grad_c = np.sum(e_dot * kx(n), axis=-1)[..., None] * kx(ds)  # (m, J, [k,] 2)
    # every pair of lines (l, o), each unordered pair twice: weight W = w_l w_o sine², sine = n_l × n_o
    p = np.stack([n[..., 1], -n[..., 0]], axis=-1)
    sine = n[:, :, None, 0] * n[:, None, :, 1] - n[:, :, None, 1] * n[:, None, :, 0]  # (m, J, J)
    big = w[:, :, None] * w[:, None, :] * sine**2  # 0 on the diagonal
    total = 0.5 * np.sum(big, axis=(1, 2)) + mu * np.sum(w, axis=1) + mu * mu  # (m,)
    # no weight at all (no prior, parallel lines only): the identity (v = 0), not 0 / 0
    total = np.where(total > 0.0, total, np.inf)
    # the pair's meeting velocity x = (c_l p_o - c_o p_l) / sine_lo is linear in the c's: its coefficient of
    # c_l is b_lo = p_o / sine_lo (the prior's one-line term: c_l n_l). So v = Σ_l c_l a_l with
    # a_l = (Σ_o W_lo b_lo + μ w_l n_l) / ΣW, geometric: the k parameters enter through c and ∇c only
    # (O(J k) per point; the pairs O(J²) once)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(big > 0.0, 1.0 / sine, 0.0)
    b = p[:, None, :, :] * inv[..., None]  # (m, J, J, 2): b_lo
    a = (np.sum(big[..., None] * b, axis=2) + mu * w[..., None] * n) / total[:, None, None]
    v = np.einsum("ml,mlx->mx", c, a) if not k else np.einsum("mlk,mlx->mkx", c, a)
    if gradient == "none":
        return v, None
    grad_big = (w[:, :, None, None] * grad_w[:, None, :] + w[:, None, :, None] * grad_w[:, :, None]) * sine[
        ..., None
    ] ** 2
    # ∇v = Σ_π (∇W_π ⊗ (x_π - v) + W_π ∇x_π) / ΣW = Σ_l (c_l G_l + a_l ⊗ ∇c_l), with
    # G_l = (Σ_o b_lo ⊗ ∇W_lo + μ n_l ⊗ ∇w_l - a_l ⊗ Σ_π ∇W_π) / ΣW   (the prior's own ∇(μ²) = 0)
    flux = 0.5 * np.sum(grad_big, axis=(1, 2)) + mu * np.sum(grad_w, axis=1)  # (m, 2): Σ_π ∇W_π
    if gradient == "trace":  # tr ∇v alone: the 2 x 2 blocks never formed
        inner = np.einsum("mlox,mlox->ml", b, grad_big) + mu * np.sum(n * grad_w, axis=-1)
        tr_g = (inner - np.einsum("mlx,mx->ml", a, flux)) / total[:, None]
        if not k:
            return v, np.einsum("ml,ml->m", c, tr_g) + np.einsum("mlx,mlx->m", a, grad_c)
        return v, np.einsum("mlk,ml->mk", c, tr_g) + np.einsum("mlx,mlkx->mk", a, grad_c)
    outer = np.einsum("mlox,mloy->mlxy", b, grad_big) + mu * n[..., :, None] * grad_w[..., None, :]
    g = (outer - a[..., :, None] * flux[:, None, None, :]) / total[:, None, None, None]
    if not k:
        return v, np.einsum("ml,mlxy->mxy", c, g) + np.einsum("mlx,mly->mxy", a, grad_c)
    return v, np.einsum("mlk,mlxy->mkxy", c, g) + np.einsum("mlx,mlky->mkxy", a, grad_c)
