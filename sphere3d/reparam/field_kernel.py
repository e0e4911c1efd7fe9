r"""The moving least-squares field of :func:`~sphere3d.reparam.corner_lines.line_field`, point by point.

The chart fields (:class:`~sphere3d.reparam.chart_field.ChartField`) evaluate the field at every sample of
a penumbra with a few lines each (mostly three: a found edge and its neighbours): numpy's whole-array
form builds some forty (points, lines, lines) temporaries for it, and its time was most of the emitter
strategy's. Here the same sums run per point over its own lines in one compiled loop
(:func:`sphere3d.jit.compiled`): the value $v = \sum_l c_l a_l$ and the trace of its gradient
$\mathrm{tr}\, ∇v = \sum_l (c_l\, \mathrm{tr}\, G_l + a_l · ∇c_l)$, with, for the pairs (l, o) of lines,
$W_{lo} = w_l w_o \sin^2$, $b_{lo} = p_o / \sin_{lo}$, $a_l = (\sum_o W_{lo} b_{lo} + μ w_l n_l) / ΣW$ and
$\mathrm{tr}\, G_l = (\sum_o b_{lo} · ∇W_{lo} + μ\, n_l · ∇w_l - a_l · \sum_π ∇W_π) / ΣW$ (the derivation is
:func:`~sphere3d.reparam.corner_lines.line_field`'s, which computes the whole gradient; the two agree to
rounding, tests/sphere3d/test_corner_lines.py).
"""

from __future__ import annotations

import math

import numpy as np

from sphere3d.jit import compiled
from sphere3d.reparam.film_lines import FilmLines

__all__ = ["field_points", "field_trace"]


