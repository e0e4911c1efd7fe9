"""The renderer's integrals, written once, with the change of variables left to the method.

Three nested integrals per pixel (direct illumination only):

1. **Pixel integral** over the film, ``∫ k(s) L(ω(s)) ds``, written over directions
   ``∫ k(film(ω)) J(ω) L(ω) dω`` (J: film area per solid angle). Film offsets are
   drawn from :func:`~sphere3d.sampling.sample_filter` and weighted by k / p; a
   method may rotate their directions, ω → R·ω_i, and the factor
   ``k J (Rω) / detach(k J (Rω))`` (value exactly 1) carries the change of the
   filter under the rotation (Loubet et al. 2019, Sec. 4.1; theory/pixel_filters). Its
   tangent has zero mean, which :class:`~sphere3d.tasks.ImageTask` uses as a
   control variate.
2. **Radiance** along the ray: the sky where it misses; at a hit, front-side emission
   (with the border fade) plus ``ρ/π · E`` for diffuse surfaces.
3. **Irradiance** ``E = ∫ L_i(ω) cos θ dω`` at the hit point, by multiple importance
   sampling (balance heuristic) of two strategies:

   - *emitter sampling*: a point y uniform on the emitters' area, its direction ω and
     the solid-angle density ``p_L = d² / (A cos θ_y)``; a method may rotate ω;
     the emitter hit is re-attached to the triangle the sample lies on;
   - *cosine sampling*: ω ~ cos θ / π; the method owns this estimator (it may add a
     convolution kernel, Sec. 4.2) and calls back :meth:`Shading.evaluate_bsdf`
     for the integrand at rotated directions.

   The MIS weights are evaluated at the (rotated) direction with θ-dependent
   geometry, so the two weights sum to 1 for every θ, as the decomposition of the
   integral needs; the estimators divide by the θ-free sampling densities.

A method is a :class:`Transforms` object: ``naive`` returns identity rotations, so
this module alone is the naive estimator; ``reparam`` returns rotations chosen by
probe rays. Every method reads the primary samples from the same uniforms, so the
primal is the same, bit for bit (:mod:`flatland.core.rng`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from flatland.core.dual import Dual, detach
from flatland.core.rng import Draws
from flatland.core.translation import unit_weight
from sphere3d.rotation import Rotation
from sphere3d.sampling import (
    filter_value,
    log_filter_value,
    pdf_cosine_hemisphere,
    pdf_filter,
    sample_cosine_hemisphere,
    sample_filter,
    sample_mesh,
    solid_angle_pdf,
)
from sphere3d.state import SceneState
from sphere3d.tracing import Hits, face_normals, intersect_triangles
from sphere3d.vector import dot, norm, scatter

__all__ = [
    "PRIMARY_UNIFORMS",
    "Identity",
    "PixelSamples",
    "Shading",
    "Transforms",
    "camera_radiance",
    "irradiance_samples",
    "pixel_samples",
]

PRIMARY_UNIFORMS = 7
"""Uniforms per camera sample: film offset (2), emitter sample (3), cosine sample (2)."""
INV_PI = 1.0 / np.pi


@dataclass(frozen=True)
class Shading:
    """Shading points: position x and shading normal n (θ-dependent), and the detached ray origin.

    ``origin = detach(x) + ε n_g`` (n_g: the geometric normal, n itself unless given)
    keeps rays from re-hitting the surface they leave; re-attached quantities use x itself.
    """

    state: SceneState
    x: Any
    n: Any
    origin: np.ndarray
    draws: Draws

    @staticmethod
    def at(state: SceneState, x: Any, n: Any, draws: Draws, geometric: Any = None) -> Shading:
        """Shading points ``x``, shading normals ``n`` (offset along the ``geometric`` normals when
        given); ``draws`` keys their random numbers on their samples."""
        offset = detach(n if geometric is None else geometric)
        return Shading(state, x, n, detach(x) + state.epsilon * offset, draws)

    def __len__(self) -> int:
        return len(self.origin)

    def take(self, index: np.ndarray) -> Shading:
        return Shading(self.state, self.x[index], self.n[index], self.origin[index], self.draws.take(index))

    def trace(self, mu: np.ndarray) -> Hits:
        """First hits along directions ``mu`` from the shading points (detached)."""
        return self.state.tracer.intersect(self.origin, mu)

    def contributes(self, mu: np.ndarray, hits: Hits) -> np.ndarray:
        """Where the cosine-strategy integrand can be non-zero near θ0: above the surface, and the
        ray escapes to a non-zero sky or reaches the front of an emitter.

        Elsewhere the integrand :meth:`evaluate_bsdf` computes is 0 with zero derivative,
        whatever the rotation, so a method may skip those samples.
        """
        state = self.state
        up = dot(detach(self.n), mu) > 0.0
        sky = (float(detach(state.sky)) != 0.0) or state.param == "sky.emission"
        emitting = hits.hit & np.isin(hits.triangle, state.emitters)
        tri = np.asarray(detach(state.triangles))[np.where(emitting, hits.triangle, 0)]
        front = dot(face_normals(tri), mu) < 0.0
        return up & ((~hits.hit & sky) | (emitting & front))

    def evaluate_bsdf(self, mu: np.ndarray, rotated: Any, hits: Hits) -> Any:
        """The cosine-strategy integrand ``L_i(Rμ) cos θ(Rμ) w_C(Rμ)`` at rotated directions.

        Parameters
        ----------
        mu : ndarray, shape (m, 3)
            Directions drawn independently of θ, along which ``hits`` were traced.
        rotated : Dual or ndarray, shape (m, 3)
            R·μ (value μ); the integrand is re-attached along it.
        hits : Hits, shape (m,)
            :meth:`trace` of ``mu``.
        """
        state = self.state
        m = len(mu)
        cos_x = np.maximum(dot(self.n, rotated), 0.0)
        up = detach(cos_x) > 0.0
        out = scatter(m, np.flatnonzero(up & ~hits.hit), state.sky, state.dual)  # sky: p_L = 0, so w_C = 1
        e = np.flatnonzero(up & hits.hit & np.isin(hits.triangle, state.emitters))
        if e.size:
            tri = hits.triangle[e]
            it = intersect_triangles(self.x[e], rotated[e], state.triangles[tri])
            cos_y = -dot(it.normal, rotated[e])
            front = detach(cos_y) > 0.0
            e, cos_y, tri = e[front], cos_y[front], tri[front]
            it_t, b1, b2 = it.t[front], it.b1[front], it.b2[front]
            p_light = solid_angle_pdf(1.0 / state.emitter_area, it_t, cos_y)
            p_cos = cos_x[e] * INV_PI
            # balance heuristic at the rotated direction, θ-dependent on both sides   (MIS, see module doc)
            out[e] = state.emitted(tri, b1, b2) * (p_cos / (p_cos + p_light))
        return out * cos_x


@dataclass(frozen=True)
class PixelSamples:
    """Per camera sample: the radiance L(Rω) and the filter weight ``k/p · kJ(Rω)/detach(kJ(Rω))``.

    The estimate of the pixel integral is ``radiance * weight``; the weight's tangent
    has zero mean for a continuous filter (the filter integrates to 1 whatever the
    rotation), which :class:`~sphere3d.tasks.ImageTask` uses as a control variate.
    """

    radiance: Any
    weight: Any

    @property
    def estimate(self) -> Any:
        return self.radiance * self.weight


class Transforms(Protocol):
    """How a method changes variables in the renderer's integrals (see the module docstring)."""

    def camera(self, state: SceneState, rows: np.ndarray, cols: np.ndarray, u: np.ndarray) -> Rotation:
        """One rotation per (batch, pixel) of the pixel integral, given one uniform ``u`` each."""
        ...

    def emitter(self, shading: Shading) -> Rotation:
        """One rotation per shading point for the emitter-sampling strategy (draws: ``shading.draws``)."""
        ...

    def bsdf(self, shading: Shading, mu: np.ndarray, pdf: np.ndarray) -> Any:
        """The per-sample estimate of the cosine-sampled integral (samples μ ~ cos, density ``pdf``),
        using :meth:`Shading.trace` and :meth:`Shading.evaluate_bsdf` for the integrand (a method
        that evaluates it elsewhere than along μ need not trace μ). Random numbers come from
        ``shading.draws``, keyed on each point's camera sample."""
        ...


