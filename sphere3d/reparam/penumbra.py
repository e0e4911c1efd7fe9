r"""Which shading points can see a moving occluder in front of the lights: the emitter probes' cull.

The emitter strategy's probes (:mod:`sphere3d.reparam.emitter_probes`) are needed only at points whose
shadow rays can meet a moving triangle: elsewhere the rotation they choose follows a static
point and has a zero derivative. :func:`may_see_motion` rules points out by two conservative
tests, each cheap per point:

- **bounding spheres**: the cone from x around the lights' bounding sphere and the one around
  the moving triangles' must overlap (and the moving sphere must begin before the lights' ends);
- **separating planes** (:func:`separating_planes`): with L the convex hull of the emitters'
  vertices and M that of the moving triangles', the shadow rays from x lie in the hull of x and
  L, which misses M exactly when some plane separates the two. Every plane that separates L
  from M with x on L's side is such a plane, so
  $x$ can see M only if $n_k \cdot x - d_k \le 0$ for every plane k that separates L (side
  $\ge 0$) from M (side $\le 0$). The region these planes leave is exactly the umbra and
  penumbra volume of M under L (the set of points from which M hides some of L): a separating
  plane of the hull of x and L from M also separates L from M with x on L's side, and the
  extreme ones pass through an edge of one hull and a vertex of the other, the candidates
  tried here.

A point is ruled out only beyond a margin of :data:`MARGIN` ray offsets (the probes start
ε off the surface and stop 2ε before the light, in float32). A smooth occluder has many such
planes (the icosphere of ``hard_shadow``: 118); at most :data:`PLANES` are kept, spread over their
directions, which rules out a little less.

The candidates are (edges of one hull) × (vertices of the other): on a fine mesh, every vertex of
a sphere lies on its hull, and those products would grow with the square of the mesh. So a hull
with more than :data:`HULL_VERTICES` vertices is replaced by a polytope of :data:`DIRECTIONS`
fixed face directions that holds it (:func:`_outer`): a plane that separates the lights from a
polytope holding the moving triangles separates them from the triangles too, so the cull stays
conservative and leaves the umbra and penumbra volume of that polytope, a little larger than the
mesh's. The planes are built once per state, in O(vertices) time and bounded memory.

A speed-up only: a point ruled out could see no moving occluder, so the rotation its probes
would choose follows a static point and has a zero derivative; the result is the same.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import ConvexHull, HalfspaceIntersection

from flatland.core.dual import detach
from sphere3d.live import triangles_change
from sphere3d.tables import per_state
from sphere3d.vector import dot, norm

__all__ = [
    "DIRECTIONS",
    "HULL_VERTICES",
    "MARGIN",
    "PLANES",
    "SeparatingPlanes",
    "bounding_sphere",
    "cone_may_see_motion",
    "cones_overlap",
    "emitter_sphere",
    "may_see_motion",
    "moving_occluders",
    "moving_sphere",
    "separating_planes",
]

MARGIN = 4.0
"""A point is ruled out by a plane only beyond this many ray offsets ε of the scene."""
PLANES = 48
"""At most this many separating planes are kept (:func:`_spread`): fewer rule out fewer points, never a
point they should keep."""
HULL_VERTICES = 256
"""Lights or moving occluders with more distinct vertices (or more than :data:`UNIQUE_LIMIT` triangle corners)
are replaced by an outer polytope of :data:`DIRECTIONS` faces (:func:`_outer`): the candidate planes stay a
bounded number whatever the mesh."""
UNIQUE_LIMIT = 3 << 12
"""Triangle corners up to which :func:`_outer` counts the distinct vertices (a sort) before choosing."""
DIRECTIONS = 64
"""Face directions of the outer polytope of :func:`_outer` (a discrete oriented polytope)."""
PLANE_BLOCK = 1 << 20
"""Candidate planes × hull vertices evaluated at once in :func:`separating_planes`."""


def bounding_sphere(vertices: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and radius of a sphere holding every vertex (k, 3, 3): the box's centre, a safe radius."""
    v = vertices.reshape(-1, 3)
    centre = 0.5 * (v.min(axis=0) + v.max(axis=0))
    return centre, float(np.sqrt(np.max(np.sum((v - centre) ** 2, axis=1)))) * (1.0 + 1e-9)


