r"""Shading at glossy points: the rough-conductor BSDF of :mod:`sphere3d.bsdf` under MIS (theory/bsdf).

A shape with ``roughness`` α (:mod:`sphere3d.materials`) reflects

$L_r(w_i) = ∫ L_i(w_o) f(w_i, w_o) (n·w_o) dω_o$

with f the GGX microfacet BSDF, its Fresnel term the shape's ``albedo`` F (:func:`~sphere3d.bsdf.eval_ggx`),
$w_i$ the unit direction back towards the camera or the previous path vertex. One sample per point of
each of two strategies, combined by the balance heuristic:

- *emitter sampling*: y uniform on the emitters' area (the same 3 uniforms as the diffuse
  :func:`~sphere3d.integrator.irradiance_samples`), the shadow ray traced, the unoccluded sample
  re-attached to the emitter triangle along its fixed direction; weight $p_L / (p_L + p_f)$;
- *BSDF sampling*: $w_o$ drawn from the visible GGX normals (:func:`~sphere3d.bsdf.sample_ggx`, the 2
  cosine uniforms), its ray traced; the sky where it escapes (weight 1: emitter sampling never
  draws the sky), an emitter's front side with weight $p_f / (p_f + p_L)$.

Both MIS weights are evaluated with θ-dependent densities (the moving point, normal, α and emitter),
so they sum to 1 at every θ; each estimate divides by its θ-free sampling density, so its
forward-mode derivative is the naive one (Loubet et al. 2019, Sec. 3.1): the integrand differentiated
at fixed samples. The BSDF sample is also the direction a path goes on along (:mod:`sphere3d.paths`),
with throughput $f (n·w_o) / p_f$ (:func:`~sphere3d.bsdf.weight_ggx`'s value). The method's rotations
are not applied (the identity's: ``naive``, ``finite_difference``, and ``boundary``, whose edge terms
come through the ``shading_extra`` hook weighted by the BSDF at θ0); ``reparam`` refuses scenes with
glossy shapes (:func:`sphere3d.methods._common.direct_only`). Vectorized over points.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core.dual import Dual, detach
from sphere3d.bsdf import eval_ggx, pdf_ggx, sample_ggx
from sphere3d.integrator import Shading
from sphere3d.live import take_rows
from sphere3d.sampling import sample_mesh, solid_angle_pdf
from sphere3d.tracing import Hits, face_normals, intersect_triangles
from sphere3d.vector import dot, norm, scatter

__all__ = ["GlossySamples", "glossy_samples"]


@dataclass(frozen=True)
class GlossySamples:
    """One MIS estimate of $L_r$ per glossy point, and its BSDF sample for a path to go on along.

    Attributes
    ----------
    radiance : Dual or ndarray, shape (m,)
        The estimate of the reflected radiance towards $w_i$.
    mu : ndarray, shape (m, 3)
        The BSDF samples $w_o$ (plain, unit); ``hits`` their first hits.
    throughput : Dual or ndarray, shape (m,)
        $f(w_i, w_o) (n·w_o) / p_f(w_o)$, $p_f$ θ-free; 0 where $w_o$ lies below the surface.
    above : ndarray of bool, shape (m,)
        Where $w_o$ lies above the surface (a path goes on only there).
    """

    radiance: Any
    mu: np.ndarray
    hits: Hits
    throughput: Any
    above: np.ndarray


def _emitter_term(shading: Shading, wi: Any, u: np.ndarray, alpha: Any, albedo: Any) -> Any:
    r"""Emitter-sampling estimate of $L_r$ with its MIS weight: $L_e f (n·w) w_L / p_{L,0}$."""
    state = shading.state
    m = len(shading)
    emitters = np.asarray(detach(state.triangles))[state.emitters]
    y, k = sample_mesh(u, emitters)
    tri = state.emitters[k]
    to = y - detach(shading.x)
    dist = norm(to)
    w = to / np.where(dist > 0.0, dist, 1.0)[:, None]
    cos_y = -dot(face_normals(emitters)[k], w)
    cos_x = dot(detach(shading.n), w)
    valid = (
        (cos_y > 1e-9)
        & (cos_x > 0.0)
        & (dist > 4.0 * state.epsilon)
        & (dot(detach(wi), detach(shading.n)) > 0)
    )
    idx = np.flatnonzero(valid)
    blocked = state.tracer.occluded(take_rows(shading.origin, idx), w[idx], dist[idx] - 2.0 * state.epsilon)
    vis = idx[~blocked]
    if not vis.size:
        return scatter(m, vis, 0.0, state.dual, k=state.k)
    x, n, d = shading.x[vis], shading.n[vis], w[vis]
    # re-attach: the fixed direction from the moving point meets the (moving) sampled emitter triangle
    it = intersect_triangles(x, d, state.triangles[tri[vis]])
    p_light = solid_angle_pdf(1.0 / state.emitter_area, it.t, -dot(it.normal, d))
    p_bsdf = pdf_ggx(d, wi[vis], n, alpha[vis])
    f = eval_ggx(wi[vis], d, n, alpha[vis], albedo[vis]) * np.maximum(dot(n, d), 0.0)
    f = f * state.emitted(tri[vis], it.b1, it.b2)
    # balance heuristic at θ; divided by the θ-free density p_A d² / cos θ_y, p_A = 1 / area at θ0
    p0 = solid_angle_pdf(1.0 / float(detach(state.emitter_area)), dist[vis], cos_y[vis])
    return scatter(m, vis, f * (p_light / (p_light + p_bsdf)) / p0, state.dual, k=state.k)


def _incident(shading: Shading, wi: Any, mu: np.ndarray, hits: Hits, alpha: Any) -> Any:
    r"""$L_i(w_o)$ along the BSDF samples with the BSDF strategy's MIS weight: the sky (weight 1) where
    they escape, $L_e\, p_f / (p_f + p_L)$ at an emitter's front side, 0 elsewhere."""
    state = shading.state
    m = len(mu)
    out = scatter(m, np.flatnonzero(~hits.hit), state.sky, state.dual, k=state.k)
    e = np.flatnonzero(hits.hit & np.isin(hits.triangle, state.emitters))
    if e.size:
        tri = hits.triangle[e]
        it = intersect_triangles(shading.x[e], mu[e], state.triangles[tri])
        cos_y = -dot(it.normal, mu[e])
        front = detach(cos_y) > 0.0
        e, cos_y, tri, b1, b2, t = e[front], cos_y[front], tri[front], it.b1[front], it.b2[front], it.t[front]
        p_light = solid_angle_pdf(1.0 / state.emitter_area, t, cos_y)
        p_bsdf = pdf_ggx(mu[e], wi[e], shading.n[e], alpha[e])
        out[e] = state.emitted(tri, b1, b2) * (p_bsdf / (p_bsdf + p_light))
    return out


