"""The boundary method's transforms: no change of variables, the edge terms added beside it.

Through the two derivative-only hooks of :class:`~sphere3d.integrator.Transforms`:
``shading_extra`` adds the boundary term of each shading integral
(:mod:`sphere3d.boundary.shading`), ``pixel_extra`` the boundary term of the pixel integrals
per batch (:mod:`sphere3d.boundary.camera`). The camera, emitter and cosine strategies stay
the identity's, so the value and the interior term are ``naive``'s.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sphere3d.boundary.camera import camera_edge_term
from sphere3d.boundary.edges import Edges
from sphere3d.boundary.shading import shading_edge_term
from sphere3d.integrator import Identity, Shading
from sphere3d.state import SceneState, build_state

__all__ = ["BoundaryTransforms"]


@dataclass(frozen=True)
class BoundaryTransforms(Identity):
    """Identity rotations; the shading and pixel integrals gain their boundary terms.

    Attributes
    ----------
    edges : Edges
        The scene's edges at θ0 (:func:`~sphere3d.boundary.edges.mesh_edges`).
    per_point : int
        Edge samples per shading point (the method's ``secondary`` option).
    rate : float
        Film edge points per pixel of projected edge length and sample (the method's ``rate``).
    """

    edges: Edges
    per_point: int = 1
    rate: float = 2.0

    def shading_extra(self, shading: Shading) -> np.ndarray | None:
        """The mean of ``per_point`` edge samples of the boundary term of E per shading point
        (:func:`~sphere3d.boundary.shading.shading_edge_term`; uniforms ``"boundary.edge"``)."""
        if not shading.state.dual:
            return None
        u = shading.draws.uniforms("boundary.edge", 2, self.per_point)
        return shading_edge_term(shading, self.edges, u)

    def pixel_extra(self, task: Any, state: SceneState) -> np.ndarray | None:
        """The boundary term of every pixel integral per batch, shape (batches, height, width)
        (:func:`~sphere3d.boundary.camera.camera_edge_term`), for an image task with tangents."""
        if not state.dual or not hasattr(task, "spp"):
            return None
        plain = build_state(task.scene, task.param, 0.0, task.tracer)
        per_batch = task.spp // task.batches
        return np.stack(
            [
                camera_edge_term(state, plain, self.edges, task.seed, b, self.rate * per_batch)
                for b in range(task.batches)
            ]
        )