@dataclass(frozen=True)
class SeparatingPlanes:
    """Planes $n_k \\cdot x = d_k$ (unit ``normals`` (K, 3), ``offsets`` (K,)) with the lights on the
    positive side and the moving triangles on the negative one, and the margin beyond which a point on
    the lights' side is ruled out."""

    normals: np.ndarray
    offsets: np.ndarray
    margin: float

    def rule_out(self, x: np.ndarray) -> np.ndarray:
        """Points ``x`` (m, 3) on the lights' side of some plane, beyond the margin."""
        return np.max(_sides(x, self.normals, self.offsets), axis=0) > self.margin


def _sides(x: np.ndarray, normals: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Signed distances (k, m) of points ``x`` (m, 3) to the planes (unit ``normals`` (k, 3), ``offsets``).

    By coordinates, not ``normals @ x.T``: BLAS hands a product this size to its own threads, which
    then spin beside the renderer's own threads. Planes
    first: a reduction over them is elementwise across the points (over a short last axis, 2 x slower)."""
    n = normals[:, :, None]
    return n[:, 0] * x[:, 0] + n[:, 1] * x[:, 1] + n[:, 2] * x[:, 2] - offsets[:, None]


def _hull(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The convex hull of ``points`` (k, 3): its vertices (n, 3), edges (e, 2) and faces (f, 3), indices
    into the vertices. Up to four points every pair and triple, else Qhull's triangulated facets
    (joggled, "QJ": flat and collinear sets too); supersets of the true edges and faces do no harm,
    every candidate plane is checked."""
    points = np.unique(points, axis=0)
    if len(points) <= 4:
        i, j = np.triu_indices(len(points), k=1)
        faces = np.array(list(itertools.combinations(range(len(points)), 3)), dtype=np.intp)
        return points, np.column_stack([i, j]), faces.reshape(-1, 3)
    hull = ConvexHull(points, qhull_options="QJ")
    used = np.unique(hull.simplices)  # the hull's own vertices, renumbered
    faces = np.searchsorted(used, hull.simplices)
    pairs = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    return points[used], np.unique(pairs, axis=0), faces


def _directions(count: int) -> np.ndarray:
    """``count`` >= 26 unit directions: the 26 of the cube's faces, edges and corners, then a Fibonacci
    spiral over the sphere."""
    cube = np.array([d for d in itertools.product((-1.0, 0.0, 1.0), repeat=3) if any(d)])
    k = np.arange(count - len(cube)) + 0.5
    z = 1.0 - 2.0 * k / (count - len(cube))
    phi = np.pi * (3.0 - np.sqrt(5.0)) * k
    r = np.sqrt(1.0 - z * z)
    spiral = np.column_stack([r * np.cos(phi), r * np.sin(phi), z])
    return np.concatenate([cube / norm(cube)[:, None], spiral])


def _outer(points: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""A convex polytope holding ``points`` (k, 3), as :func:`_hull` gives it: their convex hull
    itself if they are at most :data:`UNIQUE_LIMIT` with at most :data:`HULL_VERTICES` distinct ones,
    else the polytope $\{p : n_j \cdot p \le h_j\}$ of the :data:`DIRECTIONS` fixed directions $n_j$
    of :func:`_directions`, with
    $h_j = \max_p n_j \cdot p + τ$, τ a rounding margin (a discrete oriented polytope). It holds the
    points, so a plane that separates it from the other hull separates them too: the cull stays
    conservative, only a little looser. Its vertices by Qhull's half-space intersection about the
    points' mean (strictly inside, as τ > 0). Cost: (k × :data:`DIRECTIONS`) dot products, by blocks."""
    if len(points) <= UNIQUE_LIMIT:
        points = np.unique(points, axis=0)
        if len(points) <= HULL_VERTICES:
            return _hull(points)
    normals = _directions(DIRECTIONS)
    step = max(1, PLANE_BLOCK // DIRECTIONS)
    offsets = np.max(
        [
            np.max(_sides(points[i : i + step], normals, np.zeros(DIRECTIONS)), axis=1)
            for i in range(0, len(points), step)
        ],
        axis=0,
    )
    offsets += 1e-9 * scale
    polytope = HalfspaceIntersection(np.column_stack([normals, -offsets]), points.mean(axis=0))
    return _hull(polytope.intersections)


def _planes(p: np.ndarray, q: np.ndarray, r: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals and offsets of the planes through the points p, q, r (k, 3) each, unoriented;
    degenerate ones dropped."""
    n = np.cross(q - p, r - p)
    length = norm(n)
    keep = length > 1e-12 * scale**2
    n = n[keep] / length[keep, None]
    return n, dot(n, p[keep])


def _candidates(a: tuple, b: tuple, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """The planes of the faces of hull ``a`` and those through each edge of ``a`` and vertex of ``b``."""
    points, edges, faces = a
    p, q = (np.repeat(points[edges[:, k]], len(b[0]), axis=0) for k in (0, 1))
    r = np.tile(b[0], (len(edges), 1))
    face = _planes(points[faces[:, 0]], points[faces[:, 1]], points[faces[:, 2]], scale)
    through = _planes(p, q, r, scale)
    return np.concatenate([face[0], through[0]]), np.concatenate([face[1], through[1]])


@per_state
def separating_planes(state: Any) -> SeparatingPlanes | None:
    """The planes separating the emitters' convex hull from the moving non-emitter triangles' (module
    docstring), oriented lights-positive; None without emitters, moving triangles or such a plane."""
    moving = moving_occluders(state)
    if not moving.any() or len(state.emitters) == 0:
        return None
    triangles = np.asarray(detach(state.triangles))
    scale = max(
        1.0, float(np.max(np.abs(triangles[state.emitters]))), float(np.max(np.abs(triangles[moving])))
    )
    lights = _outer(triangles[state.emitters].reshape(-1, 3), scale)
    movers = _outer(triangles[moving].reshape(-1, 3), scale)
    (n1, d1), (n2, d2) = _candidates(lights, movers, scale), _candidates(movers, lights, scale)
    n, d = np.concatenate([n1, n2]), np.concatenate([d1, d2])
    tol = 1e-9 * scale  # a plane may touch both hulls
    up, down = np.empty(len(n), dtype=bool), np.empty(len(n), dtype=bool)
    step = max(1, PLANE_BLOCK // (len(lights[0]) + len(movers[0])))
    for lo in range(0, len(n), step):  # blocks of planes: (planes x vertices) stays bounded
        block = slice(lo, lo + step)
        side_l, side_m = _sides(lights[0], n[block], d[block]), _sides(movers[0], n[block], d[block])
        up[block] = (side_l.min(axis=1) >= -tol) & (side_m.max(axis=1) <= tol)
        down[block] = (side_l.max(axis=1) <= tol) & (side_m.min(axis=1) >= -tol)
    if not (up.any() or down.any()):
        return None  # the hulls overlap: no point is ruled out
    normals = np.concatenate([n[up], -n[down]])
    offsets = np.concatenate([d[up], -d[down]])
    keep = _spread(normals, PLANES)
    return SeparatingPlanes(normals[keep], offsets[keep], MARGIN * state.epsilon)


def _spread(normals: np.ndarray, count: int) -> np.ndarray:
    """Indices of at most ``count`` of the unit ``normals`` (k, 3), spread over their directions: each next
    one the farthest from those chosen (farthest-point selection from the first; all if k <= count)."""
    if len(normals) <= count:
        return np.arange(len(normals))
    chosen = [0]
    gap = norm(normals - normals[0])
    for _ in range(count - 1):  # a loop over the few planes kept, not over samples
        chosen.append(int(np.argmax(gap)))
        gap = np.minimum(gap, norm(normals - normals[chosen[-1]]))
    return np.array(chosen)


@per_state
def moving_occluders(state: Any) -> np.ndarray:
    """Per triangle: True for the non-emitter triangles that change with θ (read-only, once per state)."""
    moving = triangles_change(state)
    moving[state.emitters] = False
    moving.flags.writeable = False  # shared by every caller of this state
    return moving


@per_state
def moving_sphere(state: Any) -> tuple[np.ndarray, float]:
    """:func:`bounding_sphere` of the :func:`moving_occluders` at θ0, once per state; meaningless (a
    sphere of radius 0 about the origin) without them."""
    moving = moving_occluders(state)
    if not moving.any():
        return np.zeros(3), 0.0
    return bounding_sphere(np.asarray(detach(state.triangles))[moving])


@per_state
def _changing(state: Any) -> np.ndarray:
    """:func:`~sphere3d.live.triangles_change`, once per state (read-only)."""
    changing = triangles_change(state)
    changing.flags.writeable = False
    return changing


@per_state
def _spheres(state: Any) -> tuple[tuple[np.ndarray, float], tuple[np.ndarray, float]]:
    """The bounding spheres of the changing triangles and of the emitters, once per state."""
    triangles = np.asarray(detach(state.triangles))
    return bounding_sphere(triangles[_changing(state)]), bounding_sphere(triangles[state.emitters])


@per_state
def emitter_sphere(state: Any) -> tuple[np.ndarray, float]:
    """The emitters' bounding sphere at θ0 (centre, radius), once per state."""
    return bounding_sphere(np.asarray(detach(state.triangles))[state.emitters])


def cones_overlap(state: Any, x: np.ndarray) -> np.ndarray:
    r"""Rows of the points ``x`` (plain, (m, 3)) from which the cone around the emitters' bounding
    sphere and the one around the changing triangles' overlap (or that lie inside either sphere).

    A ray from x to the emitters lies within the angle $β_L = \arcsin(r_L / d_L)$ of the direction
    to their sphere's centre, one that meets the changing triangles (:func:`triangles_change`:
    emitters too, if they move) within $β_M$ of theirs, so the two cones must overlap,
    $α < β_L + β_M$, and the moving sphere must begin before the emitters' sphere ends.
    """
    (c_m, r_m), (c_l, r_l) = _spheres(state)
    to_m, to_l = c_m - x, c_l - x
    d_m, d_l = norm(to_m), norm(to_l)
    inside = (d_m <= r_m) | (d_l <= r_l)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_a = np.clip(dot(to_m, to_l) / (d_m * d_l), -1.0, 1.0)
        reach = np.arcsin(np.minimum(1.0, r_l / d_l)) + np.arcsin(np.minimum(1.0, r_m / d_m))
    overlap = np.arccos(cos_a) < reach * (1.0 + 1e-9) + 1e-9
    return inside | (overlap & (d_m - r_m < d_l + r_l))


def may_see_motion(state: Any, x: np.ndarray) -> np.ndarray:
    """Rows of the points ``x`` (plain, (m, 3)) whose shadow rays to the emitters may meet a moving triangle.

    Conservative: first by bounding spheres (:func:`cones_overlap`), then, of those, the points a
    separating plane rules out are dropped (:func:`separating_planes`).
    """
    if not _changing(state).any():
        return np.zeros(len(x), dtype=bool)
    kept = cones_overlap(state, x)
    planes = separating_planes(state)
    if planes is not None:
        rows = np.flatnonzero(kept)
        kept[rows[planes.rule_out(x[rows])]] = False
    return kept


@per_state
def _changing_sphere(state: Any) -> tuple[np.ndarray, float] | None:
    """The bounding sphere of the changing triangles (emitters too), once per state; None without them."""
    changing = _changing(state)
    return bounding_sphere(np.asarray(detach(state.triangles))[changing]) if changing.any() else None


def cone_may_see_motion(state: Any, x: np.ndarray, centre: np.ndarray, half: float) -> np.ndarray:
    r"""Rows of the points ``x`` (plain, (m, 3)) from which a ray within the angle ``half`` of the unit
    directions ``centre`` (m, 3) may meet a changing triangle (:func:`triangles_change`: emitters too).

    Conservative, by their bounding sphere (centre c, radius r): a ray from x meeting it lies within
    $\arcsin(r / |c - x|)$ of the direction to c, so the cone must reach that far,
    $α < \mathrm{half} + \arcsin(r / |c - x|)$; a point inside the sphere is kept."""
    sphere = _changing_sphere(state)
    if sphere is None:
        return np.zeros(len(x), dtype=bool)
    c, r = sphere
    to = c - x
    d = norm(to)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_a = np.clip(dot(to, centre) / d, -1.0, 1.0)
        reach = np.arcsin(np.minimum(1.0, r / d)) + half
    return (d <= r) | ~(np.arccos(cos_a) >= reach * (1.0 + 1e-9) + 1e-9)
