"""The boundary method: the naive interior term plus the boundary terms of edge sampling.

Where the integrator calls it: one ``task.evaluate(task.dual_offset(), BoundaryTransforms(...))``
(``variable(0.0)``, or ``variables(k)`` for k parameters: one pass, the jumps times each parameter's
normal velocity)
(:mod:`sphere3d.boundary.transforms`): no change of variables; the shading integrals' boundary
term (:mod:`sphere3d.boundary.shading`) through ``shading_extra``, the pixel integrals' per batch
(:mod:`sphere3d.boundary.camera`) through ``pixel_extra``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from flatland.core.budget import BYTES_PER_RAY, Term
from flatland.core.contract import Option
from flatland.core.validate import check_int, check_positive
from sphere3d.boundary.camera import POINT_CHUNK, film_edges, point_bytes, point_count, point_rays
from sphere3d.boundary.edges import state_edges
from sphere3d.boundary.indirect import side_edges
from sphere3d.boundary.transforms import BoundaryTransforms, draw_bytes, draw_points
from sphere3d.methods._common import GRADIENT_METHODS, memory_model
from sphere3d.paths import PATH_RAYS
from sphere3d.state import plain_state
from sphere3d.tasks import CHUNK, ImageTask, PointTask, Tally

__all__ = ["INDIRECT", "RATE", "SECONDARY", "boundary", "memory"]


RATE = 2.0
"""Default film edge points per pixel of projected edge length and sample."""
SECONDARY = 4
"""Default edge samples per shading point. With RATE, chosen for the least (error × time) on
``hard_shadow``: the camera term's variance falls like 1 / ``rate`` and the shading term's like
1 / ``secondary``, each for a small share more time, the silhouette test being shared by the draws."""
INDIRECT = 1
"""Default edge samples per path vertex of the jump of the reflected radiance (``max_depth`` > 1 only):
each costs two side paths of the remaining depth, far more than an emission-jump sample's four rays."""


@GRADIENT_METHODS.register(
    "boundary",
    Option("rate", RATE, check_positive),
    Option("secondary", SECONDARY, check_int),
    Option("indirect", INDIRECT, check_int),
)
def boundary(task: ImageTask | PointTask, rate: float, secondary: int, indirect: int = INDIRECT) -> Tally:
    r"""Naive interior term plus the boundary terms of the pixel and shading integrals (edge sampling).

    Every integral the renderer differentiates has the form $∫ f(θ, y) dy$ with f
    jumping along curves that move with θ; by the Leibniz (Reynolds transport) rule
    its derivative is the interior term $∫ ∂f/∂θ\, dy$ — the ``naive`` estimator,
    obtained here from the same integrator with the same primary samples — plus, for
    every curve, $∫ [f^- - f^+] (v·n)\, dl$: the jump across the curve times its normal
    velocity (Loubet et al. 2019, Sec. 3.2, the term their reparameterization avoids;
    Li et al. 2018, Sec. 3-4, estimate it by sampling the edges). Both boundary terms
    are included:

    - **pixel integrals** (:mod:`sphere3d.boundary.camera`): the film images of silhouette,
      boundary and crease edges (of flat-shaded shapes), ``rate · spp/batches`` points per pixel of projected
      edge length per batch, each splatted to the pixels whose filter covers it;
    - **shading integrals** (:mod:`sphere3d.boundary.shading`): at every shading point
      ``secondary`` draws among the moving silhouette edges seen from it (occluders'
      outlines, emitters' borders), each a part of an edge's arc inside an emitter's image
      (under a black sky) drawn ∝ its angle, and one point on it;
    - on paths of ``max_depth`` d > 1 (:mod:`sphere3d.paths`): those terms at every vertex, and at
      each vertex v < d ``indirect`` more draws among the arcs of its silhouettes and flat creases for
      the jump of the radiance the surfaces behind them reflect, each side by a path of d - v vertices
      (:mod:`sphere3d.boundary.indirect`); the film term's sides are paths of d vertices.

    The value is ``naive``'s, bit for bit. Unbiased for meshes whose edges are the
    only discontinuities (see :mod:`sphere3d.boundary.edges` for what is not handled: partly
    overlapping edges, surfaces cutting through each other), up to the offsets of the rays
    traced beside the edges ($O(δ^2)$ on the film and at shading points: extrapolated from δ and 2δ).
    Cost: four rays per edge point on the film (both sides at two offsets), and per shading point
    ``4 secondary`` rays (likewise) plus the silhouette test against the edges the edge tree
    finds (:mod:`sphere3d.boundary.edge_tree`); on paths, per vertex v < d, ``2 indirect`` side paths
    of d - v vertices, and each film edge point's four sides are paths of d vertices.
    """
    plain = plain_state(task.scene, task.param, task.tracer)
    edges = state_edges(plain)
    side = side_edges(plain, edges) if task.max_depth > 1 else None
    transforms = BoundaryTransforms(edges, secondary, rate, task.max_depth, 1, side, indirect)
    return task.evaluate(task.dual_offset(), transforms)


