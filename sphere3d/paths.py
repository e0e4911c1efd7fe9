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
of 0 that no parameter moves. Under a method that changes the BSDF strategy's variables (``reparam``)
the path goes on along the rotated sample, the throughput carrying the kernel weight
(:mod:`sphere3d.path_changes`). Under ``boundary`` each vertex's hooks are told its number (``at_vertex``):
its edge terms' side paths carry the d - v vertices after vertex v (:mod:`sphere3d.boundary.indirect`).

A scene with glossy shapes (``roughness``, :mod:`sphere3d.glossy`) takes :class:`MixedPaths` at every d,
1 included: each vertex reflects by its own material (a glossy one by
:func:`~sphere3d.glossy.glossy_samples` towards the camera or the previous vertex, throughput
$f \cos / p_f$), the path going on along its cosine or BSDF sample. A scene without them takes the
code above, unchanged.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core.dual import detach
from sphere3d.glossy import glossy_samples
from sphere3d.integrator import INV_PI, Identity, Shading, Transforms, irradiance_samples
from sphere3d.path_changes import Onward, Recorder, Steer, glossy_throughput, path_baseline, recorder, steer
from sphere3d.tracing import Hits, intersect_triangles
from sphere3d.vector import dot, normalize, scatter, zeros

__all__ = ["MixedPaths", "Paths", "carrier", "cosine_ratio", "irradiance_paths", "reflected", "vertex"]

PATH_RAYS = 3
"""Rays per vertex the memory budget counts: the camera's or previous vertex's ray, the emitter
sample's shadow ray and the cosine sample's ray (1 + 2d for d vertices, at most 3d)."""


def cosine_ratio(cosine: Any) -> Any:
    r"""$\cos_θ / \cos_{θ_0}$ of cosine samples (0 where $\cos_{θ_0} \le 0$): value exactly 1, the
    derivative of the cosine in the integrand over the θ-free density $p = \cos_{θ_0} / π$."""
    c0 = detach(cosine)
    ok = c0 > 0.0
    return np.where(ok, cosine / np.where(ok, c0, 1.0), 0.0)


def _onward(shading: Shading, transforms: Any, go_on: bool) -> tuple[Shading, Any, Recorder | None]:
    """The vertex's shading points, transforms and recorder: under a method that changes the BSDF
    strategy's variables, a :class:`~sphere3d.path_changes.Recorder` (kept from the previous vertex), and
    points as :class:`~sphere3d.path_changes.Onward` where the path goes on from them (``go_on``)."""
    rec = transforms if isinstance(transforms, Recorder) else recorder(transforms, shading.state)
    if rec is None:
        return shading, transforms, None
    return (Onward.of(shading) if go_on else shading), rec, rec


def _at(transforms: Any, depth: int) -> Any:
    """``transforms`` told that its hooks run at path vertex ``depth`` (its ``at_vertex``: ``boundary``'s,
    whose edge terms carry the radiance of the vertices after it), else ``transforms`` itself."""
    at = getattr(transforms, "at_vertex", None)
    return transforms if at is None else at(depth)


def _steered(rec: Recorder | None, mu: np.ndarray, k: int | None) -> Steer:
    """Where the samples ``mu`` go on: along the recorded members' rotations (:func:`steer`), else μ."""
    return steer(None if rec is None else rec.take(), mu, k)


def _baseline(
    total: Any, shading: Shading, go: Steer, mu: np.ndarray, scale: Any, depth: int, last: int
) -> Any:
    """``total`` with the control variate of the radiance carried on from vertex ``depth - 1`` subtracted
    (:func:`~sphere3d.path_changes.path_baseline`, derivative only; the value unchanged), the carried
    paths ending at vertex ``last``."""
    term = path_baseline(shading, go, mu, scale, f"bounce.{depth}", carrier(depth, last))
    return total if term is None else total + term


def carrier(depth: int, last: int) -> Callable[[Shading, np.ndarray], Any] | None:
    r"""The ``carry`` of :func:`~sphere3d.path_changes.path_baseline` for a path's vertex ``depth`` of
    ``last``: at the kernel centre's hit (plain), the MIS estimate $\hat E$ with its uniforms plus the
    vertices ``depth + 1`` … ``last`` along its cosine samples (each vertex's own uniforms
    ``"bounce.k"``, those the carried path draws there: common random numbers), as
    :func:`irradiance_paths` at a fixed point. None at the last vertex: the direct $\hat E$ is all the
    carried radiance has.

    Why: the control variate cancels the kernel weight's tangent times the carried radiance only as
    far as $c ≈ π L$; with the direct light alone, the light the further vertices bring (large where
    the next vertex lies in shadow) multiplies that tangent unchecked, whose rate grows without bound
    where a moving point nears a static crease (docs/theory/radiometry.md, "Paths")."""
    if depth >= last:
        return None

    def carry(at: Shading, u: np.ndarray) -> Any:
        e, mu, hits = irradiance_samples(at, u, Identity(), True)
        beta = np.pi * cosine_ratio(dot(at.n, mu))  # cos / p = π cos_θ / cos_θ0 (value π: a plain point)
        walk = _continue_mixed if at.state.glossy.any() else _continue
        return e + walk(at, mu, hits, beta, Identity(), depth + 1, last)

    return carry


