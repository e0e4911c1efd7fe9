r"""The boundary term of the pixel integrals: edge sampling on the film (primary edges).

Pixel p integrates $I_p = ∫ k(x - p) L(x) dx$ over film positions x (pixels). Where
L jumps along a curve $C(θ)$ that moves with θ, the Leibniz (Reynolds) rule adds to the
interior derivative $∫ k\, ∂L/∂θ\, dx$ (the ``naive`` estimator) the term

    $∫_C k(x - p) [L(x^-) - L(x^+)] (v · n)\, dl$,

n the curve's unit normal on the film, $x^∓$ the points just before and after x along
n, $v = dx/dθ$ the velocity of the curve point (Loubet et al. 2019, Sec. 3.2; Li et
al. 2018, Sec. 3). The filter k is static on the film and adds no term, even the box.

The curves are the projections of mesh edges (:mod:`sphere3d.boundary.edges`): every
boundary, non-manifold and crease edge (a crease between faces of a shape with zero
albedo, or of a smooth-shaded shape, has no jump and is skipped). An edge is clipped
to the part in front of the camera ($\mathrm{depth} > ε$) and its projection to the film
widened by the filter radius;
points are drawn *stratified along each edge's projected length* $Λ_e$,
$N_e = \lceil ρ Λ_e \rceil$ per batch, $ρ = \mathrm{rate} · \mathrm{spp}/\mathrm{batches}$
(``rate`` points per pixel of projected length per camera sample per pixel): point j of edge e
at the fraction $(j + u_j) / N_e + φ_e \bmod 1$ of its image, weighted $Λ_e/N_e$, with $u_j$ and
the edge's rotation $φ_e$ uniform, fresh in every batch (Cranley-Patterson). The strata hold a
single edge each ($v · n$ jumps at a vertex between the two edges' normals), and their rotation
puts every jump of the integrand along the edge (where the edge passes in front of another edge's
image: a T-junction) at a uniform place in its stratum in every batch. With fixed strata a jump
lying near a stratum's end would be crossed with the same small probability f in every batch: a
batch's estimate is then a rare event (the point beyond the jump) on top of a tight core, and
in the seeds where none of the batches draws it the standard error from their spread misses the
event's share f (single pixels tens of standard errors off in some seeds beside the
T-junction of :func:`~sphere3d.closed_form.junction_scene`, tests/sphere3d/test_standard_errors.py).
At each point:

- its 3D position on the edge, $P = A + s (B - A)$ with A, B the edge's Dual vertices
  and s fixed, projected to the film with Duals: the tangent of the film position
  is v (the component along the edge, which s-fixed points also carry, does not
  matter: only $v · n$ enters);
- the edge point must be seen by the camera: a shadow ray to it, blocked more than
  2ε before it, makes the point contribute 0;
- $L(x ∓ δn)$ and $L(x ∓ 2δn)$ by :func:`~sphere3d.integrator.camera_radiance` on the plain
  state at θ0, with the same shading uniforms on all four sides (common random numbers), δ =
  :data:`EPS_FILM` pixels; on paths of ``max_depth`` d the full radiance of paths of d vertices
  (:mod:`sphere3d.paths`), the further vertices' numbers keyed alike on every side;
- the jump extrapolated to δ → 0 (Richardson, as the shading term's):
  $J = 2 J(δ) - J(2δ)$ with $J(δ) = L(x - δn) - L(x + δn)$. Where another curve crosses this one
  (a moving silhouette across a static edge: a T-junction on the film), the side ray crosses it
  within about δ / sin α of the crossing (α their angle), a whole jump wrong on a stretch of that
  length: one pair alone is biased by $O(δ)$ there (tests/sphere3d/test_junctions.py test07, on
  :func:`~sphere3d.closed_form.junction_scene`); the step of $J(2δ)$ lies twice as far, so the
  extrapolation's errors on the two stretches cancel;
- the contribution $Λ_e/N_e\, J\, (v · n)$ goes to every pixel whose filter
  support covers the point, weighted by $k(x - p)$.

Unbiased for these curves up to $O(δ^2)$ (the side rays are δ and 2δ off the curve: in the
shading, and where two curves come within δ of each other). The batches are independent (their
own strata and keyed draws), so the batch standard error is honest per pixel; where a pixel's
filter support meets the edges only in a sliver (the filter's tail, near a vertex) a batch's
estimate is a sum of one or two rare points, far from normal, and its z-score has heavier tails
than Student's t (tests/sphere3d/test_standard_errors.py measures both).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flatland.core.dual import detach, tangent
from flatland.core.rng import Draws, stream
from sphere3d.boundary.edges import Edges
from sphere3d.integrator import Identity, camera_radiance
from sphere3d.paths import PATH_RAYS, vertex
from sphere3d.sampling import filter_radius, filter_value
from sphere3d.state import SceneState
from sphere3d.tracing import Hits
from sphere3d.vector import cross, dot, norm

__all__ = [
    "EPS_FILM",
    "POINT_BYTES",
    "POINT_CHUNK",
    "FilmEdges",
    "camera_edge_term",
    "film_edges",
    "point_bytes",
    "point_count",
    "point_rays",
]

EPS_FILM = 1e-3
"""Offset δ (pixels) of the camera rays traced beside an edge point, along the edge's film normal (at
δ and 2δ on each side)."""
SHADING_UNIFORMS = 5
"""Uniforms of the shading at a side point (3 emitter + 2 cosine), the same on both sides."""
POINT_CHUNK = 1 << 16
"""Edge points per memory chunk of :func:`camera_edge_term`: its memory is bounded whatever ``rate``."""
POINT_BYTES = 6144
"""Bytes per edge point of a chunk at most: its film and 3D positions (Duals), four side rays with their
hits and shading, the shadow ray and the splat's temporaries."""
POINT_RAYS = 13
"""Rays per edge point with direct light: the shadow ray to it, the four side rays (δ and 2δ on each
side), and each side's two shading rays."""