class Identity:
    """No change of variables: the renderer as it stands (the naive estimator, Sec. 3.1)."""

    def camera(self, state: SceneState, rows: np.ndarray, cols: np.ndarray, u: np.ndarray) -> Rotation:
        return Rotation.identity(rows.shape)

    def emitter(self, shading: Shading) -> Rotation:
        return Rotation.identity((len(shading),))

    def bsdf(self, shading, mu, pdf):
        rotated = mu if not shading.state.dual else Dual(mu)
        return shading.evaluate_bsdf(mu, rotated, shading.trace(mu)) / pdf


def _emitter_term(shading: Shading, u: np.ndarray, transforms: Transforms) -> Any:
    """Emitter-sampling estimate of E, MIS-weighted, per shading point."""
    state = shading.state
    m = len(shading)
    emitters = np.asarray(detach(state.triangles))[state.emitters]
    y, k = sample_mesh(u, emitters)
    tri = state.emitters[k]
    xv = detach(shading.x)
    to = y - xv
    dist = norm(to)
    safe = np.where(dist > 0.0, dist, 1.0)
    w = to / safe[:, None]
    cos_y = -dot(face_normals(emitters[k]), w)
    cos_x = dot(detach(shading.n), w)
    valid = (cos_y > 1e-9) & (cos_x > 0.0) & (dist > 4.0 * state.epsilon)
    idx = np.flatnonzero(valid)
    blocked = state.tracer.occluded(shading.origin[idx], w[idx], dist[idx] - 2.0 * state.epsilon)
    vis = idx[~blocked]
    if vis.size == 0:
        return scatter(m, vis, 0.0, state.dual)
    # θ-free sampling density in solid angle: p_A d² / cos θ_y, p_A = 1 / area at θ0
    pdf = solid_angle_pdf(1.0 / float(detach(state.emitter_area)), dist[vis], cos_y[vis])
    sub = shading.take(vis)
    rotated = transforms.emitter(sub).apply(w[vis])
    # re-attach: the rotated ray from the moving shading point meets the sampled emitter triangle
    it = intersect_triangles(sub.x, rotated, state.triangles[tri[vis]])
    cos_x_d = np.maximum(dot(sub.n, rotated), 0.0)
    cos_y_d = -dot(it.normal, rotated)
    p_light = solid_angle_pdf(1.0 / state.emitter_area, it.t, cos_y_d)
    p_cos = cos_x_d * INV_PI
    f = state.emitted(tri[vis], it.b1, it.b2) * cos_x_d
    return scatter(m, vis, f * (p_light / (p_light + p_cos)) / pdf, state.dual)