def _weighted(beta: Any, go: Steer) -> Any:
    """``beta`` times the kernel weights (value 1) of a steered continuation; ``beta`` without one."""
    return beta if go.weight is None else beta * go.weight


def _reflecting(state: Any, hits: Hits) -> tuple[np.ndarray, Any, np.ndarray]:
    """The shapes the rays ``hits`` met, their albedos, and the rows where a path goes on: a hit whose
    albedo is positive or moves with θ (a path ends on a miss or at an albedo of 0 no parameter moves)."""
    shape = state.shape_of[np.where(hits.hit, hits.triangle, 0)]
    albedo = state.albedo[shape]
    return shape, albedo, np.flatnonzero(hits.hit & ((detach(albedo) > 0.0) | state.albedo_varies[shape]))


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
        _, albedo, keep = _reflecting(state, hits)
        if not keep.size:
            break
        tri, d = hits.triangle[keep], mu[keep]  # d: μ, or Rμ (value μ) under a change of variables
        it = intersect_triangles(shading.x[keep], d, state.triangles[tri])
        # shade the side the ray arrives on: flip the geometric normal where it meets the back
        side = np.where((dot(detach(it.normal), detach(d)) < 0.0)[:, None], 1.0, -1.0)
        normal = state.shading_normals(tri, it.b1, it.b2, it.normal)
        geometric = it.normal * side
        shade_n = geometric if normal is it.normal else normal * side
        shading = Shading.at(state, it.point, shade_n, shading.draws.take(keep), geometric)
        shading, transforms, rec = _onward(shading, transforms, depth < last)
        rows, beta, albedo = rows[keep], beta[keep], albedo[keep]
        u = shading.draws.uniforms(f"bounce.{depth}", 5)  # keyed on (sample, depth): chunking changes nothing
        if depth == last:
            e = irradiance_samples(shading, u, _at(transforms, depth))
        else:
            e, mu, hits = irradiance_samples(shading, u, _at(transforms, depth), True)
        total[rows] = total[rows] + beta * (albedo * INV_PI * e)
        if depth < last:  # a diffuse vertex's cosine sample: f cos / p = ρ cos_θ / cos_θ0 (at Rμ, times w)
            go = _steered(rec, mu, state.k)
            carry = carrier(depth + 1, last)
            cv = path_baseline(shading, go, mu, detach(beta) * detach(albedo), f"bounce.{depth + 1}", carry)
            if cv is not None:
                total[rows] = total[rows] + cv
            beta = _weighted(beta * albedo * cosine_ratio(dot(shading.n, go.direction)), go)
            mu = go.direction
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
        shading, transforms, rec = _onward(shading, transforms, True)
        e, mu, hits = irradiance_samples(shading, u, transforms, True)
        go = _steered(rec, mu, shading.state.k)  # μ, or Rμ with its kernel weight
        beta = _weighted(
            albedo * cosine_ratio(dot(shading.n, go.direction)), go
        )  # (ρ/π) cos_θ / (cos_θ0 / π)
        indirect = _continue(shading, go.direction, hits, beta, transforms, 2, self.max_depth)
        return _baseline(albedo * INV_PI * e + indirect, shading, go, mu, albedo, 2, self.max_depth)


def _arrive(shading: Shading, mu: np.ndarray, hits: Hits, keep: np.ndarray) -> Shading:
    """The next vertices: the hits of rows ``keep`` re-attached to θ (the ray from the moving point to the
    hit triangle), shaded on the side the ray arrives on (as in :func:`_continue`)."""
    state = shading.state
    tri, d = hits.triangle[keep], mu[keep]  # μ, or Rμ (value μ) under a change of variables
    it = intersect_triangles(shading.x[keep], d, state.triangles[tri])
    side = np.where((dot(detach(it.normal), detach(d)) < 0.0)[:, None], 1.0, -1.0)
    normal = state.shading_normals(tri, it.b1, it.b2, it.normal)
    geometric = it.normal * side
    shade_n = geometric if normal is it.normal else normal * side
    return Shading.at(state, it.point, shade_n, shading.draws.take(keep), geometric)


