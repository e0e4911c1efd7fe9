r"""The film kernel of the pixel integral: rotations per camera sample, chosen inside small kernels.

The default variant's pixel integral (Loubet et al. 2019, Sec. 4.2, 4.3; the extensions are
listed in the theory page *extensions*). The pixel integral $∫ k(s) L(ω(s)) ds$ is convolved
with a Gaussian film kernel $g(s - c)$ of variance 1 / ``kappa_film`` ($\mathrm{pixels}^{-2}$),
$∫ g(s - c) dc = 1$ for every s. Each camera sample s (drawn from the filter, the naive
estimator's own sample) gets a kernel centre $c \sim g(· - s)$, the reverse order of the
paper's $ω \sim p$, $μ \sim k(·, ω)$ (theory/kernels), which keeps every evaluation at s itself
and the primal bit-identical to ``naive``'s; around c a ring of probes
(:func:`~sphere3d.reparam.probes.ring_offsets`, radius ``spread`` kernel standard deviations)
chooses the point the sample's rotation follows (:mod:`sphere3d.reparam.probes`, with the
``refine`` bisection onto the silhouette and the snap onto the hit triangle's edge,
:func:`silhouette_snap`), and the rotation turns about that point at the rate that keeps the
snapped edge's image on its own line (:func:`~sphere3d.reparam.snaps.line_spin`; at a corner
the kernel-weighted mean of its two edges' rates), so an edge turning in the image (a shape
rotating) is followed along the kernel, not only at the point. The sample is evaluated along
$R·ω(s)$ with the weight
$g(\mathrm{film}(Rω) - c) / \mathrm{detach}(g(\mathrm{film}(Rω) - c))$ (value exactly 1,
:func:`~flatland.core.translation.unit_weight`), next to the filter's own
$k J (Rω) / \mathrm{detach}(k J (Rω))$ (:func:`~sphere3d.integrator.pixel_samples`).

**Antithetic centres.** Each sample gets two centres, $c = s + σz$ and its mirror image
$c' = s - σz$, each with its own probes and rotation, and the estimate is the mean of the two
(not the authors' paired samples, which share one rotation between two evaluation points and
change the primal). Where both rotations follow the same motion, the kernel weights'
derivatives $κ (c - s)·\dot f$ and $κ (c' - s)·\dot f$ cancel; the radiance is evaluated once,
along the mean of the two rotated directions' tangents (exact: the derivative is linear in
them). Unbiased for a silhouette that the rotation follows: for a fixed centre the rotation is
one change of variables of the whole film integral, and integrating over c restores the pixel
integral. The product of the two weights keeps a zero-mean derivative,
$d/dθ ∫ dc ∫ k(\mathrm{film}\, Rω) J g(\mathrm{film}\, Rω - c) dω = d/dθ\, 1 = 0$, so the
filter-weight control variate of :class:`~sphere3d.tasks.ImageTask` stays exact.

**The kernel's width.** The default concentration is the authors' camera kernel
$κ = 1 / (1 - \cos(0.4 · \mathrm{pixel\ angle}))$ read on the film, $1 - \cos x ≈ x^2 / 2$: a
Gaussian of $σ = 0.4 / \sqrt{2} ≈ 0.28$ px, flatland's
:func:`~flatland.reparam.default.default_kappa_film` in pixel units. The kernel being a fraction
of a pixel wide, the probes see the silhouette next to each sample rather than somewhere on the
pixel's footprint: two edges or a corner in one footprint are followed by different samples.

**Nothing to follow.** Where every probe of a kernel hits one plane of one flat-shaded shape
(:func:`one_plane`), nothing in sight is discontinuous and the rotation is the identity, as
flatland's probes take it when they all see one primitive (any rotation is a change of
variables of a continuous integrand: unbiased). The derivative of those samples then comes
from their shading points sliding over the moving face, not from the filter weight's
derivative times a noisy radiance: less variance. Not applied while the camera moves (every
surface then moves in the image), nor to smooth shapes (interpolated normals: the radiance
varies across the probes' triangles). Rows whose probes cannot reach a moving triangle's film
image (the hull of its vertices' images, :func:`_reaching_motion`) are not probed at all.

**Junctions.** Where a kernel's ring holds one moving silhouette edge and a static edge (the
ground's far edge behind an occluder: a T-junction, or a sliver of sky between the two), an affine
map of the film that keeps both lines replaces the rotation (:mod:`sphere3d.reparam.junctions`): a
rotation, locally a translation of the film, that follows the silhouette drags the static edge.
Where the ring holds a moving corner and a static edge, one field keeps the corner's edges and the
static one (:mod:`sphere3d.reparam.corner_lines`).

Where it is biased: a kernel holding a discontinuity its rotation does not follow: an edge
between the ring's probes, or a feature about a pixel across whose edges move differently
inside one kernel (a small triangle's three edges: a rotation with its turn follows one edge
exactly and two at their common corner to first order, not three; motion in depth and scaling
change the image's size, which no rotation follows, where a sideways translation moves every
edge alike; a triangle narrower than the ring's probes' spacing, seen by none of them). Not
reduced by more samples. Sizes: the
``reparam_bias`` and atlas measurement pages.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from flatland.core.dual import Dual, detach, tangent
from flatland.core.rng import Draws
from flatland.core.validate import ValidationError, check_positive
from sphere3d.film import AffineFilm, FilmTransform
from sphere3d.live import all_rows, any_rows, moves
from sphere3d.reparam.corner_lines import corner_line_maps
from sphere3d.reparam.film_affine import inner_shapes
from sphere3d.reparam.film_corners import REACH, nearest_corners, silhouette_corners
from sphere3d.reparam.junctions import junction_maps
from sphere3d.reparam.probes import follow_probes, ring_offsets
from sphere3d.reparam.snaps import Snap, edge_snap
from sphere3d.rotation import Rotation
from sphere3d.state import SceneState
from sphere3d.tables import per_state
from sphere3d.tracing import Hits, face_normals

__all__ = [
    "KAPPA_FILM",
    "KAPPA_FILM_MAX",
    "check_kappa_film",
    "film_transform",
    "one_plane",
    "silhouette_snap",
]

KAPPA_FILM = 2.0 / 0.4**2
"""Default film kernel concentration, pixels⁻²: σ = 0.4 px / √2 ≈ 0.28 px, the authors' camera
kernel κ = 1 / (1 - cos(0.4 · pixel angle)) with 1 - cos x ≈ x² / 2 (Loubet et al. 2019, Sec. 4.2)."""
KAPPA_FILM_MAX = 1e12
"""Largest film kernel concentration: σ = 1e-6 px, still far above the rounding of film coordinates
(about 1e-14 px on a film of a few thousand pixels); the weight's derivative grows like √κ."""


