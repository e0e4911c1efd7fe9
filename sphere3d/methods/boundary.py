"""The boundary method: the naive interior term plus the boundary terms of edge sampling.

Where the integrator calls it: one ``task.evaluate(variable(0.0), BoundaryTransforms(...))``
(:mod:`sphere3d.boundary.transforms`): no change of variables; the shading integrals' boundary
term (:mod:`sphere3d.boundary.shading`) through ``shading_extra``, the pixel integrals' per batch
(:mod:`sphere3d.boundary.camera`) through ``pixel_extra``.
"""

from __future__ import annotations

from flatland.core.contract import Option
from flatland.core.dual import variable
from flatland.core.validate import check_int, check_positive
from sphere3d.boundary.edges import mesh_edges
from sphere3d.boundary.transforms import BoundaryTransforms
from sphere3d.methods._common import GRADIENT_METHODS
from sphere3d.state import build_state
from sphere3d.tasks import ImageTask, PointTask, Tally

__all__ = ["RATE", "SECONDARY", "boundary"]


RATE = 2.0
"""Default film edge points per pixel of projected edge length and sample."""
SECONDARY = 4
"""Default edge samples per shading point. With RATE, chosen for the least (error × time) on
``hard_shadow``: the camera term's variance falls like 1 / ``rate`` and the shading term's like
1 / ``secondary``, each for a small share more time, the silhouette test being shared by the draws."""


@GRADIENT_METHODS.register(
    "boundary", Option("rate", RATE, check_positive), Option("secondary", SECONDARY, check_int)
)
def boundary(task: ImageTask | PointTask, rate: float, secondary: int) -> Tally:
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
      (under a black sky) drawn ∝ its angle, and one point on it.

    The value is ``naive``'s, bit for bit. Unbiased for meshes whose edges are the
    only discontinuities (see :mod:`sphere3d.boundary.edges` for what is not handled: partly
    overlapping edges, surfaces cutting through each other), up to the $O(δ)$ offsets
    of the rays traced beside the edges. Cost: two rays per edge point on the film,
    and per shading point ``2 secondary`` rays plus a silhouette test against every edge.
    """
    plain = build_state(task.scene, task.param, 0.0, task.tracer)
    edges = mesh_edges(plain.triangles, plain.shape_of)
    return task.evaluate(variable(0.0), BoundaryTransforms(edges, secondary, rate))
