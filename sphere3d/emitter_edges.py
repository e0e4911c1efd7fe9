"""The boundary term of the emitter-sampling strategy: the light's own edges, held fixed.

The emitter strategy of :mod:`sphere3d.integrator` samples a point y uniformly on the
emitters' area A (at θ0), turns its direction w(y) by one rotation R(θ) per shading
point (:meth:`~sphere3d.integrator.Transforms.emitter`) and re-attaches it to the plane
of the sampled triangle: T_θ(y), the identity at θ0. The re-attachment has no edge
(its barycentrics are not clamped), so the estimator differentiates

    E_L(θ) = ∫_A F(T_θ(y), θ) 1[T_θ(y) ∈ A] |J| dA(y)

without the indicator. F is the area-measure integrand
``L_e V cos θ_x cos θ_y / d² · w_L`` (w_L the balance weight of the emitter strategy).
Where the rotation follows an occluder and the light's edge is sharp (no ``fade``),
the edge moves in the rotated frame, and its term is lost: the soft-shadow gradient.
By Leibniz's rule (Loubet et al. 2019, Sec. 4.3: an emitter's border is a
discontinuity like any other, to be followed or held fixed; theory/leibniz) the
missing term is

    - ∫_∂A F_in(y) (V_T(y) · n_out(y)) dl(y),

F_in the integrand just inside, n_out the outward unit normal of A in its plane, and
V_T = dT/dθ the velocity of the re-attached point relative to the emitter, read from
the tangents of the re-attached barycentrics, ``V_T = ḃ₁ e₁ + ḃ₂ e₂`` (e₁, e₂ the
triangle's edge vectors): it is computed by the same Dual re-attachment
(:func:`~sphere3d.tracing.intersect_triangles`) along the rotated direction of the edge
point. Its value is 0, so the primal is unchanged; with it the emitter strategy's
derivative is unbiased for whatever rotation is chosen (the visibility it treats as
fixed aside, as the interior term does).

The edges are the emitters' **boundary edges** (one face among the emitter triangles),
edges between two emitter shapes and creases (two non-coplanar faces); for a
two-face edge both faces' terms are summed at the same point (each only if its front
faces the shading point). An edge shared by three or more emitter triangles gets the
term of one face only (no built-in scene has one). Each shading point draws one point
uniform in length on these edges (density 1 / perimeter) and traces one shadow ray.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core.dual import Dual, detach, tangent
from sphere3d.edges import mesh_edges
from sphere3d.rotation import Rotation
from sphere3d.tracing import face_normals, intersect_triangles
from sphere3d.vector import cross, dot, norm

__all__ = ["EmitterEdgeSamples", "add_tangent", "sample_emitter_edges"]

INV_PI = 1.0 / np.pi


@dataclass(frozen=True)
class EmitterEdgeSamples:
    """One point on the emitters' edges per shading point that sees it (plain arrays, θ0).

    Attributes
    ----------
    index : ndarray of int, shape (k,)
        The shading points (rows of the :class:`~sphere3d.integrator.Shading`) whose edge
        point is above their surface, in front of a face of the edge and unoccluded.
    w : ndarray, shape (k, 3)
        Unit direction from the shading point to the edge point.
    faces : ndarray of int, shape (k, 2)
        The edge's emitter triangles (global indices); -1 where there is no second one.
    front : ndarray of bool, shape (k, 2)
        Which of them faces the shading point (the emitter strategy samples only those).
    outward : ndarray, shape (k, 2, 3)
        Outward unit normal of each face at the edge, in the face's plane.
    dist, cos_x : ndarray, shape (k,)
        Distance to the edge point and cos θ_x there.
    perimeter : float
        Total length of the edges (the sampling density is 1 / perimeter).
    """

    index: np.ndarray
    w: np.ndarray
    faces: np.ndarray
    front: np.ndarray
    outward: np.ndarray
    dist: np.ndarray
    cos_x: np.ndarray
    perimeter: float

    def tangent_term(self, state: Any, x: Any, rotation: Rotation) -> np.ndarray:
        """The boundary term's estimate (a tangent, shape (k,)) given one rotation per point.

        ``x``: the points ``index`` (Dual positions); ``rotation``: their emitter rotations.
        Estimate ``- perimeter · Σ_faces F_in (V_T · n_out)`` (module docstring).
        """
        rotated = rotation.apply(self.w)
        area = float(detach(state.emitter_area))
        tri0 = np.asarray(detach(state.triangles))
        out = np.zeros(len(self.index))
        for j in range(2):  # the edge's two faces (not a loop over samples)
            s = np.flatnonzero(self.front[:, j])
            if s.size == 0:
                continue
            f = self.faces[s, j]
            it = intersect_triangles(x[s], rotated[s], state.triangles[f])
            t0 = tri0[f]
            # velocity of the re-attached point relative to the emitter, V_T = ḃ₁ e₁ + ḃ₂ e₂
            v = tangent(it.b1)[:, None] * (t0[:, 1] - t0[:, 0]) + tangent(it.b2)[:, None] * (
                t0[:, 2] - t0[:, 0]
            )
            speed = dot(v, self.outward[s, j])
            cos_y = -dot(face_normals(t0), self.w[s])
            d = self.dist[s]
            p_light = d * d / (area * cos_y)  # solid-angle density of the emitter strategy
            p_cos = self.cos_x[s] * INV_PI
            # F_in: L_e (just inside: the border fade, if any, is 0 there) cos_x cos_y / d² w_L
            emitted = np.asarray(detach(state.emitted(f, detach(it.b1), detach(it.b2))), dtype=np.float64)
            f_in = emitted * self.cos_x[s] * cos_y / (d * d) * (p_light / (p_light + p_cos))
            out[s] -= self.perimeter * f_in * speed
        return out


def sample_emitter_edges(state: Any, shading: Any) -> EmitterEdgeSamples | None:
    """One point per shading point, uniform in length on the emitters' edges (module docstring).

    ``shading``: a :class:`~sphere3d.integrator.Shading`; random numbers from its draws
    (stream ``"emitter.edge"``), so the primary samples are untouched. None when the
    emitters have no such edge (a closed mesh without creases) or no point sees one.
    """
    emitters = np.asarray(detach(state.triangles))[state.emitters]
    edges = mesh_edges(emitters, state.shape_of[state.emitters])
    keep = np.flatnonzero(edges.always | edges.crease)
    if keep.size == 0:
        return None
    edges = edges.take(keep)
    length = norm(edges.b - edges.a)
    cdf = np.cumsum(length)
    perimeter = float(cdf[-1])
    u = shading.draws.uniforms("emitter.edge", 2)
    e = np.minimum(np.searchsorted(cdf, u[:, 0] * perimeter, side="right"), len(cdf) - 1)
    y = edges.a[e] + u[:, 1:2] * (edges.b[e] - edges.a[e])
    local = np.stack([edges.face[e], edges.other[e]], axis=1)  # into ``emitters``; -1: no second face
    faces = np.where(local >= 0, state.emitters[np.maximum(local, 0)], -1)
    to = y - detach(shading.x)
    dist = norm(to)
    w = to / np.where(dist > 0.0, dist, 1.0)[:, None]
    cos_x = dot(detach(shading.n), w)
    tri = emitters[np.maximum(local, 0)]  # (m, 2, 3, 3)
    normals = face_normals(tri)
    front = (-dot(normals, w[:, None]) > 1e-9) & (faces >= 0)  # the emitter strategy's own test
    valid = front.any(axis=1) & (cos_x > 0.0) & (dist > 4.0 * state.epsilon)
    idx = np.flatnonzero(valid)
    blocked = state.tracer.occluded(shading.origin[idx], w[idx], dist[idx] - 2.0 * state.epsilon)
    idx = idx[~blocked]
    if idx.size == 0:
        return None
    # outward normal in the face's plane: perpendicular to the edge, away from the face's centroid
    along = edges.b[e[idx]] - edges.a[e[idx]]
    outward = cross(along[:, None], normals[idx])
    outward = outward / norm(outward)[..., None]
    centroid = tri[idx].mean(axis=2)
    away = dot(outward, edges.a[e[idx]][:, None] - centroid) > 0.0
    outward = np.where(away[..., None], outward, -outward)
    return EmitterEdgeSamples(idx, w[idx], faces[idx], front[idx], outward, dist[idx], cos_x[idx], perimeter)


def add_tangent(estimate: Dual, index: np.ndarray, term: np.ndarray) -> Dual:
    """``estimate`` with ``term`` added to the tangents at ``index``: the value, bit for bit, unchanged."""
    t = estimate.tangent.copy()
    np.add.at(t, index, term)
    return Dual(estimate.value, t)