def check_kappa_film(name: str, value: Any) -> float:
    r"""0 < ``kappa_film`` <= :data:`KAPPA_FILM_MAX` (pixels⁻²), one error naming the option otherwise."""
    kappa = check_positive(name, value)
    if kappa > KAPPA_FILM_MAX:
        raise ValidationError(
            name, f"must be <= {KAPPA_FILM_MAX:g} (a kernel below 1e-6 px is rounding), got {value!r}"
        )
    return kappa


def film_transform(
    state: SceneState,
    x: np.ndarray,
    y: np.ndarray,
    draws: Draws,
    kappa_film: float,
    probes: int,
    spread: float,
    refine: int,
    plane: bool = True,
    junctions: bool = True,
    shapes: bool = True,
    corners: bool = True,
    corner_lines: bool = True,
) -> FilmTransform:
    r"""Two rotations per camera sample at film point (x, y) (pixels), inside an antithetic pair of kernels.

    The centres $c = s + σz$ and $c' = s - σz$ are both distributed as $g(· - s)$, so the mean
    of the two estimates is unbiased; where both rotations follow the same motion their
    kernel weights' derivatives $κ (c - s)·\dot f$ and $κ (c' - s)·\dot f$ cancel (module docstring).

    Parameters
    ----------
    state : SceneState
        The scene at θ (camera, tracer, θ-dependent triangles).
    x, y : ndarray, shape (n,)
        The samples' film coordinates (pixel centre plus the filter offset).
    draws : Draws
        One row per sample: z from ``"kernel.film"``, the rings' phases from ``"probes.film"``.
    kappa_film : float
        1 / variance of the Gaussian kernel, $\mathrm{pixels}^{-2}$.
    probes, spread, refine
        As the ``reparam`` options: probe rays per kernel (its centre and a ring of ``probes - 1``
        at ``spread`` kernel standard deviations); bisection rays toward the silhouette.
    plane : bool, optional
        The identity where every probe of a kernel hits one plane of a flat-shaded shape
        (:func:`one_plane`; :class:`~sphere3d.reparam.default.ReparamTransforms` ``film_one_plane``,
        module docstring),
        while the camera stands still.
    junctions : bool, optional
        Where a ring holds one moving silhouette edge and a static edge, the affine map keeping both
        (:mod:`sphere3d.reparam.junctions`).
    shapes : bool, optional
        Where a moving shape's whole image lies within the kernel's reach (the ring, or
        :data:`~sphere3d.reparam.film_corners.REACH` σ where wider), or is thin and reaches into it,
        follow it by an affine map of the film (:mod:`sphere3d.reparam.film_affine`).
    corners : bool, optional
        Where a moving silhouette vertex's image lies within the kernel's reach (the ring, or
        :data:`~sphere3d.reparam.film_corners.REACH` σ where wider), follow both its silhouette
        edges by an affine map of the film (:mod:`sphere3d.reparam.film_corners`).
    corner_lines : bool, optional
        Where such a ring also holds a static edge (with ``junctions``), the field keeping the corner's
        edges and that edge (:mod:`sphere3d.reparam.corner_lines`).

    Returns
    -------
    FilmTransform
        The two rotations and their kernel centres (Loubet et al. 2019, Sec. 4.2, 4.3).
    """
    cam = state.camera
    n = x.size
    sigma = 1.0 / math.sqrt(kappa_film)
    # c ~ g(· - s) around the sample (reverse order, theory/kernels), and its mirror image c' = 2s - c
    s, z = np.stack([x, y], axis=-1), sigma * draws.normals("kernel.film", 2)
    centre = np.concatenate([s + z, s - z])  # rows: the n first members, then the n second
    phase = draws.uniforms("probes.film", 2).T.ravel()
    k = state.k  # None, or k parameters: every tangent below with a leading axis of k
    rotation = Rotation.identity((2 * n,), k)
    # shapes and corners come from the scene's tables, not from the probes: the kernel's reach, not the ring's
    reach = max(spread, REACH) * sigma
    # a moving shape whose whole image lies within reach: the fan of affine maps that follows its outline
    own = np.concatenate([s, s])  # each member's own film point: the cone or sector of a fan it lies in
    affine = inner_shapes(state, centre, reach, own) if shapes else AffineFilm.none(2 * n, k)
    if corners:  # a silhouette corner within the kernel's reach: the affine map that follows both its edges
        near = nearest_corners(state, centre, reach)
        fan = silhouette_corners(state, centre, reach, own, near)
        if junctions and corner_lines:  # and a static edge: the field keeping all (reparam.corner_lines)
            _fill(affine, _rows_of(2 * n, *corner_line_maps(state, near, centre, own, spread * sigma), k))
        _fill(affine, fan)
    moving = _moving_vertices(state)
    # where the camera stands still and no probe can see a moving triangle, any point chosen is static
    # and the rotation the identity: probes and heuristic run only on the other rows (same result)
    rows = _reaching_motion(state, centre, spread * sigma)
    if rows.size:
        ring = centre[rows, None] + ring_offsets(spread * sigma, probes, phase[rows])
        d = cam.directions(ring[..., 0], ring[..., 1])
        hits = state.tracer.intersect(detach(cam.origin), d)
        if not np.any(moves(cam.origin)):  # and only where a probe did see one
            seen = any_rows(hits.on(moving))
            rows, d, hits = rows[seen], d[seen], hits.take(seen)
            if plane:  # one plane in sight, nothing to follow: the identity (module docstring)
                keep = ~one_plane(state, hits)
                rows, d, hits = rows[keep], d[keep], hits.take(keep)
        if junctions:  # one moving edge and a static one, two that do not meet, a crease: reparam.junctions
            free = rows[~affine.mask[rows]]
            at, maps = junction_maps(state, centre[free], own[free], spread * sigma)
            _fill(affine, _rows_of(2 * n, free[at], maps, k))
        # the probes' rotation where no affine map applies (the same, row by row, as for all rows)
        keep = ~affine.mask[rows]
        rows, d, hits = rows[keep], d[keep], hits.take(keep)
        # a corner up to twice the ring's radius away: its second edge still enters the ring if it
        # makes more than 30 degrees with the line to the centre (sin 30° = 1/2)
        snap = silhouette_snap(state, centre[rows], 2.0 * spread * sigma)
        o = cam.origin
        # the turn that keeps a snapped edge's image on its own line (sphere3d.reparam.snaps.line_spin),
        # the kernel's σ read in radians at the film's centre
        axis = cam.directions(centre[rows, 0], centre[rows, 1])
        pixel_angle = 2.0 * cam.tan_half / cam.width
        spin = (axis / np.linalg.norm(axis, axis=1, keepdims=True), sigma * pixel_angle)
        sub = follow_probes(state, o, detach(o), d, hits, refine=refine, snap=snap, spin=spin).rotation
        rotation.target[rows] = sub.target
        rotation.active[rows] = sub.active
        if sub.spin is not None:
            turn = np.zeros(2 * n if k is None else (k, 2 * n))
            turn[..., rows] = tangent(sub.spin)
            rotation = Rotation(rotation.target, rotation.active, Dual(np.zeros(2 * n), turn, k))
    if affine.mask.any():
        rotation.active[affine.mask] = False
        rotation.target.tangent[affine.mask if k is None else (slice(None), affine.mask)] = 0.0
        if rotation.spin is not None:
            rotation.spin.tangent[..., affine.mask] = 0.0
    first, second = slice(0, n), slice(n, 2 * n)  # views, not copies
    return FilmTransform(
        (rotation.take(first), rotation.take(second)),
        (centre[:n], centre[n:]),
        kappa_film,
        (affine.take(first), affine.take(second)),
    )