def irradiance_samples(shading: Shading, u: np.ndarray, transforms: Transforms) -> Any:
    """One MIS estimate of ``E = ∫ L_i cos θ dω`` per shading point (uniforms ``u``: 3 emitter + 2 cosine)."""
    state = shading.state
    total = 0.0
    if len(state.emitters):
        total = total + _emitter_term(shading, u[:, 0:3], transforms)
    n0 = detach(shading.n)
    mu = sample_cosine_hemisphere(u[:, 3:5], n0)
    pdf = pdf_cosine_hemisphere(mu, n0)
    return total + transforms.bsdf(shading, mu, pdf)


def pixel_samples(
    state: SceneState,
    transforms: Transforms,
    rows: np.ndarray,
    cols: np.ndarray,
    u: np.ndarray,
    camera_rotation: Rotation,
    draws: Draws,
) -> Any:
    """One estimate of the pixel integral per sample (pixel ``rows``, ``cols``; uniforms ``u``).

    ``camera_rotation`` holds one rotation per sample (its pixel's). The estimate is
    ``radiance * weight`` (:class:`PixelSamples`); both are Duals when the state
    carries tangents. ``draws`` keys the samples' further random numbers on their indices.
    """
    cam = state.camera
    offsets = sample_filter(u[:, 0:2], cam.filter)
    weight = filter_value(offsets, cam.filter) / pdf_filter(offsets, cam.filter)  # k / p, θ-free
    cx, cy = cols + 0.5, rows + 0.5
    d = cam.directions(cx + offsets[:, 0], cy + offsets[:, 1])
    if state.dual:
        rotated = camera_rotation.apply(d)
        fx, fy = cam.film(rotated)
        # k(film(Rω)) J(Rω) / detach(...): value 1, derivative of the filter under the rotation
        # (theory/pixel_filters)
        log_kj = log_filter_value(np.stack([fx - cx, fy - cy], axis=-1), cam.filter) + cam.log_jacobian(
            rotated
        )
        weight = weight * unit_weight(log_kj)
    else:
        rotated = d
    return PixelSamples(camera_radiance(state, transforms, d, rotated, u[:, 2:7], draws), weight)


def camera_radiance(
    state: SceneState,
    transforms: Transforms,
    d: np.ndarray,
    rotated: Any,
    u: np.ndarray,
    draws: Draws,
    hits: Hits | None = None,
) -> Any:
    """Radiance arriving at the camera along unit directions ``d`` (plain), re-attached along ``rotated``.

    Emission of the first hit's front side plus ``ρ/π E`` at diffuse hits, E estimated
    with the shading uniforms ``u`` (n, 5) under ``transforms``; the sky where a ray misses.
    ``hits``: the rays' hits if the caller knows them (only ``shape`` and ``triangle`` are
    read), else they are traced.
    """
    n = len(d)
    cam = state.camera
    if hits is None:
        hits = state.tracer.intersect(detach(cam.origin), d)
    hit = np.flatnonzero(hits.hit)
    miss = np.flatnonzero(~hits.hit)
    radiance = scatter(n, miss, state.sky, state.dual)
    if hit.size:
        tri = hits.triangle[hit]
        it = intersect_triangles(cam.origin, rotated[hit], state.triangles[tri])
        facing = dot(detach(it.normal), detach(rotated)[hit])  # only its value is used
        front = facing < 0.0  # the ray arrives on the side the normal faces
        side = np.where(front[:, None], 1.0, -1.0)
        geometric = it.normal * side
        # smooth shapes shade with interpolated vertex normals; face normals otherwise (the same object)
        normal = state.shading_normals(tri, it.b1, it.b2, it.normal)
        shade_n = geometric if normal is it.normal else normal * side
        shape = state.shape_of[tri]
        value = state.emitted(tri, it.b1, it.b2) * front
        albedo = state.albedo[shape]
        diffuse = (detach(albedo) > 0.0) | (state.param is not None and state.param.endswith(".albedo"))
        s = np.flatnonzero(diffuse)
        if s.size:
            shading = Shading.at(state, it.point[s], shade_n[s], draws.take(hit[s]), geometric[s])
            e = irradiance_samples(shading, u[hit[s]], transforms)
            value = value + scatter(hit.size, s, albedo[s] * INV_PI * e, state.dual)
        radiance[hit] = value
    return radiance