@memory_model("boundary")
def memory(task: ImageTask | PointTask, options: Mapping[str, Any]) -> tuple[Term, ...]:
    r"""Memory model of :func:`boundary`: what ``secondary`` (k), ``indirect`` (j) and ``rate`` add.

    ``secondary``: 4k rays per shading point (one per camera sample, or per sample at a point, at each
    of the d = ``max_depth`` vertices of its path), traced in slices: at once
    :func:`~sphere3d.boundary.transforms.draw_bytes` for a memory chunk's shading points.
    ``indirect`` (d > 1 only): at vertex v < d, j draws of two side rays and two side paths of d - v
    vertices (:data:`~sphere3d.paths.PATH_RAYS` rays a vertex), $2 j \sum_{v<d} (1 + 3 (d - v))$ rays per
    sample, and at once a slice's side paths, :data:`~flatland.core.budget.BYTES_PER_RAY` per ray of a
    vertex.
    ``rate``: per batch $N = \lceil \mathrm{rate} · (\mathrm{spp}/\mathrm{batches}) · Λ \rceil$ film edge
    points (Λ the edges' projected length, :func:`~sphere3d.boundary.camera.film_edges`, from the scene
    at θ0), :func:`~sphere3d.boundary.camera.point_rays` rays each (a path of d vertices on each side),
    and at once :func:`~sphere3d.boundary.camera.point_bytes` (points in chunks); none at a point.
    """
    k, depth = options.get("secondary", SECONDARY), task.max_depth
    image = isinstance(task, ImageTask)
    pixels = task.scene.camera.width * task.scene.camera.height if image else 1
    samples = pixels * task.spp if image else task.n  # one shading point each
    chunk = min(task.chunk_pixels, pixels) * task.spp if image else min(CHUNK, task.n // task.batches)
    block = f"{min(chunk, draw_points(k))} shading points × {k} edge samples"
    rays = 4 * k * samples * depth
    terms = (Term("secondary", k, "edge samples per shading point", block, draw_bytes(k, chunk), rays=rays),)
    if depth > 1:
        j = options.get("indirect", INDIRECT)
        side_rays = 2 * j * sum(1 + PATH_RAYS * (depth - v) for v in range(1, depth))
        points = min(chunk, draw_points(k))
        at_once = points * 2 * j * PATH_RAYS * BYTES_PER_RAY
        block = f"{points} shading points × {j} edge samples × 2 side paths"
        what = "edge samples per path vertex of the reflected radiance's jump"
        terms = (*terms, Term("indirect", j, what, block, at_once, rays=side_rays * samples))
    if not image:
        return terms
    rate = options.get("rate", RATE)
    plain = plain_state(task.scene, task.param, task.tracer)
    length = film_edges(plain, plain, state_edges(plain)).length  # Λ_e
    n = int(point_count(rate * (task.spp // task.batches), length).sum())
    block = f"{min(n, POINT_CHUNK)} film edge points"
    what = "film edge points per pixel of edge and sample"
    rays = task.batches * n * point_rays(depth)
    return (*terms, Term("rate", rate, what, block, point_bytes(n), rays=rays))