def point_rays(max_depth: int) -> int:
    """Rays per edge point with paths of ``max_depth`` vertices on each of its four sides: the shadow
    ray, and per side its ray and :data:`~sphere3d.paths.PATH_RAYS` a vertex less the first vertex's
    incoming ray (:data:`POINT_RAYS` at 1)."""
    return POINT_RAYS + 4 * PATH_RAYS * (max_depth - 1)


def _liang_barsky(p0: np.ndarray, p1: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, ...]:
    """Parameter range [t0, t1] of the segments p0 → p1 (n, 2) inside the box [lo, hi] (empty: t0 >= t1)."""
    d = p1 - p0
    t0, t1 = np.zeros(len(p0)), np.ones(len(p0))
    for k in range(2):  # the two axes; each bounds t from both sides
        with np.errstate(divide="ignore", invalid="ignore"):
            ta = (lo[k] - p0[:, k]) / d[:, k]
            tb = (hi[k] - p0[:, k]) / d[:, k]
        flat = d[:, k] == 0.0
        inside = (p0[:, k] >= lo[k]) & (p0[:, k] <= hi[k])
        t0 = np.where(flat, np.where(inside, t0, 1.0), np.maximum(t0, np.minimum(ta, tb)))
        t1 = np.where(flat, np.where(inside, t1, 0.0), np.minimum(t1, np.maximum(ta, tb)))
    return t0, t1


def _side_hits(plain: SceneState, edges: Edges, d: np.ndarray) -> Hits:
    """What the camera sees along ``d`` (2n, 3), the rays just beside the n edge points (minus side
    first): on a side where one of the edge's own faces lies, the nearest such face; elsewhere the
    traced first hit.

    Tracing alone fails beside a face seen almost edge-on, whose image can be thinner than
    :data:`EPS_FILM`: the ray beside a crease would pass it and report the background. A face
    lies on the side of its centroid with respect to the plane through the camera and the edge
    (the edge's vertices lie in that plane); the nearer face along the ray (plane intersection
    in float64) is the one seen. Non-manifold edges are traced on both sides.
    """
    n = len(edges)
    o0 = np.asarray(plain.camera.origin)
    tri = np.asarray(plain.triangles)
    traced = plain.tracer.intersect(o0, d)
    shape, triangle = traced.shape.copy(), traced.triangle.copy()
    plane = cross(edges.a - o0, edges.b - o0)
    ray_side = np.sign(dot(np.concatenate([plane, plane]), d))
    best = np.full(2 * n, np.inf)
    for f, usable in ((edges.face, edges.count <= 2), (edges.other, edges.other >= 0)):
        t3 = tri[np.maximum(f, 0)]
        face_side = np.sign(dot(plane, t3.mean(axis=1) - o0))
        normal = cross(t3[:, 1] - t3[:, 0], t3[:, 2] - t3[:, 0])
        t3, normal = np.concatenate([t3, t3]), np.concatenate([normal, normal])
        with np.errstate(divide="ignore", invalid="ignore"):
            t = dot(normal, t3[:, 0] - o0) / dot(normal, d)  # the ray meets the face's plane
        ok = np.tile(usable & (face_side != 0.0), 2) & (np.tile(face_side, 2) == ray_side) & (t > 0.0)
        nearer = ok & (t < best)
        best = np.where(nearer, t, best)
        f2 = np.tile(f, 2)
        triangle = np.where(nearer, f2, triangle)
        shape = np.where(nearer, plain.shape_of[np.maximum(f2, 0)], shape)
    return Hits(shape, triangle, traced.t, traced.u, traced.v)