def glossy_samples(
    shading: Shading, wi: Any, u: np.ndarray, alpha: Any, albedo: Any, transforms: Any = None
) -> GlossySamples:
    r"""The MIS estimate of $L_r(w_i)$ at glossy points (module docstring), uniforms ``u`` (m, 5):
    3 for the emitter sample, 2 for the BSDF sample.

    Parameters
    ----------
    shading : Shading
        The points, their θ-dependent positions and unit shading normals.
    wi : Dual or ndarray, shape (m, 3)
        Unit directions towards the camera or the previous vertex.
    alpha, albedo : Dual or ndarray, shape (m,)
        GGX roughness and Fresnel reflectance F per point.
    transforms : Transforms, optional
        The method's: its ``shading_extra`` hook, given the BSDF at θ0 as the weight of its
        directions, adds its derivative-only term (``boundary``'s edges, theory/bsdf); its rotations
        are not used (the identity's: methods that change variables refuse glossy shapes).
    """
    state = shading.state
    total = _emitter_term(shading, wi, u[:, 0:3], alpha, albedo) if len(state.emitters) else 0.0
    n0, wi0, alpha0 = detach(shading.n), detach(wi), detach(alpha)
    mu = sample_ggx(u[:, 3:5], wi0, n0, alpha0)
    p0 = pdf_ggx(mu, wi0, n0, alpha0)
    above = (dot(n0, mu) > 0.0) & (p0 > 0.0) & (dot(wi0, n0) > 0.0)
    hits = shading.trace(mu)
    # f (n·w_o) / p_f with p_f at θ0: value weight_ggx, derivative the integrand's at the fixed sample
    f = eval_ggx(wi, mu, shading.n, alpha, albedo) * np.maximum(dot(shading.n, mu), 0.0)
    throughput = np.where(above, f / np.where(above, p0, 1.0), 0.0)
    radiance = total + throughput * _incident(shading, wi, mu, hits, alpha)
    if transforms is not None and state.dual:
        f0 = (np.asarray(detach(v), dtype=np.float64) for v in (alpha, albedo))
        alpha0, albedo0 = f0
        bsdf = lambda rows, w: eval_ggx(wi0[rows], w, n0[rows], alpha0[rows], albedo0[rows])  # noqa: E731
        extra = transforms.shading_extra(shading, bsdf)
        if extra is not None:  # derivative only: the value is untouched (+ 0.0)
            radiance = radiance + Dual(np.zeros(len(shading)), extra, state.k)
    return GlossySamples(radiance, mu, hits, throughput, above)
