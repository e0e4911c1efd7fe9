r"""A small shape inside a film kernel's ring: the affine map of the film that follows all its edges.

The film kernel's rotations (:mod:`sphere3d.reparam.film_kernel`) follow one point of the image,
turning with its edge: two degrees of freedom of translation and one of turn. A shape whose
whole film image lies inside the ring of a kernel's probes, or that is thinner than the ring
however long, has all its silhouette edges (or both its long edges) in the kernel, moving apart
when it scales, moves in depth or turns out of the image plane, and its image is often narrower
than the probes' spacing, seen by none of them (a 0.5 px triangle lost 84-97 % of its film
derivative under every motion, an 8 px one seen at 10 degrees 30-37 %). For such a shape the film map of the
sample is instead the affine map $A(u) = u + (θ - θ_0)\,(\dot a + \dot B\,(u - \bar p))$ whose
derivative fits the motion of the shape's vertex images $p_i$ (their mean $\bar p$), by least
squares: $\dot a$ the mean of the $\dot p_i$, $\dot B = C_{\dot p p} C_{pp}^{-1}$ with the
cross-covariance $C_{\dot p p}$ of the velocities and the positions and the positions' own
covariance $C_{pp}$. A triangle projects to the triangle
of its vertices' images, so for one triangle the map is exact: it carries all three edges, under
every motion (the flat-film counterpart of flatland's
:func:`~flatland.reparam.probes.film_inner_shape`). For a shape of several triangles it follows
the vertices to first order (exact where their images move affinely: translation, scaling,
turning in the image plane).

A change of variables of the film: the sample at s is evaluated at $A(s)$, whose direction is
the sample's own (value) moving with $\dot A(s)$, and its weight carries $|\det A|$ (value 1,
derivative $\mathrm{tr}\,\dot B$) in place of the rotation's ratio of film Jacobians
$J(Rω) / J(ω)$ (:func:`~sphere3d.film.affine_directions`; :meth:`sphere3d.film.FilmTransform.log_jacobian`).
Unbiased where that shape's edges are the only discontinuities in the kernel; where another
shape's edge also lies in it, that edge is dragged by the map (the probes' rotation would follow
one of the two as well). Loubet et al. 2019, Sec. 4.3: a refinement of the probe heuristic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flatland.core.dual import detach, tangent
from sphere3d.film import AffineFilm
from sphere3d.live import moves
from sphere3d.state import SceneState
from sphere3d.tables import per_state

__all__ = ["inner_shapes"]

DEGENERATE = 1e-12
"""Relative size of the smallest eigenvalue of a shape's vertex images' scatter below which its
image counts as a segment (a triangle seen edge-on) and no affine map is fitted."""


@dataclass(frozen=True)
class _ShapeImages:
    """Per moving shape with a fitted map: its index, the mean of its vertex images and their largest
    distance from it (pixels), the map's derivative (``a_dot`` (k, 2), ``b_dot`` (k, 2, 2)), and its
    image's core: the segment ``ends`` (k, 2, 2) along the images' major axis between their extreme
    projections, through the mean, and the ``width`` (k,) of the images across that axis."""

    shape: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    a_dot: np.ndarray
    b_dot: np.ndarray
    ends: np.ndarray
    width: np.ndarray


@per_state
def _shape_images(state: SceneState) -> _ShapeImages:
    """Once per state: every shape whose image moves (a vertex carries a tangent, or the camera moves),
    all of whose vertices lie in front of the camera and whose image is not degenerate, with its
    least-squares affine motion (module docstring). O(vertices)."""
    cam = state.camera
    camera_moves = bool(np.any(moves(cam.origin)))
    moving = np.any(moves(state.triangles), axis=(1, 2))
    rows: list[tuple[int, np.ndarray, float, np.ndarray, np.ndarray]] = []
    forward = np.asarray(cam.forward, dtype=np.float64)
    for s in np.unique(state.shape_of):  # a handful of shapes, each vectorized over its vertices
        mine = state.shape_of == s
        if not (camera_moves or moving[mine].any()):
            continue
        v = state.triangles[mine].reshape(-1, 3) - cam.origin
        if not np.all(np.asarray(detach(v)) @ forward > 0.0):
            continue
        fx, fy = cam.film(v)
        p = np.stack([np.asarray(detach(fx)), np.asarray(detach(fy))], axis=1)
        p_dot = np.stack([np.asarray(tangent(fx)), np.asarray(tangent(fy))], axis=-1)  # ((k,) V, 2)
        centre = p.mean(axis=0)
        q = p - centre
        scatter = q.T @ q
        extent = float(np.trace(scatter))
        if extent <= 0.0 or np.linalg.eigvalsh(scatter)[0] <= DEGENERATE * extent:
            continue
        # least squares: Σ (ṗ_i - mean ṗ)(p_i - p̄)ᵀ (Σ (p_i - p̄)(p_i - p̄)ᵀ)⁻¹   (module docstring), for
        # k parameters each one's fit as a single parameter's (the rows' axis first, then k)
        fits = [_fit(slot, q, scatter) for slot in ([p_dot] if p_dot.ndim == 2 else p_dot)]
        rate, b_dot = (fits[0][i] if p_dot.ndim == 2 else np.stack([f[i] for f in fits]) for i in (0, 1))
        major = np.linalg.eigh(scatter)[1][:, 1]
        along, across = q @ major, q @ np.array([-major[1], major[0]])
        ends = centre + np.outer([along.min(), along.max()], major)
        radius = float(np.sqrt(np.max(np.sum(q * q, axis=1))))
        rows.append((int(s), centre, radius, rate, b_dot, ends, float(across.max() - across.min())))
    if not rows:
        flat, square = np.zeros((0, 2)), np.zeros((0, 2, 2))
        return _ShapeImages(np.zeros(0, np.int64), flat, np.zeros(0), flat, square, square, np.zeros(0))
    return _ShapeImages(*(np.array(column) for column in zip(*rows, strict=True)))


def _fit(p_dot: np.ndarray, q: np.ndarray, scatter: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One parameter's least-squares motion of a shape's vertex images: (ȧ, Ḃ) from their velocities
    ``p_dot`` (V, 2), their offsets ``q`` from the mean and the offsets' ``scatter``."""
    rate = p_dot.mean(axis=0)
    return rate, ((p_dot - rate).T @ q) @ np.linalg.inv(scatter)


