r"""A small shape inside a film kernel's ring: a fan of affine maps of the film that follows its outline.

The film kernel's rotations (:mod:`sphere3d.reparam.film_kernel`) follow one point of the image,
turning with its edge: two degrees of freedom of translation and one of turn. A shape whose
whole film image lies inside the ring of a kernel's probes, or that is thinner than the ring
however long, has all its silhouette edges (or both its long edges) in the kernel, moving apart
when it scales, moves in depth or turns, and its image is often narrower than the probes'
spacing, seen by none of them (a 0.5 px triangle lost 84-97 % of its film derivative under every
motion, an 8 px one seen at 10 degrees 30-37 %).

For such a shape the film map of the sample is a fan of affine maps about a point c inside its
image. The outline of the image of a convex shape whose vertices lie in front of the camera is the
convex hull of its vertex images $p_i$ (a triangle's: its three vertex images). With c the mean
of the hull's vertices and $\dot c$ the mean of their film velocities, the film is cut into the
cones from c through consecutive hull vertices $p_i$, $p_{i+1}$, and on each cone the map is the
affine $A(u) = u + (θ - θ_0)(\dot c + \dot B_i (u - c))$ with

    $\dot B_i\,[p_i - c,\ p_{i+1} - c] = [\dot p_i - \dot c,\ \dot p_{i+1} - \dot c]$,

which moves c with $\dot c$ and each of the two hull vertices with its own velocity: the outline
edge $p_i p_{i+1}$ goes onto its moved segment, and two neighbouring cones' maps agree along the ray
they share (both are affine on it and agree at c and at its hull vertex), so the pieces tile the
film. For one triangle the three cones' maps are one, the affine map through its three vertex
images, exact under every motion; for a convex mesh each outline edge is carried exactly, under
every motion. (One affine map fitted to all the vertex images by least squares would not do for a
mesh: under a turn out of the image plane its vertex images, front and back, move in no affine way,
and the fit averages the outline's motion away.) The sample's cone is the one its own film point
lies in (as for the corners' fans, :mod:`sphere3d.reparam.film_corners`); a map of its kernel's
centre only.

A change of variables of the film: the sample at s is evaluated at $A(s)$, whose direction is
the sample's own (value) moving with $\dot A(s)$, and its weight carries $|\det A|$ (value 1,
derivative $\mathrm{tr}\,\dot B_i$) in place of the rotation's ratio of film Jacobians
$J(Rω) / J(ω)$ (:func:`~sphere3d.film.affine_directions`; :meth:`sphere3d.film.FilmTransform.log_jacobian`).
Unbiased where that shape's outline edges are the only discontinuities in the kernel. Biased
where another shape's edge also lies in it (dragged by the map; the probes' rotation would follow
one of the two as well), and for a non-convex shape, whose image's concave stretches and inner
silhouettes are not the hull's edges and are dragged likewise. Loubet et al. 2019, Sec. 4.3: a
refinement of the probe heuristic; the flat-film counterpart of flatland's
:func:`~flatland.reparam.probes.film_inner_shape`.

The hull is :class:`scipy.spatial.ConvexHull` (Qhull) of each moving shape's vertex images, once
per state: O(V log V).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from flatland.core.dual import detach, tangent
from sphere3d.film import AffineFilm
from sphere3d.live import moves
from sphere3d.reparam.film_corners import sectors
from sphere3d.state import SceneState
from sphere3d.tables import per_state

__all__ = ["inner_shapes"]

DEGENERATE = 1e-12
"""Relative size of the smallest eigenvalue of a shape's vertex images' scatter below which its
image counts as a segment (a triangle seen edge-on) and no affine map is fitted."""


@dataclass(frozen=True)
class _ShapeImages:
    """Per moving shape with a fan: its index, the fan's centre c (the mean of its hull's vertices) and
    the hull vertices' largest distance from it (pixels), the velocity ``a_dot`` (k, 2) of c, and its
    image's core: the segment ``ends`` (k, 2, 2) along the images' major axis between their extreme
    projections, through c, and the ``width`` (k,) of the images across that axis. Per cone, shape by
    shape from ``start`` (k,) in runs of ``count`` (k,): the ``angle`` (H,) about c of the hull vertex
    that begins it, ascending within a shape, and its map's linear derivative ``b_dot`` (H, 2, 2), or
    (H, k', 2, 2) for k' parameters (module docstring)."""

    shape: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    a_dot: np.ndarray
    ends: np.ndarray
    width: np.ndarray
    start: np.ndarray
    count: np.ndarray
    angle: np.ndarray
    b_dot: np.ndarray


@per_state
def _shape_images(state: SceneState) -> _ShapeImages:
    """Once per state: every shape whose image moves (a vertex carries a tangent, or the camera moves),
    all of whose vertices lie in front of the camera and whose image is not degenerate, with the fan
    of affine maps about its hull (module docstring). O(V log V)."""
    cam = state.camera
    camera_moves = bool(np.any(moves(cam.origin)))
    moving = np.any(moves(state.triangles), axis=(1, 2))
    rows: list[tuple] = []
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
        q = p - p.mean(axis=0)
        scatter = q.T @ q
        extent = float(np.trace(scatter))
        if extent <= 0.0 or np.linalg.eigvalsh(scatter)[0] <= DEGENERATE * extent:
            continue
        try:
            hull = ConvexHull(p).vertices  # counter-clockwise (in film x, y), each vertex once
        except QhullError:  # flat to Qhull's precision (a speck far off): a segment, as DEGENERATE says
            continue
        centre = p[hull].mean(axis=0)
        rate = p_dot[..., hull, :].mean(axis=-2)  # (2,) or (k, 2): c's velocity
        angle = np.arctan2(*(p[hull] - centre)[:, ::-1].T)
        turn = np.argmin(angle)  # the cones in ascending angle, from the hull vertex of least angle
        hull, angle = np.roll(hull, -turn), np.roll(angle, -turn)
        # per cone: B' [p_i - c, p_(i+1) - c] = [p'_i - c', p'_(i+1) - c']   (module docstring)
        e = np.stack([p[hull], p[np.roll(hull, -1)]], axis=-1) - centre[:, None]  # (H, 2, 2): columns
        slots = [p_dot] if p_dot.ndim == 2 else list(p_dot)
        e_dot = [
            np.stack([t[hull], t[np.roll(hull, -1)]], axis=-1) - r[:, None]
            for t, r in zip(slots, np.reshape(rate, (-1, 2)), strict=True)
        ]
        b_dot = [
            np.swapaxes(np.linalg.solve(np.swapaxes(e, 1, 2), np.swapaxes(d, 1, 2)), 1, 2) for d in e_dot
        ]
        major = np.linalg.eigh(scatter)[1][:, 1]
        along, across = (p - centre) @ major, (p - centre) @ np.array([-major[1], major[0]])
        ends = centre + np.outer([along.min(), along.max()], major)
        radius = float(np.sqrt(np.max(np.sum((p[hull] - centre) ** 2, axis=1))))
        width = float(across.max() - across.min())
        rows.append(
            (
                int(s),
                centre,
                radius,
                rate,
                ends,
                width,
                angle,
                b_dot[0] if p_dot.ndim == 2 else np.stack(b_dot, axis=1),
            )
        )
    if not rows:
        flat, none = np.zeros((0, 2)), np.zeros(0, np.int64)
        square = np.zeros((0, 2, 2) if state.k is None else (0, state.k, 2, 2))
        a_dot = np.zeros((0, 2) if state.k is None else (0, state.k, 2))
        return _ShapeImages(
            none, flat, np.zeros(0), a_dot, square, np.zeros(0), none, none, np.zeros(0), square
        )
    count = np.array([len(r[6]) for r in rows])
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    columns = [np.array(c) for c in list(zip(*rows, strict=True))[:6]]
    return _ShapeImages(
        *columns, start, count, np.concatenate([r[6] for r in rows]), np.concatenate([r[7] for r in rows])
    )


def inner_shapes(state: SceneState, centre: np.ndarray, reach: float, at: np.ndarray) -> AffineFilm:
    """Per kernel centre (n, 2), pixels: the fan of the visible moving shape whose film image lies within
    ``reach`` pixels of it (the ring's disc), the one nearest the centre, in the cone that holds the
    sample's own film point ``at`` (n, 2); none elsewhere.

    A shape counts when its whole image lies inside the disc (its hull's circle about the fan's
    centre does), or when its image is thin (narrower than the disc, 2 ``reach``: both its long edges
    can lie in one ring, where one rotation follows one, and probes may pass on both sides of it)
    and its core (the segment along its major axis, widened by half its width) reaches into the
    disc. Visible: a ray at the fan's centre hits
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
    mid = images.centre[k]
    hits = state.tracer.intersect(detach(cam.origin), cam.directions(mid[:, 0], mid[:, 1]))
    seen = hits.shape == images.shape[k]
    rows, k = rows[seen], k[seen]
    rel = at[rows] - images.centre[k]
    cone = sectors(images.angle, images.start[k], images.count[k], np.arctan2(rel[:, 1], rel[:, 0]))
    out.mask[rows] = True
    out.a_dot[rows], out.centre[rows] = images.a_dot[k], images.centre[k]
    out.b_dot[rows] = images.b_dot[images.start[k] + cone]
    return out