def camera_candidates(state: SceneState, edges: Edges) -> np.ndarray:
    """Edges that may carry a jump of the camera's radiance: silhouettes, boundaries, and creases of
    flat-shaded shapes that reflect (albedo > 0, or the albedo is the parameter).

    A crease of a smooth shape (``smooth: true``) is skipped: the interpolated vertex normals
    agree on both sides, so the side rays would only measure an O(EPS_FILM) difference and the
    part of the hemisphere each face's own plane cuts off (:mod:`sphere3d.reparam.face_plane`),
    whose change across the crease is the difference of $n_s·n_g$ on its two faces, nearly 0 where
    $n_s$ lies between the two face normals (a bias of that order, checked against the term of
    those creases alone under a sky; skipping saves 480 of the 490 edges of the ``hard_shadow``
    icosphere, most of its projected edge length).
    """
    origin = np.asarray(detach(state.camera.origin))
    albedo = np.asarray(detach(state.albedo))
    reflects = (albedo > 0.0) | state.albedo_varies
    # a smooth shape's vertex normals are shared by its faces: its shading is continuous across creases
    flat = ~np.asarray(state.smooth)[edges.face]
    shading_jump = edges.crease & reflects[state.shape_of[edges.face]] & flat
    return edges.silhouette(origin) | shading_jump


@dataclass(frozen=True)
class FilmEdges:
    """The candidate edges (:func:`camera_candidates`) clipped to depth > ε, and their film images
    clipped to the film widened by the filter radius: 3D parameters ``s0``, ``s1`` of the clipped
    ends ``p3a``, ``p3b``, their film points ``fa``, ``fb``, the film fractions ``t0``, ``t1`` inside the
    widened film and the projected ``length`` there (pixels); ``total`` is Λ, their sum."""

    edges: Edges
    s0: np.ndarray
    s1: np.ndarray
    p3a: np.ndarray
    p3b: np.ndarray
    fa: np.ndarray
    fb: np.ndarray
    t0: np.ndarray
    t1: np.ndarray
    length: np.ndarray

    @property
    def total(self) -> float:
        return float(self.length.sum())


def film_edges(state: SceneState, plain: SceneState, edges: Edges) -> FilmEdges:
    """The film images of the edges that may carry a jump (:class:`FilmEdges`); Λ = 0 if there are none."""
    cam = state.camera
    edges = edges.take(np.flatnonzero(camera_candidates(state, edges)))
    o0 = plain.camera.origin
    # clip each edge in 3D to depth > ε (depth is linear in the edge parameter s)
    za, zb = dot(edges.a - o0, cam.forward), dot(edges.b - o0, cam.forward)
    near = plain.epsilon
    with np.errstate(divide="ignore", invalid="ignore"):
        s_cross = (near - za) / (zb - za)
    s0 = np.where(za >= near, 0.0, np.where(zb > za, s_cross, 1.0))
    s1 = np.where(zb >= near, 1.0, np.where(za > zb, s_cross, 0.0))
    front = s1 > s0
    edges, s0, s1 = edges.take(front), s0[front], s1[front]
    p3a = edges.a + s0[:, None] * (edges.b - edges.a)
    p3b = edges.a + s1[:, None] * (edges.b - edges.a)
    fa = np.stack(cam.film(p3a - o0), axis=-1).reshape(-1, 2)
    fb = np.stack(cam.film(p3b - o0), axis=-1).reshape(-1, 2)
    r = filter_radius(cam.filter)
    t0, t1 = _liang_barsky(fa, fb, np.array([-r, -r]), np.array([cam.width + r, cam.height + r]))
    length = norm(fb - fa) * np.maximum(t1 - t0, 0.0)
    return FilmEdges(edges, s0, s1, p3a, p3b, fa, fb, t0, t1, length)


