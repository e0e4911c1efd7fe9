r"""Light paths of up to ``max_depth`` vertices (theory/radiometry, "Paths"; glossy ones: theory/bsdf).

With ``max_depth`` d = 1 the renderer is direct illumination (:mod:`sphere3d.integrator`), and nothing
here runs. With d > 1 a path goes on from every diffuse shading point along its cosine sample (the
BSDF sample the shading's MIS already traced, reused), and each further diffuse vertex y adds
$β (ρ_y / π) \hat E(y)$, $\hat E$ the same MIS estimate (emitter and cosine sampling, balance
heuristic, :func:`~sphere3d.integrator.irradiance_samples`), up to d vertices:
$L = L_e + \mathcal{T} L_e + … + \mathcal{T}^d L_e$. The emission a continuation ray meets is
counted once, inside the previous vertex's $\hat E$ with its MIS weight; the vertex there adds only
what it reflects. Throughput: a diffuse vertex's cosine sample weighs
$f \cos / p = (ρ/π) \cos_θ / (\cos_{θ_0} / π) = ρ \cos_θ / \cos_{θ_0}$ (value exactly ρ: the
derivative of the moving normal's cosine over the θ-free density, :func:`cosine_ratio`).

Vectorized over all paths; a loop over depth only. Vertex k's uniforms are the stream ``"bounce.k"``
keyed on the primary sample (:class:`~flatland.core.rng.Draws`), so images do not depend on chunking
or threads. No Russian roulette (no bias, no early end): a path ends at d, on a miss, or at an albedo
of 0 that no parameter moves. Only the identity transforms (``naive``, ``finite_difference``) continue
paths; ``reparam`` and ``boundary`` refuse d > 1 (:func:`sphere3d.methods._common.direct_only`).

A scene with glossy shapes (``roughness``, :mod:`sphere3d.glossy`) takes :class:`MixedPaths` at every d,
1 included: each vertex reflects by its own material (a glossy one by
:func:`~sphere3d.glossy.glossy_samples` towards the camera or the previous vertex, throughput
$f \cos / p_f$), the path going on along its cosine or BSDF sample. A scene without them takes the
code above, unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core.dual import detach
from sphere3d.glossy import glossy_samples
from sphere3d.integrator import INV_PI, Shading, Transforms, irradiance_samples
from sphere3d.tracing import Hits, intersect_triangles
from sphere3d.vector import dot, normalize, scatter

__all__ = ["MixedPaths", "Paths", "cosine_ratio", "irradiance_paths", "vertex"]

PATH_RAYS = 3
"""Rays per vertex the memory budget counts: the camera's or previous vertex's ray, the emitter
sample's shadow ray and the cosine sample's ray (1 + 2d for d vertices, at most 3d)."""


def cosine_ratio(cosine: Any) -> Any:
    r"""$\cos_θ / \cos_{θ_0}$ of cosine samples (0 where $\cos_{θ_0} \le 0$): value exactly 1, the
    derivative of the cosine in the integrand over the θ-free density $p = \cos_{θ_0} / π$."""
    c0 = detach(cosine)
    ok = c0 > 0.0
    return np.where(ok, cosine / np.where(ok, c0, 1.0), 0.0)


def _continue(
    shading: Shading, mu: np.ndarray, hits: Hits, beta: Any, transforms: Transforms, depth: int, last: int
) -> Any:
    r"""The radiance vertices ``depth`` … ``last`` add to each of ``shading``'s points, the paths leaving
    them along their cosine samples ``mu`` (first ``hits``) with throughput ``beta``.

    Vertex k re-attaches the hit to θ (the ray from the moving point to the hit triangle), shades the side
    the ray arrives on, and adds $β_k (ρ/π) \hat E$; the path goes on with
    $β_{k+1} = β_k ρ \cos_θ / \cos_{θ_0}$.
    """
    state = shading.state
    total = scatter(len(shading), np.arange(0), 0.0, state.dual, k=state.k)
    rows = np.arange(len(shading))
    while depth <= last:
        shape = state.shape_of[np.where(hits.hit, hits.triangle, 0)]
        albedo = state.albedo[shape]
        keep = np.flatnonzero(hits.hit & ((detach(albedo) > 0.0) | state.albedo_varies[shape]))
        if not keep.size:
            break
        tri, d = hits.triangle[keep], mu[keep]
        it = intersect_triangles(shading.x[keep], d, state.triangles[tri])
        # shade the side the ray arrives on: flip the geometric normal where it meets the back
        side = np.where((dot(detach(it.normal), d) < 0.0)[:, None], 1.0, -1.0)
        normal = state.shading_normals(tri, it.b1, it.b2, it.normal)
        geometric = it.normal * side
        shade_n = geometric if normal is it.normal else normal * side
        shading = Shading.at(state, it.point, shade_n, shading.draws.take(keep), geometric)
        rows, beta, albedo = rows[keep], beta[keep], albedo[keep]
        u = shading.draws.uniforms(f"bounce.{depth}", 5)  # keyed on (sample, depth): chunking changes nothing
        if depth == last:
            e = irradiance_samples(shading, u, transforms)
        else:
            e, mu, hits = irradiance_samples(shading, u, transforms, True)
        total[rows] = total[rows] + beta * (albedo * INV_PI * e)
        if depth < last:  # a diffuse vertex's cosine sample: f cos / p = ρ cos_θ / cos_θ0
            beta = beta * albedo * cosine_ratio(dot(shading.n, mu))
        depth += 1
    return total


@dataclass(frozen=True)
class Paths:
    r"""A diffuse vertex of the camera's paths (``vertex`` of :func:`~sphere3d.integrator.camera_radiance`):
    the direct $ρ/π\, E$ plus the vertices 2 … ``max_depth`` of the paths leaving along its cosine samples."""

    max_depth: int

    def __call__(
        self, shading: Shading, u: np.ndarray, albedo: Any, transforms: Transforms, shape: Any = None
    ) -> Any:
        e, mu, hits = irradiance_samples(shading, u, transforms, True)
        beta = albedo * cosine_ratio(dot(shading.n, mu))  # (ρ/π) cos_θ / (cos_θ0 / π)
        indirect = _continue(shading, mu, hits, beta, transforms, 2, self.max_depth)
        return albedo * INV_PI * e + indirect


def _arrive(shading: Shading, mu: np.ndarray, hits: Hits, keep: np.ndarray) -> Shading:
    """The next vertices: the hits of rows ``keep`` re-attached to θ (the ray from the moving point to the
    hit triangle), shaded on the side the ray arrives on (as in :func:`_continue`)."""
    state = shading.state
    tri, d = hits.triangle[keep], mu[keep]
    it = intersect_triangles(shading.x[keep], d, state.triangles[tri])
    side = np.where((dot(detach(it.normal), d) < 0.0)[:, None], 1.0, -1.0)
    normal = state.shading_normals(tri, it.b1, it.b2, it.normal)
    geometric = it.normal * side
    shade_n = geometric if normal is it.normal else normal * side
    return Shading.at(state, it.point, shade_n, shading.draws.take(keep), geometric)


def _reflect(
    shading: Shading, wi: Any, u: np.ndarray, shape: np.ndarray, albedo: Any, transforms: Transforms
):
    r"""Per vertex of either material: (its MIS estimate of the light it reflects towards ``wi``, the
    continuation directions, their hits, the throughput $f \cos / p$, where the path may go on).

    Diffuse rows: $(ρ/π) \hat E$ and the cosine sample (:func:`irradiance_samples`, throughput
    $ρ \cos_θ / \cos_{θ_0}$); glossy rows: :func:`~sphere3d.glossy.glossy_samples` (throughput
    $f \cos / p_f$). Both read the same 5 uniforms per row."""
    state = shading.state
    m = len(shading)
    radiance = scatter(m, np.arange(0), 0.0, state.dual, k=state.k)
    throughput = scatter(m, np.arange(0), 0.0, state.dual, k=state.k)
    mu, above = np.zeros((m, 3)), np.ones(m, dtype=bool)
    parts = []
    glossy = state.glossy[shape]
    for rows in (np.flatnonzero(~glossy), np.flatnonzero(glossy)):  # the two materials, not the samples
        if not rows.size:
            continue
        sub = shading.take(rows)
        if glossy[rows[0]]:
            g = glossy_samples(sub, wi[rows], u[rows], state.roughness[shape[rows]], albedo[rows], transforms)
            radiance[rows], throughput[rows], mu[rows], above[rows] = g.radiance, g.throughput, g.mu, g.above
            parts.append((rows, g.hits))
        else:
            e, mu_d, hits_d = irradiance_samples(sub, u[rows], transforms, True)
            radiance[rows] = albedo[rows] * INV_PI * e
            throughput[rows] = albedo[rows] * cosine_ratio(dot(sub.n, mu_d))
            mu[rows] = mu_d
            parts.append((rows, hits_d))
    fields = {}
    for name in ("shape", "triangle", "t", "u", "v"):
        column = np.zeros(m, dtype=getattr(parts[0][1], name).dtype)
        for rows, h in parts:
            column[rows] = getattr(h, name)
        fields[name] = column
    return radiance, mu, Hits(**fields), throughput, above


def _continue_mixed(
    shading: Shading, mu: np.ndarray, hits: Hits, beta: Any, transforms: Transforms, depth: int, last: int
) -> Any:
    r""":func:`_continue` for scenes with glossy shapes: each vertex reflects by its own material
    (:func:`_reflect`, towards $w_i = -μ$), the path going on along its BSDF or cosine sample with
    $β_{k+1} = β_k f \cos / p$; rows whose sample left below a glossy surface end."""
    state = shading.state
    total = scatter(len(shading), np.arange(0), 0.0, state.dual, k=state.k)
    rows = np.arange(len(shading))
    while depth <= last:
        shape = state.shape_of[np.where(hits.hit, hits.triangle, 0)]
        albedo = state.albedo[shape]
        keep = np.flatnonzero(hits.hit & ((detach(albedo) > 0.0) | state.albedo_varies[shape]))
        if not keep.size:
            break
        wi = -mu[keep]  # towards the previous vertex: the fixed direction of the sample
        shading = _arrive(shading, mu, hits, keep)
        rows, beta = rows[keep], beta[keep]
        u = shading.draws.uniforms(f"bounce.{depth}", 5)  # keyed on (sample, depth): chunking changes nothing
        radiance, mu, hits, factor, above = _reflect(shading, wi, u, shape[keep], albedo[keep], transforms)
        total[rows] = total[rows] + beta * radiance
        beta = beta * factor
        hits = Hits(np.where(above, hits.shape, -1), hits.triangle, hits.t, hits.u, hits.v)
        depth += 1
    return total


@dataclass(frozen=True)
class MixedPaths:
    r"""A camera path's first vertex in a scene with glossy shapes (any ``max_depth``, 1 included): each
    hit reflects by its material towards the camera ($w_i$ the unit vector from the θ-dependent point to
    the camera), and paths of d > 1 vertices go on by :func:`_continue_mixed`."""

    max_depth: int

    def __call__(
        self, shading: Shading, u: np.ndarray, albedo: Any, transforms: Transforms, shape: Any
    ) -> Any:
        wi = normalize(shading.state.camera.origin - shading.x)
        radiance, mu, hits, beta, above = _reflect(shading, wi, u, shape, albedo, transforms)
        if self.max_depth == 1:
            return radiance
        hits = Hits(np.where(above, hits.shape, -1), hits.triangle, hits.t, hits.u, hits.v)
        return radiance + _continue_mixed(shading, mu, hits, beta, transforms, 2, self.max_depth)


def vertex(max_depth: int, state: Any = None) -> Paths | MixedPaths | None:
    """The ``vertex`` argument of :func:`~sphere3d.integrator.pixel_samples` for paths of ``max_depth``
    vertices in ``state``'s scene: :class:`MixedPaths` if it has glossy shapes; else None (direct
    illumination, bit for bit) for 1, :class:`Paths` beyond."""
    if state is not None and state.glossy.any():
        return MixedPaths(max_depth)
    return Paths(max_depth) if max_depth > 1 else None


def irradiance_paths(shading: Shading, u: np.ndarray, transforms: Transforms, max_depth: int) -> Any:
    r"""$\hat E$ at fixed points whose incident radiance carries paths of up to ``max_depth`` - 1 further
    diffuse vertices: the MIS estimate plus the cosine samples' continuations, throughput
    $\cos / p = π \cos_θ / \cos_{θ_0}$ (the point's normal does not move: value π)."""
    if max_depth == 1:
        return irradiance_samples(shading, u, transforms)
    e, mu, hits = irradiance_samples(shading, u, transforms, True)
    beta = np.pi * cosine_ratio(dot(shading.n, mu))
    walk = _continue_mixed if shading.state.glossy.any() else _continue
    return e + walk(shading, mu, hits, beta, transforms, 2, max_depth)