def inner_shapes(state: SceneState, centre: np.ndarray, reach: float) -> AffineFilm:
    """Per kernel centre (n, 2), pixels: the affine map of the visible moving shape whose film image
    lies within ``reach`` pixels of it (the ring's disc), the one nearest the centre; none elsewhere.

    A shape counts when its whole image lies inside the disc (its vertex images' circle about their
    mean does), or when its image is thin (narrower than the disc, 2 ``reach``: both its long edges
    can lie in one ring, where one rotation follows one, and probes may pass on both sides of it)
    and its core (the segment along its major axis, widened by half its width) reaches into the
    disc. Visible: a ray at the mean of its vertex images hits
    that shape (inside a triangle's image, where the core's nearest point may not be). The cost is
    (centres × moving shapes) comparisons and one ray per centre with a candidate.
    """
    n = len(centre)
    images = _shape_images(state)
    out = AffineFilm.none(n, state.k)
    if not len(images.shape):
        return out
    gap = np.hypot(centre[:, None, 0] - images.centre[:, 0], centre[:, None, 1] - images.centre[:, 1])
    # the nearest point of each core to each centre (rows, shapes, 2)
    a, b = images.ends[:, 0], images.ends[:, 1]
    axis = b - a
    length2 = np.maximum(np.sum(axis * axis, axis=1), 1e-300)
    t = np.clip(np.einsum("nkx,kx->nk", centre[:, None] - a, axis) / length2, 0.0, 1.0)
    nearest = a + t[..., None] * axis
    core = np.hypot(centre[:, None, 0] - nearest[..., 0], centre[:, None, 1] - nearest[..., 1])
    thin = (images.width < 2.0 * reach) & (core - 0.5 * images.width < reach)
    dist = np.where((gap + images.radius < reach) | thin, core, np.inf)
    best = np.argmin(dist, axis=1)
    rows = np.flatnonzero(np.isfinite(dist[np.arange(n), best]))
    if not rows.size:
        return out
    k = best[rows]
    cam = state.camera
    at = images.centre[k]
    hits = state.tracer.intersect(detach(cam.origin), cam.directions(at[:, 0], at[:, 1]))
    seen = hits.shape == images.shape[k]
    rows, k = rows[seen], k[seen]
    out.mask[rows] = True
    out.a_dot[rows], out.b_dot[rows], out.centre[rows] = images.a_dot[k], images.b_dot[k], images.centre[k]
    return out