def _reflect(
    shading: Shading,
    wi: Any,
    u: np.ndarray,
    shape: np.ndarray,
    albedo: Any,
    transforms: Transforms,
    depth: int,
    last: int,
):
    r"""Per vertex of either material: (its MIS estimate of the light it reflects towards ``wi``, the
    continuation directions, their hits, the throughput $f \cos / p$, where the path may go on).

    Diffuse rows: $(ρ/π) \hat E$ and the cosine sample (:func:`irradiance_samples`, throughput
    $ρ \cos_θ / \cos_{θ_0}$); glossy rows: :func:`~sphere3d.glossy.glossy_samples` (throughput
    $f \cos / p_f$). Both read the same 5 uniforms per row (``depth``: the vertex's). Under a
    :class:`Recorder` (a change of variables, :class:`~sphere3d.path_changes.Onward` points) the directions
    are $Rμ$ and the throughputs carry the kernel weights (:mod:`sphere3d.path_changes`)."""
    state = shading.state
    m = len(shading)
    rec = transforms if isinstance(transforms, Recorder) and isinstance(shading, Onward) else None
    transforms = _at(transforms, depth)
    radiance = scatter(m, np.arange(0), 0.0, state.dual, k=state.k)
    throughput = scatter(m, np.arange(0), 0.0, state.dual, k=state.k)
    mu, above = zeros((m, 3), rec is not None, state.k), np.ones(m, dtype=bool)
    parts = []
    glossy = state.glossy[shape]
    for rows in (np.flatnonzero(~glossy), np.flatnonzero(glossy)):  # the two materials, not the samples
        if not rows.size:
            continue
        sub = shading.take(rows)
        if glossy[rows[0]]:
            alpha = state.roughness[shape[rows]]
            g = glossy_samples(sub, wi[rows], u[rows], alpha, albedo[rows], transforms)
            radiance[rows], throughput[rows], mu[rows], above[rows] = g.radiance, g.throughput, g.mu, g.above
            if rec is not None:  # f(w_i, Rμ) (n·Rμ) w / p_f(μ), the path going on along Rμ
                go = _steered(rec, g.mu, state.k)
                t = glossy_throughput(sub, wi[rows], g.mu, go.direction, alpha, albedo[rows], g.above)
                throughput[rows], mu[rows] = _weighted(t, go), go.direction
            parts.append((rows, g.hits))
        else:
            e, mu_d, hits_d = irradiance_samples(sub, u[rows], transforms, True)
            go = _steered(rec, mu_d, state.k)
            radiance[rows] = _baseline(
                albedo[rows] * INV_PI * e, sub, go, mu_d, albedo[rows], depth + 1, last
            )
            throughput[rows] = _weighted(albedo[rows] * cosine_ratio(dot(sub.n, go.direction)), go)
            mu[rows] = go.direction
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
        shape, albedo, keep = _reflecting(state, hits)
        if not keep.size:
            break
        wi = -mu[keep]  # towards the previous vertex: the sample's direction (Rμ under a change of variables)
        shading, transforms, _ = _onward(_arrive(shading, mu, hits, keep), transforms, depth < last)
        rows, beta = rows[keep], beta[keep]
        u = shading.draws.uniforms(f"bounce.{depth}", 5)  # keyed on (sample, depth): chunking changes nothing
        radiance, mu, hits, factor, above = _reflect(
            shading, wi, u, shape[keep], albedo[keep], transforms, depth, last
        )
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
        return reflected(shading, wi, u, shape, albedo, transforms, self.max_depth)


def reflected(
    shading: Shading, wi: Any, u: np.ndarray, shape: Any, albedo: Any, transforms: Transforms, max_depth: int
) -> Any:
    r"""The radiance points of either material (``shape``, ``albedo``) reflect towards the unit directions
    ``wi`` along paths of up to ``max_depth`` vertices, the points the first (:class:`MixedPaths`, whose
    $w_i$ points to the camera; ``boundary``'s side paths, :mod:`sphere3d.boundary.indirect`)."""
    if max_depth > 1:
        shading, transforms, _ = _onward(shading, transforms, True)
    radiance, mu, hits, beta, above = _reflect(shading, wi, u, shape, albedo, transforms, 1, max_depth)
    if max_depth == 1:
        return radiance
    hits = Hits(np.where(above, hits.shape, -1), hits.triangle, hits.t, hits.u, hits.v)
    return radiance + _continue_mixed(shading, mu, hits, beta, transforms, 2, max_depth)


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
    shading, transforms, rec = _onward(shading, transforms, True)
    e, mu, hits = irradiance_samples(shading, u, transforms, True)
    go = _steered(rec, mu, shading.state.k)
    beta = _weighted(np.pi * cosine_ratio(dot(shading.n, go.direction)), go)
    walk = _continue_mixed if shading.state.glossy.any() else _continue
    return _baseline(
        e + walk(shading, go.direction, hits, beta, transforms, 2, max_depth),
        shading,
        go,
        mu,
        np.pi,
        2,
        max_depth,
    )