def point_count(points_per_pixel: float, length: np.ndarray) -> np.ndarray:
    r"""Edge points of one batch per edge, $N_e = \lceil \mathrm{points\_per\_pixel} · Λ_e \rceil$
    (none where $Λ_e = 0$); their sum is at most $\lceil ρ Λ \rceil$ plus the number of edges seen."""
    length = np.asarray(length, dtype=np.float64)
    return np.where(length > 0.0, np.ceil(points_per_pixel * length), 0.0).astype(np.int64)


def point_bytes(n: int) -> int:
    r"""Memory model of :func:`camera_edge_term`: the bytes its points take at once for N points per batch,
    $\min(N, \mathrm{POINT\_CHUNK}) · b$ ($b$ = :data:`POINT_BYTES`): bounded by :data:`POINT_CHUNK`
    whatever ``rate``, the image and the batch's samples (the image it adds to is the task's)."""
    return min(n, POINT_CHUNK) * POINT_BYTES


def _uniforms(seed: int, batch: int, skip: int, shape: tuple[int, ...]) -> np.ndarray:
    """Uniforms ``skip`` draws into the batch's sequential stream: the numbers a single draw of them all
    would give there (PCG64 draws one 64-bit word per float64), so chunks see the same numbers."""
    rng = stream(seed, "boundary.camera", batch)
    rng.bit_generator.advance(skip)
    return rng.random(shape)


def camera_edge_term(
    state: SceneState,
    plain: SceneState,
    edges: Edges,
    seed: int,
    batch: int,
    points_per_pixel: float,
    segments: FilmEdges | None = None,
    max_depth: int = 1,
) -> np.ndarray:
    """One batch's boundary term of every pixel, shape (height, width) (see the module docstring).

    Parameters
    ----------
    state : SceneState
        The state with θ as a Dual (velocities); ``plain`` the same at θ0 without tangents
        (visibility and the radiance beside the edges).
    edges : Edges
        The scene's edges (:func:`~sphere3d.boundary.edges.mesh_edges`).
    seed, batch : int
        The batch's points come from ``stream(seed, "boundary.camera", batch)``: first the N
        stratification offsets, then N × :data:`SHADING_UNIFORMS` shading uniforms.
    points_per_pixel : float
        Expected edge points per pixel of projected edge length.
    segments : optional
        ``film_edges(state, plain, edges)`` if the caller has it (the same for every batch).
    max_depth : int
        The radiance on each side is a path of up to this many vertices (:mod:`sphere3d.paths`), the
        same random numbers on both sides.

    The points are processed :data:`POINT_CHUNK` at a time (:func:`point_bytes`), each chunk with
    its own part of the batch's stream: the same numbers as all at once, the splat's sums in chunk order.
    """
    cam = state.camera
    out = np.zeros(cam.height * cam.width if state.k is None else (state.k, cam.height * cam.width))
    seg = film_edges(state, plain, edges) if segments is None else segments
    count = point_count(points_per_pixel, seg.length)
    n = int(count.sum())
    for lo in range(0, n, POINT_CHUNK):
        points = range(lo, min(n, lo + POINT_CHUNK))
        _splat_points(out, state, plain, seg, (seed, batch), count, points, max_depth)
    return out.reshape(*out.shape[:-1], cam.height, cam.width)


