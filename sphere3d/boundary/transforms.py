"""The boundary method's transforms: no change of variables, the edge terms added beside it.

Through the two derivative-only hooks of :class:`~sphere3d.integrator.Transforms`:
``shading_extra`` adds the boundary term of each shading integral
(:mod:`sphere3d.boundary.shading`), ``pixel_extra`` the boundary term of the pixel integrals
per batch (:mod:`sphere3d.boundary.camera`). The camera, emitter and cosine strategies stay
the identity's, so the value and the interior term are ``naive``'s.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from sphere3d import execution
from sphere3d.boundary.camera import camera_edge_term, film_edges
from sphere3d.boundary.edge_tree import edge_tree
from sphere3d.boundary.edges import Edges
from sphere3d.boundary.indirect import indirect_edge_term
from sphere3d.boundary.shading import moving_edges, shading_edge_term
from sphere3d.integrator import Identity, Shading
from sphere3d.live import moves
from sphere3d.state import SceneState, plain_state

__all__ = ["DRAW_BYTES", "DRAW_CHUNK", "BoundaryTransforms", "draw_bytes", "draw_points"]

DRAW_CHUNK = 1 << 14
"""Edge samples of shading points per slice of :meth:`BoundaryTransforms.shading_extra` (``secondary``
per point): its memory is bounded whatever ``secondary``, down to one point's draws. The slice also
bounds the silhouette pairs held at once (:func:`~sphere3d.boundary.shading._found`: the points'
silhouette edges that reach the emitters, tens per point on a mesh of 10⁵ triangles)."""
DRAW_BYTES = 1024
"""Bytes per edge sample of a slice at most: its uniforms, its sub-arc's choice and ends, the point on
the edge (a Dual), the four rays beside the arc and their hits."""


def draw_points(secondary: int) -> int:
    """Shading points per slice: as many as :data:`DRAW_CHUNK` edge samples hold, at least one."""
    return max(1, DRAW_CHUNK // secondary)


def draw_bytes(secondary: int, points: int) -> int:
    r"""Memory model of :meth:`BoundaryTransforms.shading_extra` for m = ``points`` shading points at once
    (a memory chunk's): $\min(m, s) · k · b$ for k = ``secondary`` draws per point, s =
    :func:`draw_points` points per slice and b = :data:`DRAW_BYTES`; at most
    $\max(\mathrm{DRAW\_CHUNK}, k) · b$, one point's k draws being what no slicing bounds. The
    silhouette pairs of a slice's points (:meth:`~sphere3d.boundary.edge_tree.EdgeTree.silhouettes`,
    tens per point) are apart from it."""
    return min(points, draw_points(secondary)) * secondary * DRAW_BYTES


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
    max_depth : int
        The task's path length d; the film term's side radiance is a path of d vertices.
    vertex : int
        The path vertex v whose shading integrals the hooks serve (:meth:`at_vertex`).
    side : Edges, optional
        :func:`~sphere3d.boundary.indirect.side_edges` of ``edges``, for the jump of the reflected
        radiance at vertices v < d (required when d > 1).
    indirect : int
        Edge samples per shading point of that jump (the method's ``indirect`` option).
    """

    edges: Edges
    per_point: int = 1
    rate: float = 2.0
    max_depth: int = 1
    vertex: int = 1
    side: Edges | None = None
    indirect: int = 1

    def at_vertex(self, vertex: int) -> BoundaryTransforms:
        """These transforms at path vertex ``vertex`` (:mod:`sphere3d.paths` asks at every vertex past
        the first): its edge terms' side paths have ``max_depth - vertex`` further vertices."""
        return dataclasses.replace(self, vertex=vertex)

    def shading_extra(self, shading: Shading, weight: Any = None) -> np.ndarray | None:
        r"""The mean of ``per_point`` edge samples of the boundary term of E per shading point
        (:func:`~sphere3d.boundary.shading.shading_edge_term`; uniforms ``"boundary.edge"``, keyed on
        the points' samples), in slices of :func:`draw_points` points (:func:`draw_bytes`); with
        ``weight(rows, ω)``, of $∫ L_i\, weight \cos θ\, dω$ (a glossy point's BSDF at θ0). At a vertex
        v < d of a path, plus the mean of ``indirect`` samples of the jump of the reflected radiance
        (:func:`~sphere3d.boundary.indirect.indirect_edge_term`, uniforms ``"boundary.indirect"``)."""
        if not shading.state.dual:
            return None
        m, step, k = len(shading), draw_points(self.per_point), shading.state.k
        out = np.empty(m if k is None else (k, m))  # for k parameters: each one's term
        for lo in range(0, max(m, 1), step):
            part = shading if m <= step else shading.take(np.arange(lo, min(m, lo + step)))
            u = part.draws.uniforms("boundary.edge", 2, self.per_point)
            sliced = None if weight is None else (lambda rows, w, lo=lo: weight(lo + rows, w))
            out[..., lo : lo + step] = shading_edge_term(part, self.edges, u, sliced)
            further = self.max_depth - self.vertex  # vertices the side paths have beyond this one
            if further > 0:  # the jump of the radiance the surfaces behind the edges reflect
                u = part.draws.uniforms("boundary.indirect", 2, self.indirect)
                out[..., lo : lo + step] += indirect_edge_term(
                    part, self.side, u, further, self.vertex, sliced
                )
        return out

    def tables(self, state: SceneState) -> tuple[Callable[[SceneState], Any], ...]:
        """The per-state table the shading term's chunks share (:func:`sphere3d.execution.prepare`): the
        edge tree with the moving edges first (:func:`~sphere3d.boundary.edge_tree.edge_tree`)."""
        return (self._tree,) if state.dual and len(self.edges) else ()

    def _tree(self, state: SceneState) -> None:
        """Build the edge tree where a shading point may walk it: where an edge or the camera moves
        (a fixed point walks the moving edges, a moving one every edge, :func:`~sphere3d.boundary.shading.
        moving_edges`); under a parameter that moves neither (an albedo) no chunk asks for it."""
        moving = moving_edges(state, self.edges)
        if moving.any() or moves(state.camera.origin).any():
            edge_tree(self.edges, moving)

    def pixel_terms(self, task: Any, state: SceneState) -> list[Callable[[], np.ndarray]]:
        """The boundary term of every pixel integral, one job per batch (none for a task without tangents
        or pixels): each gives (height, width), or (k, height, width) for k parameters
        (:func:`~sphere3d.boundary.camera.camera_edge_term`, its own stream (seed, batch)). They need no
        chunk: :meth:`~sphere3d.tasks.ImageTask.evaluate` runs them beside the tables."""
        if not state.dual or not hasattr(task, "spp"):
            return []
        plain = plain_state(task.scene, task.param, task.tracer)
        rate = self.rate * (task.spp // task.batches)
        segments = film_edges(state, plain, self.edges)  # the same for every batch
        return [
            functools.partial(
                camera_edge_term, state, plain, self.edges, task.seed, b, rate, segments, self.max_depth
            )
            for b in range(task.batches)
        ]

    def pixel_extra(self, task: Any, state: SceneState) -> np.ndarray | None:
        """The jobs of :meth:`pixel_terms` on the threads, stacked: (batches, height, width), or (k,
        batches, height, width) for k parameters; None without them."""
        jobs = self.pixel_terms(task, state)
        if not jobs:
            return None
        per_batch = execution.map_chunks(lambda b: jobs[b](), range(len(jobs)), counted=False)
        return np.stack(per_batch, axis=0 if state.k is None else 1)