def _rows_of(n: int, rows: np.ndarray, maps: AffineFilm, k: int | None) -> AffineFilm:
    """The maps of ``rows`` among n rows (none elsewhere)."""
    out = AffineFilm.none(n, k)
    out.mask[rows] = True
    out.a_dot[rows], out.b_dot[rows], out.centre[rows] = maps.a_dot, maps.b_dot, maps.centre
    return out


def _fill(maps: AffineFilm, other: AffineFilm) -> None:
    """Give the rows of ``other``'s maps that ``maps`` has none for (in place): the rules' precedence."""
    take = other.mask & ~maps.mask
    maps.mask[take] = True
    maps.a_dot[take], maps.b_dot[take] = other.a_dot[take], other.b_dot[take]
    maps.centre[take] = other.centre[take]


COPLANAR = 1e-9
"""Tolerance of :func:`one_plane`: 1 - cos of the angle between face normals, and the offset of a
vertex from probe 0's plane relative to the triangles' extent."""


def one_plane(state: SceneState, hits: Hits) -> np.ndarray:
    r"""Rows (rings of probes) whose probes all hit one plane of one flat-shaded shape.

    Equal face normals ($1 - n_0·n_k <$ :data:`COPLANAR`) and every hit triangle's first
    vertex on probe 0's plane. There the radiance is continuous across the probes'
    triangles (one albedo, one normal); a crease between two faces changes the normal,
    so a ring across it is not one plane. Smooth shapes (interpolated vertex normals)
    never count: module docstring, Nothing to follow.
    """
    tri = np.maximum(hits.triangle, 0)
    same = all_rows(hits.hit) & all_rows(hits.shape == hits.shape[:, :1])
    out = same & ~any_rows(state.smooth[tri])
    rows = np.flatnonzero(out)  # the geometry below only where one flat shape is in sight
    t = tri[rows]
    normals, first, low, high = _plane_table(state)
    n = normals[t]  # (m, P, 3)
    n0 = n[:, :1]
    corner = first[t[:, :1]]  # (m, 1, 3): the first vertex of probe 0's triangle
    # the largest |V - corner| over the probes' vertices and coordinates, from each triangle's box
    reach = np.maximum(high[t] - corner, corner - low[t]).reshape(len(t), t.shape[1] * 3)
    extent = np.max(reach, axis=1, initial=0.0)
    parallel = all_rows(np.sum(n * n0, axis=-1) > 1.0 - COPLANAR)
    offset = np.abs(np.sum((first[t] - corner) * n0, axis=-1))  # n0 · (V_k - V_0): 0 on one plane
    out[rows] = parallel & all_rows(offset <= COPLANAR * (1.0 + extent)[:, None])
    return out