def field_points(
    u: np.ndarray,
    start: np.ndarray,
    q: np.ndarray,
    e: np.ndarray,
    q_dot: np.ndarray,
    e_dot: np.ndarray,
    ray: np.ndarray,
    end: np.ndarray,
    mu: float,
    eps2: float,
    trace_too: bool,
    v: np.ndarray,
    trace: np.ndarray,
) -> None:
    """Per point r of ``u`` (m, 2), its lines ``start[r]:start[r + 1]`` (points ``q``, directions ``e``
    (P, 2); velocities (P, K, 2); ``ray`` / ``end`` flags (P,)): the field ``v[r]`` (K, 2) and, with
    ``trace_too``, ``trace[r]`` (K,). Plain Python over scalars (compiled by :func:`field_trace`)."""
    m, kk = u.shape[0], q_dot.shape[1]
    for r in range(m):
        lo, hi = start[r], start[r + 1]
        count = hi - lo
        nx, ny, w = np.empty(count), np.empty(count), np.empty(count)
        gwx, gwy = np.empty(count), np.empty(count)
        c, gcx, gcy = np.empty((count, kk)), np.empty((count, kk)), np.empty((count, kk))
        total, fx, fy = 0.0, 0.0, 0.0
        for a in range(count):  # each line: its normal, foot, weight and normal velocity there
            line = lo + a
            ex, ey = e[line, 0], e[line, 1]
            l2 = ex * ex + ey * ey
            length = math.sqrt(l2)
            nx[a], ny[a] = -ey / length, ex / length
            rx, ry = u[r, 0] - q[line, 0], u[r, 1] - q[line, 1]
            s = (rx * ex + ry * ey) / l2
            dsx, dsy = ex / l2, ey / l2
            if ray[line] and (s < 0.0 or (end[line] and s > 1.0)):  # the foot at an end: ∇s = 0
                s = 0.0 if s < 0.0 else 1.0
                dsx, dsy = 0.0, 0.0
            ox, oy = rx - s * ex, ry - s * ey
            soft = ox * ox + oy * oy + eps2
            w[a] = 1.0 / soft
            gwx[a], gwy[a] = -2.0 * ox / (soft * soft), -2.0 * oy / (soft * soft)
            for j in range(kk):
                c[a, j] = nx[a] * (q_dot[line, j, 0] + s * e_dot[line, j, 0]) + ny[a] * (
                    q_dot[line, j, 1] + s * e_dot[line, j, 1]
                )
                rate = nx[a] * e_dot[line, j, 0] + ny[a] * e_dot[line, j, 1]
                gcx[a, j], gcy[a, j] = rate * dsx, rate * dsy
        ax, ay, inner = np.zeros(count), np.zeros(count), np.zeros(count)
        for a in range(count):  # each pair once: its weight, and its meeting velocity's coefficients
            for o in range(a + 1, count):
                sine = nx[a] * ny[o] - ny[a] * nx[o]
                big = w[a] * w[o] * sine * sine
                if big <= 0.0:
                    continue
                total += big
                gx = (w[a] * gwx[o] + w[o] * gwx[a]) * sine * sine
                gy = (w[a] * gwy[o] + w[o] * gwy[a]) * sine * sine
                fx += gx
                fy += gy
                # b_ao = p_o / sine, b_oa = -p_a / sine, p = (n_y, -n_x)
                bx, by = ny[o] / sine, -nx[o] / sine
                cx, cy = -ny[a] / sine, nx[a] / sine
                ax[a] += big * bx
                ay[a] += big * by
                ax[o] += big * cx
                ay[o] += big * cy
                inner[a] += bx * gx + by * gy
                inner[o] += cx * gx + cy * gy
        for a in range(count):  # each line with the prior: c_l n_l, weight μ w_l
            total += mu * w[a]
            ax[a] += mu * w[a] * nx[a]
            ay[a] += mu * w[a] * ny[a]
            inner[a] += mu * (nx[a] * gwx[a] + ny[a] * gwy[a])
            fx += mu * gwx[a]
            fy += mu * gwy[a]
        total += mu * mu
        for j in range(kk):
            v[r, j, 0], v[r, j, 1], trace[r, j] = 0.0, 0.0, 0.0
        if not total > 0.0:  # no weight at all: the identity
            continue
        for a in range(count):
            ax[a] /= total
            ay[a] /= total
            tr_g = (inner[a] - (ax[a] * fx + ay[a] * fy)) / total
            for j in range(kk):
                v[r, j, 0] += c[a, j] * ax[a]
                v[r, j, 1] += c[a, j] * ay[a]
                if trace_too:
                    trace[r, j] += c[a, j] * tr_g + ax[a] * gcx[a, j] + ay[a] * gcy[a, j]


def field_trace(
    at: np.ndarray, lines: FilmLines, ray: np.ndarray, mu: float, end: np.ndarray, trace_too: bool, eps: float
) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`~sphere3d.reparam.corner_lines.line_field` with ``gradient`` "trace" (``trace_too``) or "none",
    by the compiled :func:`field_points`: the value (m, 2) or (m, k, 2), and tr ∇v (m,) or (m, k), or None."""
    m, k = len(at), lines.point_dot.ndim == 3
    order = np.argsort(lines.rows, kind="stable")
    start = np.searchsorted(lines.rows[order], np.arange(m + 1))
    q_dot = lines.point_dot[order] if k else lines.point_dot[order][:, None]
    e_dot = lines.direction_dot[order] if k else lines.direction_dot[order][:, None]
    slots = q_dot.shape[1]
    v, trace = np.empty((m, slots, 2)), np.empty((m, slots))
    compiled(field_points)(
        np.ascontiguousarray(at, dtype=np.float64),
        start,
        np.ascontiguousarray(lines.point[order]),
        np.ascontiguousarray(lines.direction[order]),
        np.ascontiguousarray(q_dot),
        np.ascontiguousarray(e_dot),
        np.ascontiguousarray(ray[order]),
        np.ascontiguousarray(end[order]),
        float(mu),
        eps * eps,
        trace_too,
        v,
        trace,
    )
    if not k:
        v, trace = v[:, 0], trace[:, 0]
    return v, trace if trace_too else None
