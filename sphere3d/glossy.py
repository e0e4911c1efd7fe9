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
with throughput $f (n·w_o) / p_f$ (:func:`~sphere3d.bsdf.weight_ggx`'s value). A method that changes
variables (``reparam``) turns the emitter sample by its rotation and evaluates the BSDF sample at its
members (:class:`~sphere3d.integrator.Members`), at every vertex of a path, the path going on along
the rotated sample (:mod:`sphere3d.path_changes`); ``boundary``'s edge terms come through the
``shading_extra`` hook, weighted by the BSDF at θ0 (:class:`Lobe`), at every vertex of a path (the jump
of the reflected radiance too, :mod:`sphere3d.boundary.indirect`). Vectorized over points.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core.dual import Dual, detach
from flatland.core.validate import ValidationError
from sphere3d.bsdf import eval_ggx, pdf_ggx, sample_ggx
from sphere3d.integrator import Identity, Shading, add_tangent
from sphere3d.live import take_rows
from sphere3d.sampling import emitter_directions, solid_angle_pdf
from sphere3d.tracing import Hits, intersect_triangles
from sphere3d.vector import dot, scatter

__all__ = ["GlossySamples", "Lobe", "glossy_samples"]


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


@dataclass(frozen=True)
class Lobe:
    """The BSDF of glossy points at θ0 (plain arrays, one row per point), for a method's derivative-only
    terms: :meth:`value` $f(w_i, ω)$ and :meth:`pdf` $p_f(ω)$ at the directions of rows ``rows``."""

    wi: np.ndarray
    n: np.ndarray
    alpha: np.ndarray
    albedo: np.ndarray

    def value(self, rows: np.ndarray, w: np.ndarray) -> np.ndarray:
        """$f(w_i, w)$ of points ``rows`` at directions ``w`` (:func:`~sphere3d.bsdf.eval_ggx`)."""
        return eval_ggx(self.wi[rows], w, self.n[rows], self.alpha[rows], self.albedo[rows])

    def pdf(self, rows: np.ndarray, w: np.ndarray) -> np.ndarray:
        """The BSDF sample's density of points ``rows`` at ``w`` (:func:`~sphere3d.bsdf.pdf_ggx`)."""
        return pdf_ggx(w, self.wi[rows], self.n[rows], self.alpha[rows])


def _changes(transforms: Any, name: str) -> bool:
    """Whether ``transforms`` changes the variables of strategy ``name`` (not the identity's)."""
    return transforms is not None and getattr(type(transforms), name) is not getattr(Identity, name)


def _emitter_term(
    shading: Shading, wi: Any, u: np.ndarray, alpha: Any, albedo: Any, transforms: Any, lobe: Any
) -> Any:
    r"""Emitter-sampling estimate of $L_r$ with its MIS weight: $L_e f (n·w) w_L / p_{L,0}$; under a
    method's rotation R the integrand at $R w$ (value w), plus the method's derivative-only ``extra``."""
    state = shading.state
    m = len(shading)
    e = emitter_directions(
        u, np.asarray(detach(state.triangles))[state.emitters], detach(shading.x), detach(shading.n)
    )
    tri, w, dist, cos_y = state.emitters[e.index], e.w, e.dist, e.cos_y
    valid = (
        (cos_y > 1e-9)
        & (e.cos_x > 0.0)
        & (dist > 4.0 * state.epsilon)
        & (dot(detach(wi), detach(shading.n)) > 0)
    )
    idx = np.flatnonzero(valid)
    blocked = state.tracer.occluded(take_rows(shading.origin, idx), w[idx], dist[idx] - 2.0 * state.epsilon)
    vis = idx[~blocked]
    change = None
    if state.dual and _changes(transforms, "emitter"):
        change = transforms.emitter(shading, np.isin(np.arange(m), vis), lobe)
    if not vis.size:
        out = scatter(m, vis, 0.0, state.dual, k=state.k)
        return out if change is None or change.extra is None else add_tangent(out, *change.extra)
    x, n, d = shading.x[vis], shading.n[vis], w[vis]
    jacobian = None
    if change is not None:  # R(θ) w: value w, the tangent of the method's rotation (Sec. 4.1), or its field's
        place = np.empty(m, dtype=np.intp)
        place[change.rows] = np.arange(len(change.rows))
        d, jacobian = change.directions(place[vis], d)
    # re-attach: the (rotated) direction from the moving point meets the (moving) sampled emitter triangle
    it = intersect_triangles(x, d, state.triangles[tri[vis]])
    p_light = solid_angle_pdf(1.0 / state.emitter_area, it.t, -dot(it.normal, d))
    p_bsdf = pdf_ggx(d, wi[vis], n, alpha[vis])
    f = eval_ggx(wi[vis], d, n, alpha[vis], albedo[vis]) * np.maximum(dot(n, d), 0.0)
    f = f * state.emitted(tri[vis], it.b1, it.b2)
    # balance heuristic at θ; divided by the θ-free density p_A d² / cos θ_y, p_A = 1 / area at θ0
    p0 = solid_angle_pdf(1.0 / float(detach(state.emitter_area)), dist[vis], cos_y[vis])
    f = f * (p_light / (p_light + p_bsdf)) / p0
    out = scatter(m, vis, f if jacobian is None else f * jacobian, state.dual, k=state.k)
    return out if change is None or change.extra is None else add_tangent(out, *change.extra)


def _bsdf_term(
    shading: Shading,
    wi: Any,
    mu: np.ndarray,
    p0: np.ndarray,
    hits: Hits,
    alpha: Any,
    albedo: Any,
    transforms: Any,
    lobe: Lobe,
) -> Any:
    r"""The BSDF-sampling estimate under a method's change of variables
    (:class:`~sphere3d.integrator.Members`; the method is given the points' ``lobe`` at θ0, for a
    kernel that follows its width): $L_i(Rμ) f(w_i, Rμ) (n·Rμ) w_f(Rμ)\, w / p_{f,0}(μ)$ at the
    rows it evaluates, w its kernel weights (value 1; Loubet et al. 2019, Sec. 4.2). The diffuse
    strategy's control variate (``baseline``, written for the cosine density) is not used: an unbiased
    estimate without it."""
    state = shading.state
    members = transforms.bsdf(shading, mu, hits, lobe)
    if members.directions is not None:
        raise ValidationError("paired", "paired kernel samples are not supported on glossy shapes, got True")
    rows = np.arange(len(mu)) if members.rows is None else members.rows
    if not rows.size:
        return scatter(len(mu), rows, 0.0, state.dual, k=state.k)
    sub, d = shading.take(rows), members.rotated
    f = eval_ggx(wi[rows], d, sub.n, alpha[rows], albedo[rows]) * np.maximum(dot(sub.n, d), 0.0)
    est = f * _incident(sub, wi[rows], d, hits.take(rows), alpha[rows]) / p0[rows]
    est = est if members.weights is None else est * members.weights
    return scatter(len(mu), rows, est, state.dual, k=state.k)


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
        The method's: its ``emitter`` rotation turns the emitter sample, its ``bsdf`` members
        evaluate the BSDF sample (``reparam``); its ``shading_extra`` hook, given the BSDF at θ0 as
        the weight of its directions, adds its derivative-only term (``boundary``'s edges, theory/bsdf).
    """
    state = shading.state
    n0, wi0, alpha0 = detach(shading.n), detach(wi), detach(alpha)
    lobe = Lobe(*(np.asarray(v, dtype=np.float64) for v in (wi0, n0, alpha0, detach(albedo))))
    total = (
        _emitter_term(shading, wi, u[:, 0:3], alpha, albedo, transforms, lobe) if len(state.emitters) else 0.0
    )
    mu = sample_ggx(u[:, 3:5], wi0, n0, alpha0)
    p0 = pdf_ggx(mu, wi0, n0, alpha0)
    above = (dot(n0, mu) > 0.0) & (p0 > 0.0) & (dot(wi0, n0) > 0.0)
    hits = shading.trace(mu)
    # f (n·w_o) / p_f with p_f at θ0: value weight_ggx, derivative the integrand's at the fixed sample
    f = eval_ggx(wi, mu, shading.n, alpha, albedo) * np.maximum(dot(shading.n, mu), 0.0)
    throughput = np.where(above, f / np.where(above, p0, 1.0), 0.0)
    if state.dual and _changes(transforms, "bsdf"):
        radiance = total + _bsdf_term(shading, wi, mu, p0, hits, alpha, albedo, transforms, lobe)
    else:
        radiance = total + throughput * _incident(shading, wi, mu, hits, alpha)
    if transforms is not None and state.dual:
        extra = transforms.shading_extra(shading, lobe.value)
        if extra is not None:  # derivative only: the value is untouched (+ 0.0)
            radiance = radiance + Dual(np.zeros(len(shading)), extra, state.k)
    return GlossySamples(radiance, mu, hits, throughput, above)