@per_state
def _plane_table(state: SceneState) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per triangle (detached): its unit face normal, first vertex, and the low and high corners of its
    box, (T, 3) each, for :func:`one_plane` (gathered per probe instead of the probes' vertices)."""
    v = np.asarray(detach(state.triangles))
    return face_normals(v), v[:, 0], v.min(axis=1), v.max(axis=1)


def _reaching_motion(state: SceneState, centre: np.ndarray, reach: float) -> np.ndarray:
    """Rows whose probes (within ``reach`` px of ``centre``) may see a moving triangle
    (:func:`_moving_vertices`), or all rows when the camera moves or a moving triangle reaches
    behind the camera plane.

    Conservative: the film image of the moving triangles (all in front of the camera) lies in the
    convex hull of their vertices' images (a triangle projects to the triangle of its vertices'
    images), so a row whose centre lies farther than ``reach`` from that hull (farther than
    ``reach`` outside one of its edges' lines) cannot see one; first by the hull's box, then by
    its edges (:func:`_film_hull`); the result is the same, bit for bit, as probing every row.
    """
    cam = state.camera
    if np.any(moves(cam.origin)):
        return np.arange(len(centre))
    if not _moving_vertices(state).any():
        return np.arange(0)
    hull = _film_hull(state)
    if hull is None:  # a moving vertex at or behind the camera plane
        return np.arange(len(centre))
    (x0, x1, y0, y1), edges = hull
    x, y = centre[:, 0], centre[:, 1]
    rows = np.flatnonzero((x + reach >= x0) & (x - reach <= x1) & (y + reach >= y0) & (y - reach <= y1))
    if edges is None:
        return rows
    c = centre[rows]
    # signed distances to the edges' lines, edges first (a maximum across rows, not over a short axis)
    outside = np.max(edges[:, 0:1] * c[:, 0] + edges[:, 1:2] * c[:, 1] + edges[:, 2:3], axis=0)
    return rows[outside <= reach * (1.0 + 1e-9) + HULL_MARGIN]


HULL_EDGES = 64
"""Film hulls with more edges are replaced by the polygon of this many fixed edge normals that holds them
(:func:`_film_hull`): the rows × edges test of :func:`_reaching_motion` stays bounded whatever the mesh;
looser, so a few more rows are probed, with the same result."""
HULL_MARGIN = 1e-6
"""Pixels added to the probes' reach in :func:`_reaching_motion` (rounding of the film points, of
float32 rays and of Qhull's joggle, 1e-11 relative)."""


@per_state
def _moving_vertices(state: SceneState) -> np.ndarray:
    """Per triangle: True where its vertices carry a tangent, under any parameter (read-only, once per
    state)."""
    moving = np.any(moves(state.triangles), axis=(1, 2))
    moving.flags.writeable = False  # shared by every chunk of the render
    return moving


@per_state
def _film_hull(state: SceneState) -> tuple | None:
    r"""The film box (x0, x1, y0, y1) of the moving triangles' vertices (:func:`_moving_vertices`, at
    least one) and their convex hull's edges (k, 3): unit normal and offset, $n \cdot p + d \le 0$
    inside (None where Qhull finds no 2D hull: the box alone); None if a vertex lies at or behind
    the camera plane. Once per state."""
    cam = state.camera
    v = np.asarray(detach(state.triangles))[_moving_vertices(state)].reshape(-1, 3) - detach(cam.origin)
    if np.any(np.sum(v * np.asarray(detach(cam.forward)), axis=1) <= 0.0):
        return None
    fx, fy = (np.asarray(detach(f)) for f in cam.film(v))
    points = np.column_stack([fx, fy])
    try:
        hull = ConvexHull(points, qhull_options="QJ")
    except QhullError:  # fewer than 3 distinct points: the box alone
        return (fx.min(), fx.max(), fy.min(), fy.max()), None
    edges = hull.equations
    if len(edges) > HULL_EDGES:  # a fine mesh's hull: the polygon of HULL_EDGES fixed normals holding it
        phi = 2.0 * np.pi * np.arange(HULL_EDGES) / HULL_EDGES
        normals = np.column_stack([np.cos(phi), np.sin(phi)])
        offsets = -np.max(points[hull.vertices] @ normals.T, axis=0)  # n·p + d <= 0 for every vertex
        edges = np.column_stack([normals, offsets])
    return (fx.min(), fx.max(), fy.min(), fy.max()), edges


def silhouette_snap(state: SceneState, centre: np.ndarray, radius: float) -> Snap:
    r"""Move a bisected probe hit onto its triangle's edge, or to that edge's corner near the kernel.

    :func:`~sphere3d.reparam.snaps.edge_snap` on the film: a corner whose image lies within ``radius``
    pixels of the kernel ``centre`` (m, 2) is followed. A film rotation (locally a translation
    of the film) that follows a point on a straight edge's line follows the whole edge under
    translation and motion in depth (the edge's normal velocity is affine in the point and
    constant along the line), while one following a point inside T drifts by its distance from
    the edge times the image's rate of scaling (Loubet et al. 2019, Sec. 4.3: a refinement of
    the heuristic).
    """
    cam = state.camera

    def gap(rows: np.ndarray, ends: np.ndarray) -> np.ndarray:
        fx, fy = cam.film(ends)
        return np.hypot(fx - centre[rows, None, 0], fy - centre[rows, None, 1])

    return edge_snap(state, gap, radius)
