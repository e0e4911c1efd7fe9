"""The boundary method: the naive interior term plus the boundary terms of edge sampling.

Where the integrator calls it: one ``task.evaluate(variable(0.0), BoundaryTransforms(...))``
for the interior term; ``camera`` and ``emitter`` stay the identity, ``bsdf`` is the
identity's cosine-sampled estimate plus the boundary term of the shading integral
(:mod:`sphere3d.shading_edges`), added as a zero value with a tangent. After the
evaluation, an :class:`~sphere3d.tasks.ImageTask` adds the boundary term of the pixel
integrals per batch (:mod:`sphere3d.camera_edges`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from flatland.core.contract import Option
from flatland.core.dual import variable
from flatland.core.validate import check_positive
from sphere3d.camera_edges import camera_edge_term
from sphere3d.edges import mesh_edges
from sphere3d.integrator import Identity
from sphere3d.methods._common import GRADIENT_METHODS
from sphere3d.tasks import ImageTask, PointTask, Tally

__all__ = ["BoundaryTransforms", "boundary"]


@dataclass(frozen=True)
class BoundaryTransforms(Identity):
    """Identity rotations; the cosine-sampled estimate gains the shading integral's boundary term."""


@GRADIENT_METHODS.register("boundary", Option("rate", 1.0, check_positive))
def boundary(task: ImageTask | PointTask, rate: float) -> Tally:
    """Naive interior term plus the boundary term of every moving discontinuity (Li et al. 2018).

    Included: the pixel integrals' discontinuities, the film images of silhouette,
    boundary and crease edges (:mod:`sphere3d.camera_edges`), sampled ``rate`` points
    per pixel of projected edge length per camera sample per pixel.

    Omitted: the shading integrals' discontinuities (shadow edges and the emitter's
    own border seen from a shading point): for them this estimator is the ``naive``
    one, biased by minus their boundary term (tests/sphere3d/test_boundary.py shows it).
    """
    tally = task.evaluate(variable(0.0), BoundaryTransforms())
    if not isinstance(task, ImageTask):
        return tally
    state = task.scene.state(task.param, variable(0.0), task.tracer)
    plain = task.scene.state(task.param, 0.0, task.tracer)
    edges = mesh_edges(plain.triangles, plain.shape_of)
    per_batch = task.spp // task.batches
    extra = np.stack(
        [camera_edge_term(state, plain, edges, task.seed, b, rate * per_batch) for b in range(task.batches)]
    )
    return replace(tally, derivative=tally.derivative + extra)