def _splat_points(
    out: np.ndarray,
    state: SceneState,
    plain: SceneState,
    seg: FilmEdges,
    key: tuple[int, int],
    per_edge: np.ndarray,
    points: range,
    max_depth: int = 1,
) -> None:
    """Add the contributions of the batch's edge points ``points`` (of n) to ``out`` (module docstring)."""
    cam = state.camera
    height, width = cam.height, cam.width
    edges, count, n = seg.edges, len(points), int(per_edge.sum())
    o0 = plain.camera.origin
    # stratified along each edge's image: its point j uniform in [j, j + 1) Λ_e / N_e, weight Λ_e / N_e
    i = np.arange(points.start, points.stop)
    end = np.cumsum(per_edge)
    k = np.searchsorted(end, i, side="right")  # the edge of point i: end[k - 1] <= i < end[k]
    j = i - (end[k] - per_edge[k])
    # the strata rotated by the edge's own uniform φ_e, fresh per batch: a jump along the edge falls at
    # a uniform place in its stratum in every batch (module docstring)
    rotation = stream(key[0], "boundary.camera.rotation", key[1]).random(len(per_edge))[k]
    fraction = np.mod((j + _uniforms(*key, points.start, (count,))) / per_edge[k] + rotation, 1.0)
    t = seg.t0[k] + fraction * (seg.t1[k] - seg.t0[k])
    share = seg.length[k] / per_edge[k]
    t = np.clip(t, 0.0, 1.0)
    # film fraction t -> fraction σ of the clipped 3D segment (perspective: x = lerp weighted by depth)
    da, db = dot(seg.p3a[k] - o0, cam.forward), dot(seg.p3b[k] - o0, cam.forward)
    sigma = t * da / ((1.0 - t) * db + t * da)
    s = seg.s0[k] + sigma * (seg.s1[k] - seg.s0[k])
    a, b = edges.endpoints(state.triangles)
    point = a[k] + s[:, None] * (b[k] - a[k])  # Dual: moves with θ at fixed s
    fx, fy = cam.film(point - cam.origin)
    x = np.stack([detach(fx), detach(fy)], axis=-1)
    v = np.stack([tangent(fx), tangent(fy)], axis=-1)  # (count, 2), or (k, count, 2) for k parameters
    seg_film = seg.fb[k] - seg.fa[k]
    seg_length = norm(seg_film)
    # a zero-length image is never drawn (rounding aside: its weight is then 0, not 0/0)
    normal = (
        np.stack([-seg_film[:, 1], seg_film[:, 0]], axis=-1)
        / np.where(seg_length > 0.0, seg_length, 1.0)[:, None]
    )
    # the edge point itself must be the camera's first hit (up to 2ε before it)
    p0 = edges.a[k] + s[:, None] * (edges.b[k] - edges.a[k])
    to = p0 - o0
    dist = norm(to)
    seen = ~plain.tracer.occluded(o0, to / dist[:, None], np.maximum(dist - 2.0 * plain.epsilon, 0.0))
    # radiance just beside the curve, at δ and 2δ, the same shading uniforms on every side
    u = _uniforms(*key, n + SHADING_UNIFORMS * points.start, (count, SHADING_UNIFORMS))
    # keyed per batch, apart from the primary samples' keys (below 2^62): no draw shared between batches;
    # the same keys on every side, so the paths beyond the first vertex share their numbers too
    draws = Draws.of(key[0], np.tile((1 << 62) + key[1] * (1 << 40) + i, 2))
    shade = vertex(
        max_depth, plain
    )  # paths of max_depth vertices, glossy shapes by their BSDF (sphere3d.paths)
    near = edges.take(k)
    jumps = []
    for offset in (EPS_FILM, 2.0 * EPS_FILM):
        side = np.concatenate([x - offset * normal, x + offset * normal])
        d = cam.directions(side[:, 0], side[:, 1])
        hits = _side_hits(plain, near, d)
        radiance = np.asarray(
            camera_radiance(plain, Identity(), d, d, np.concatenate([u, u]), draws, hits, shade)
        )
        jumps.append(radiance[:count] - radiance[count:])
    # J(δ) = L(x - δn) - L(x + δn) = J + a δ + O(δ²): 2 J(δ) - J(2δ) = J + O(δ²)   (Richardson)
    jump = 2.0 * jumps[0] - jumps[1]
    # Reynolds: the side x⁻ grows into x⁺ at speed v · n   (Loubet et al. 2019, Sec. 3.2); for k
    # parameters the same jumps times each parameter's v · n, into its own image
    slots = [(out, v)] if v.ndim == 2 else list(zip(out, v, strict=True))
    weights = [jump * np.sum(v_i * normal, axis=1) * share * seen for _, v_i in slots]
    reach = math.ceil(filter_radius(cam.filter) + 0.5)
    base = np.floor(x).astype(np.int64)
    for dy in range(-reach, reach + 1):  # splat to every pixel whose filter support covers x
        for dx in range(-reach, reach + 1):
            col, row = base[:, 0] + dx, base[:, 1] + dy
            inside = (col >= 0) & (col < width) & (row >= 0) & (row < height)
            kx = filter_value(np.stack([x[:, 0] - col - 0.5, x[:, 1] - row - 0.5], axis=-1), cam.filter)
            for (image, _), weight in zip(slots, weights, strict=True):
                np.add.at(image, (row * width + col)[inside], (kx * weight)[inside])
