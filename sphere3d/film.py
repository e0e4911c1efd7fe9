r"""Film splatting: every camera sample contributes to every pixel whose filter covers it.

The default film of :class:`~sphere3d.tasks.ImageTask`, :func:`~sphere3d.render.render` and
:func:`~sphere3d.render.render_gradient` (``film="splat"``); ``film="pixel"`` keeps each sample in the
pixel that drew it.
The film transform of a camera sample (:class:`FilmTransform`: its rotations and film kernels,
what a method's ``camera`` returns) is defined here too.

Pixel p' draws its samples s from its own filter sampler, density $p(s - p')$
(:func:`~sphere3d.sampling.pdf_filter`; the gaussian filter's is the truncated normal, not
k itself). Pooled over the image's pixels the samples have density
$q(s) = Σ_{p'} p(s - p')$ (only pixels of the image), and a sample at s contributes
$k(s - p) / q(s) · L(s)$ to every pixel p with $k(s - p) > 0$: multi-sample MIS over the
pixel samplers with the balance heuristic (Veach 1997; Loubet et al. 2019, Sec. 4.2 for the
kernel weights below). Unbiased: with N samples per pixel and the mean taken over N,
$E = Σ_{p'} ∫ p(s - p') k(s - p) L(s) / q(s) ds = ∫ k(s - p) L(s) ds$. The filter's
weight derivative (the dominant noise of ``reparam`` on ``hard_shadow``,
:mod:`sphere3d.reparam.film_kernel`) is shared among up to nine samplers' samples instead
of one pixel's.

Under a camera rotation (:func:`~sphere3d.integrator.pixel_samples`, the film kernel of
:mod:`sphere3d.reparam.film_kernel`): sample s, kernel centre $c \sim g(· - s)$, rotation $R_c$
(a function of c and the sample's own streams only, not of any pixel). For pixel p the
weight is $k(\mathrm{film}(Rω) - p) J(Rω) g(\mathrm{film}(Rω) - c) / \mathrm{detach}(q(s) J g)$,
value $k(s - p) / q(s)$: the per-pixel weight with the pixel centre replaced by p and the
density p by q. The reverse-order argument of :mod:`sphere3d.reparam.film_kernel` holds with q in
place of p: the pair (s, c) has the θ-free joint density $q(s) g(c - s)$ pooled over the
samplers, and for a fixed c, $T_c$ the film map of $R_c$, the expectation of the estimate
$|T_c'| g(T_c s - c) k(T_c s - p) L(T_c s) / (q(s) g(c - s))$ summed over the samplers is
$∫ dc ∫ g(u - c) k(u - p) L(u) du = ∫ k(u - p) L(u) du$ for every θ ($u = T_c s$).

Control variate: with L = 1 the same sum is 1 for every θ, so the weights' tangents
$\dot w_{i,p}$ summed over *all* the samplers' samples (any set holding equally many samples
of every pixel, e.g. one batch) have zero mean for each pixel p; one sample's alone does not
(the ratio $p(s - p') / q(s)$ is not carried by the rotation). A scale $c_{p,-i}$ independent
of sample i with the same expectation for every i keeps $E[Σ_i c_{p,-i} \dot w_{i,p}] = 0$:
the mean radiance of pixel p's own samples, leaving sample i out when it is one of them
(any subset of pixel p's i.i.d. samples has the same mean). The value gets the same
control variate, $c_{p,-i} (w_{i,p} - [i ∈ p])$: $E Σ_i w_{i,p} = N$, so a constant radiance
is estimated exactly, where the raw splat's value is noisier than one pixel's own samples
(the number of neighbours' samples landing near p varies). The derivative gets that control
variate's tangent, $c_{p,-i} \dot w_{i,p} + \dot c_{p,-i} (w_{i,p} - [i ∈ p])$ (zero mean alike):
the derivative of the value's estimate, so a radiance linear in θ gives value / θ exactly, and
the splatted $\dot L$ loses the weights' noise as the value does. See
:meth:`~sphere3d.tasks.ImageTask._splat_chunk`.

What it costs and gains (RMSE, value and derivative noise against the per-pixel film): the
``hard_shadow`` measurement page, whose ``reparam (pixel film)`` rows are the per-pixel film. The
batches' standard errors understate the spread slightly: the pooled scale of the control
variate couples the batches weakly (:meth:`~sphere3d.tasks.ImageTask._control_variate`).

Independence of chunks and threads: each chunk holds whole pixels and sums, per source
pixel p', batch and target offset p - p', over the source's own samples (:func:`stencil`);
the image sums these stencils in a fixed order (:func:`gather`, in bands of rows on the threads),
whatever the chunking, tile by tile of rows (:meth:`~sphere3d.tasks.ImageTask._splat_tiles`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core.dual import Dual, detach, tangent
from sphere3d.rotation import Rotation
from sphere3d.sampling import filter_radius, filter_value_1d, log_filter_value_1d, pdf_filter_1d

__all__ = [
    "FILMS",
    "AffineFilm",
    "FilmTransform",
    "Splat",
    "affine_directions",
    "gather",
    "reach",
    "splat_band",
    "splat_stencils",
    "splat_weights",
    "stencil",
]

FILMS = ("splat", "pixel")
"""Image options, the default first: each sample splatted into every pixel its filter covers, or
counted in its own pixel only."""


@dataclass(frozen=True)
class AffineFilm:
    r"""Per camera sample (film kernel member): whether an affine film map applies (``mask``), and its
    derivative, $\dot A(u) = \dot a + \dot B (u - \bar p)$: ``a_dot`` (n, 2), ``b_dot`` (n, 2, 2),
    ``centre`` (n, 2) (pixels). For k parameters ``a_dot`` is (n, k, 2) and ``b_dot`` (n, k, 2, 2): each
    sample's map moves in k directions (the parameters' axis after the samples', so rows index alike)."""

    mask: np.ndarray
    a_dot: np.ndarray
    b_dot: np.ndarray
    centre: np.ndarray

    @staticmethod
    def none(n: int, k: int | None = None) -> AffineFilm:
        """No sample has a map (for ``k`` parameters: k zero derivatives per sample)."""
        slots = () if k is None else (k,)
        return AffineFilm(
            np.zeros(n, bool), np.zeros((n, *slots, 2)), np.zeros((n, *slots, 2, 2)), np.zeros((n, 2))
        )

    def take(self, index: Any) -> AffineFilm:
        """The samples at ``index``."""
        return AffineFilm(self.mask[index], self.a_dot[index], self.b_dot[index], self.centre[index])


def affine_directions(cam: Any, omega: np.ndarray, affine: AffineFilm) -> tuple[Dual, np.ndarray]:
    r"""Directions ``omega`` (plain, (n, 3)) moving with the affine film map (Dual), and tr B'.

    The film point $u = \mathrm{film}(ω)$ moves at $\dot A(u) = \dot a + \dot B (u - \bar p)$; the
    unnormalized direction $d = f + s_x r + s_y u_c$ ($s_x = (2x/w - 1) t$, $s_y = (1 - 2y/h) t h/w$,
    $t = \tan(fov/2)$, $u_c$ the camera's up) then moves at $\dot d = (2t/w)(\dot x r - \dot y u_c)$,
    and the unit direction $ω = d / |d|$, with $|d| = 1 / (ω·f)$, at
    $\dot ω = (ω·f)(\dot d - ω (ω·\dot d))$. Rows without a map get a zero tangent.
    """
    x, y = cam.film(omega)
    u = np.stack([x, y], axis=-1) - affine.centre
    scale = 2.0 * cam.tan_half / cam.width
    right, up, forward = (np.asarray(v, dtype=np.float64) for v in (cam.right, cam.up, cam.forward))
    cos = omega @ forward

    def moved(a_dot: np.ndarray, b_dot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # one parameter's
        velocity = a_dot + np.einsum("nij,nj->ni", b_dot, u)
        velocity = np.where(affine.mask[:, None], velocity, 0.0)
        d_dot = scale * (velocity[:, :1] * right - velocity[:, 1:] * up)
        omega_dot = cos[:, None] * (d_dot - omega * np.sum(omega * d_dot, axis=1)[:, None])
        return omega_dot, np.where(affine.mask, b_dot[:, 0, 0] + b_dot[:, 1, 1], 0.0)

    if affine.a_dot.ndim == 2:
        omega_dot, trace = moved(affine.a_dot, affine.b_dot)
        return Dual(np.array(omega, dtype=np.float64), omega_dot), trace
    k = affine.a_dot.shape[1]  # k parameters: each one's map as a single parameter's
    slots = [moved(affine.a_dot[:, i], affine.b_dot[:, i]) for i in range(k)]
    omega_dot, trace = (np.stack(parts) for parts in zip(*slots, strict=True))
    return Dual(np.array(omega, dtype=np.float64), omega_dot, k), trace


@dataclass(frozen=True)
class FilmTransform:
    """Per camera sample: one or two rotations of its direction, each optionally with a film kernel.

    The sample's estimate is the mean of its estimates under the ``rotations`` (one, or
    two: an antithetic pair); ``centres`` (one (n, 2) array per rotation, pixels) are the
    centres c of Gaussian film kernels of concentration ``kappa`` (1 / variance, pixels⁻²),
    none for no kernel (log weight 0).
    """

    rotations: tuple[Rotation, ...]
    centres: tuple[np.ndarray, ...] = ()
    kappa: float = 0.0
    affine: tuple[AffineFilm, ...] = ()
    """Per member, the samples whose film map is an affine map instead of the rotation
    (:mod:`sphere3d.reparam.film_affine`; none if empty)."""

    def active(self, member: int) -> np.ndarray:
        """Where the member's map moves anything (its rotation, or an affine map)."""
        rotation = self.rotations[member].active
        return rotation | self.affine[member].mask if self.affine else rotation

    def directions(self, member: int, cam: Any, omega: np.ndarray, rows: np.ndarray) -> tuple[Any, Any]:
        r"""The member's map applied to the plain directions ``omega`` of samples ``rows`` (Dual, value
        ``omega``), and where an affine map applies, $\mathrm{tr}\,\dot B$ (None: no such row)."""
        r = self.rotations[member].take(rows).apply(omega)
        if not self.affine:
            return r, None
        affine = self.affine[member].take(rows)
        if not affine.mask.any():
            return r, None
        moved, trace = affine_directions(cam, omega, affine)
        t = np.where(affine.mask[:, None], moved.tangent, r.tangent)
        return Dual(r.value, t, r.k), (affine.mask, trace)

    def log_jacobian(self, cam: Any, r: Any, affine: Any) -> Any:
        r"""log of the film map's Jacobian at the moved directions ``r``: the rotation's ratio of film
        Jacobians $\log J(Rω)$ (up to a constant), or $\log |\det A|$ where ``affine`` = (mask,
        trace) marks an affine map (derivative $\mathrm{tr}\,\dot B$; :mod:`sphere3d.reparam.film_affine`)."""
        log_j = cam.log_jacobian(r)
        if affine is None:
            return log_j
        mask, trace = affine
        return Dual(log_j.value, np.where(mask, trace, log_j.tangent), log_j.k)

    @staticmethod
    def identity(shape: tuple[int, ...], k: int | None = None) -> FilmTransform:
        """No change of variables (with ``k`` zero tangents for k parameters)."""
        return FilmTransform((Rotation.identity(shape, k),))

    def log_kernel(self, member: int, fx: Any, fy: Any, rows: Any = slice(None)) -> Any:
        """log g(f - c) + const at the rotated film points f = (fx, fy) of samples ``rows``
        (Loubet et al. 2019, Sec. 4.2)."""
        if not self.centres:
            return 0.0
        c = self.centres[member][rows]
        dx, dy = fx - c[:, 0], fy - c[:, 1]
        return -0.5 * self.kappa * (dx * dx + dy * dy)  # log of exp(-κ |f - c|² / 2)


def reach(kind: str) -> tuple[int, int]:
    r"""(j, h): a film point s reaches the pixels ``floor(s) + [-j, j]`` per axis; a sample of
    pixel p' reaches the pixels ``p' + [-h, h]``.

    $|s - i - ½| < r$ with $\mathrm{frac}(s) - ½ ∈ [-½, ½)$ gives $|i - \lfloor s \rfloor| < r + ½$;
    a sample lies within r of its pixel's centre, so $\lfloor s \rfloor - p' ∈ [-h + j, h - j]$.
    Gaussian (r = 1.5) and tent (r = 1): (1, 2); box (r = ½): (0, 0).
    """
    j = math.ceil(filter_radius(kind) - 0.5)
    return j, 2 * j  # h = j + j: the sample's offset from its pixel plus the film point's reach


@dataclass(frozen=True)
class Splat:
    """Per camera sample (n) and reached pixel (m = (2j + 1)², row-major over the offsets of :func:`reach`).

    ``slot`` (n, m): the pixel's stencil slot, $(Δr + h)(2h + 1) + Δc + h$ for its offset (Δr, Δc)
    from the sample's own pixel (-1: none); ``weight`` (n, m): $k(s - p) / q(s)$; ``cx`` and
    ``cy`` (n, 2j + 1): the centres of the reached columns and rows, ``on_x`` and ``on_y``
    whether any reached pixel lies in them.
    """

    slot: np.ndarray
    weight: np.ndarray
    cx: np.ndarray
    cy: np.ndarray
    on_x: np.ndarray
    on_y: np.ndarray

    def weight_tangents(self, fx: Any, fy: Any, log_rest: Any, rows: np.ndarray, kind: str) -> np.ndarray:
        r"""Tangents of $k(f - p) · \mathrm{rest} / \mathrm{detach}(…)$ (value 1) per reached pixel p at the
        rotated film points (fx, fy) of samples ``rows``: plain (len(rows), m).

        The filter is a product, $\log k(f - p) = \log k_1(f_x - p_x) + \log k_1(f_y - p_y)$, so the
        tangent is the column's term plus the row's plus ``log_rest``'s: each axis's term is taken
        once per column and row (2j + 1 each, the other axis held at offset 0 with tangent 0, which
        adds an exact 0), not once per pixel. Columns and rows with no reached pixel are evaluated
        at offset 0 (finite); their pixels' weight value 0 cancels them.
        """
        k = self.cx.shape[1]
        axes = []
        for f, c, on in ((fx, self.cx, self.on_x), (fy, self.cy, self.on_y)):
            d = (f[:, None] - c[rows]) * on[rows].astype(np.float64)
            axes.append(tangent(log_filter_value_1d(d, kind)))  # (rows, k): this axis's term alone
        tx, ty = axes  # (rows, k), or (parameters, rows, k)
        rest = tangent(log_rest)
        total = tx[..., None, :] + ty[..., :, None]  # pixel (a, b): row a, column b
        return (total + (rest[..., None, None] if np.ndim(rest) else rest)).reshape(*tx.shape[:-1], k * k)


def splat_weights(
    x: np.ndarray, y: np.ndarray, rows: np.ndarray, cols: np.ndarray, width: int, height: int, kind: str
) -> Splat:
    r"""The pixels film points (x, y) of samples of pixels (``rows``, ``cols``) reach and the weights
    $k(s - p) / q(s)$, $q(s) = Σ_{p'} p(s - p')$ over the image's pixels (module docstring)."""
    j, h = reach(kind)
    n, k, span = len(x), 2 * j + 1, np.arange(-j, j + 1)
    ib, ia = np.tile(np.arange(k), k), np.repeat(np.arange(k), k)  # pixel (a, b): row a, column b
    col = np.floor(x).astype(np.int64)[:, None] + span  # (n, k) each
    row = np.floor(y).astype(np.int64)[:, None] + span
    cx, cy = col + 0.5, row + 0.5
    # k and p are products over the axes: each axis's factor once per column and row (zero outside the
    # image), then per pixel, x factor times y factor (np.take: C-ordered, as np.sum's rounding below
    # depends on the layout; faster than broadcasting over k = 3)
    dx, dy = x[:, None] - cx, y[:, None] - cy
    in_x, in_y = (col >= 0) & (col < width), (row >= 0) & (row < height)
    px, py = (np.where(inside, pdf_filter_1d(d, kind), 0.0) for inside, d in ((in_x, dx), (in_y, dy)))
    vx, vy = (np.where(inside, filter_value_1d(d, kind), 0.0) for inside, d in ((in_x, dx), (in_y, dy)))
    density = np.take(px, ib, axis=1) * np.take(py, ia, axis=1)
    q = np.sum(density, axis=1)  # > 0: the sample's own pixel is among them, with p > 0 at s
    value = np.take(vx, ib, axis=1) * np.take(vy, ia, axis=1)
    weight = value / np.where(q > 0.0, q, 1.0)[:, None]
    side = 2 * h + 1
    d_row, d_col = row - rows[:, None], col - cols[:, None]  # offsets from the sample's own pixel
    slot_row = np.where(np.abs(d_row) <= h, (d_row + h) * side, -side * side).astype(np.int16)
    slot_col = np.where(np.abs(d_col) <= h, d_col + h, -side * side).astype(np.int16)
    reached = weight > 0.0
    slot = np.take(slot_row, ia, axis=1) + np.take(slot_col, ib, axis=1)
    slot = np.where(reached & (slot >= 0), slot, np.int16(-1))
    grid = reached.reshape(n, k, k)
    on_x, on_y = grid[:, 0].copy(), grid[:, :, 0].copy()  # a reached pixel in the column, the row
    for a in range(1, k):  # k <= 3 (np.any over an axis this short is slower)
        on_x |= grid[:, a]
        on_y |= grid[:, :, a]
    return Splat(slot, weight, cx, cy, on_x, on_y)


def stencil(values: tuple[np.ndarray, ...], slot: np.ndarray, h: int, out: np.ndarray) -> None:
    """Per quantity, group, target offset and source pixel, the sum over the source's samples of each of
    ``values`` (groups, pixels, samples, m), written to ``out`` (len(values), groups, (2h + 1)², pixels).

    ``slot`` (same shape): the target's slot (:class:`Splat`; -1: none). ``np.bincount`` adds each
    bin's entries one by one in their order, a source pixel's samples in sample order, so every
    sum is the same whatever chunk holds the pixel.
    """
    g, p = slot.shape[:2]
    slots = (2 * h + 1) ** 2
    # bins pixel-major, (group, pixel, slot): a pixel's entries hit neighbouring bins (slot-major bins
    # a pixel count apart would alias in the cache); ``out`` is slot-major, for gather. Each pixel has
    # one more bin, first, for its entries reaching no slot (-1), dropped
    base = (np.arange(g * p) * (slots + 1) + 1).reshape(g, p, 1, 1)
    key = np.add(base, slot).ravel()
    for i, v in enumerate(values):
        sums = np.bincount(key, weights=v.ravel(), minlength=g * p * (slots + 1))
        out[i] = sums.reshape(g, p, slots + 1)[:, :, 1:].transpose(0, 2, 1)


def gather(parts: np.ndarray, height: int, width: int, h: int, rows: range, first: int = 0) -> np.ndarray:
    """Image rows ``rows`` (..., len(rows), width) from stencils (..., (2h + 1)², n * width) of the source
    rows ``first`` to ``first + n`` (every source row of ``rows`` inside the image: from
    ``max(0, rows.start - h)`` to ``min(height, rows.stop + h)``), each pixel the sum of its sources'
    slots in a fixed order (offsets row-major), whatever ``first`` and ``rows``."""
    side = 2 * h + 1
    st = parts.reshape(*parts.shape[:-2], side * side, -1, width)
    r0, r1 = rows.start, rows.stop
    image = np.zeros((*parts.shape[:-2], r1 - r0, width))
    for a in range(side):  # 25 slots at most: a loop over offsets, not samples
        for b in range(side):
            da, db = a - h, b - h  # target = source + (da, db)
            t0, t1, u0, u1 = max(r0, da), min(r1, height + da), max(0, db), min(width, width + db)
            if t0 < t1 and u0 < u1:
                s0, s1 = t0 - da - first, t1 - da - first  # the source rows, from the first one held
                image[..., t0 - r0 : t1 - r0, u0:u1] += st[..., a * side + b, s0:s1, u0 - db : u1 - db]
    return image


def _slots(x: Any, k: int | None) -> list[np.ndarray]:
    """The tangents of ``x`` as a list: one array, or the k slots of k tangents."""
    t = np.asarray(tangent(x), dtype=np.float64)
    return [t] if k is None else list(t)


def splat_stencils(
    radiance: Any, weight: Any, slot: np.ndarray, k: int | None, h: int, cv: Any, out: tuple
) -> None:
    r"""One chunk's splatted estimates $e = L w$ as stencils (:func:`stencil`), value and tangents, and
    with the control variate those of the weights of other pixels' samples and its pixels' radiance
    totals.

    ``radiance`` (samples) and ``weight`` (samples, m): Duals of one tangent or of ``k``, in the sample
    order (batches, pixels, samples); ``slot`` their stencil slots; ``out`` = (stencils, totals) the
    chunk's columns of :meth:`~sphere3d.tasks.ImageTask._splat_buffers`: quantities e, its q tangents
    (q = 1, or k), then w and its q tangents. ``cv``: None (no control variate) or
    ``(n, leave_one_out)``, the scope's sample count and the function giving the totals and each
    sample's leave-one-out scale. Each tangent is computed as the one tangent of a single parameter,
    by the same expressions (:meth:`~sphere3d.tasks.ImageTask._splat_chunk` says what is computed).
    """
    stencils, totals = out
    shape = slot.shape
    wv = np.asarray(detach(weight), dtype=np.float64).reshape(shape)
    wts = [t.reshape(shape) for t in _slots(weight, k)]
    rv = np.asarray(detach(radiance), dtype=np.float64).reshape(*shape[:3], 1)
    rts = [t.reshape(*shape[:3], 1) for t in _slots(radiance, k)]
    ev = rv * wv
    ets = [rt * wv + rv * wt for rt, wt in zip(rts, wts, strict=True)]  # e = L w: the product rule
    if totals is None:
        stencil((ev, *ets), slot, h, stencils)
        return
    n, leave_one_out = cv
    total, scale = leave_one_out(rv[..., 0], n)
    centre = (2 * h + 1) * h + h  # the slot of the sample's own pixel
    own = np.flatnonzero(slot == centre)  # one entry per sample at most: only there is i ∈ p
    scale = scale.ravel()[own // shape[-1]]  # sample i left out of its own pixel
    ev.ravel()[own] -= scale * (wv.ravel()[own] - 1.0)
    totals[0] = total.reshape(totals.shape[1:])
    for i, (rt, et, wt) in enumerate(zip(rts, ets, wts, strict=True)):
        total_t, scale_t = leave_one_out(rt[..., 0], n)
        scale_t = scale_t.ravel()[own // shape[-1]]
        et.ravel()[own] -= scale * wt.ravel()[own] + scale_t * (wv.ravel()[own] - 1.0)
        totals[1 + i] = total_t.reshape(totals.shape[1:])
    stencil((ev, *ets, wv, *wts), slot, h, stencils)
    stencils[len(stencils) // 2 :, :, centre] = 0.0  # the weights of other pixels' samples only


def splat_band(sums: np.ndarray, totals: np.ndarray | None, per_batch: int, n: int) -> tuple[np.ndarray, ...]:
    """A band's value and tangents from its gathered stencil sums (quantities, batches, pixels) and its
    pixels' radiance totals (:func:`splat_stencils`): the means over ``per_batch``, minus, with the
    control variate (``n`` samples per scope), the other pixels' samples' weights times their target's
    mean radiance (value), and the tangent of that product (each tangent)."""
    sums = sums / per_batch
    if totals is None:
        return tuple(sums)
    q = len(sums) // 2  # e and its tangents, then w and its tangents
    mean = totals / n
    value = sums[0] - mean[0] * sums[q]
    return (value, *(sums[i] - mean[0] * sums[q + i] - mean[i] * sums[q] for i in range(1, q)))
