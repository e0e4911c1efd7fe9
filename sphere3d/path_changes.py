r"""A method's change of variables carried along a light path (theory/radiometry, "Paths").

At a path vertex x the shading integral's BSDF (or cosine) strategy draws μ independently of θ and
the integrand is everything that arrives along it: the emission the sample meets *and* the radiance
the next vertex reflects. A method that changes variables (``reparam``) evaluates the integrand at
$R(θ) μ$ times its kernel weight w (value 1; Loubet et al. 2019, Sec. 4.1-4.2), so the path must go on
along the same rotated direction, as the authors' path reparameterization does: the next
vertex is re-attached to θ where the ray from the moving x along $Rμ$ meets the hit triangle (value:
the hit along μ, bit for bit), its incoming direction is $-Rμ$, and the throughput carries the
integrand's factors at $Rμ$ and w:

$β_{k+1} = β_k\, f(w_i, Rμ)\, (n·Rμ)\, w / p(μ)$

(diffuse: $ρ\, (n·Rμ) / (n_0·μ)$ times w). Every value is the naive one, bit for bit; only tangents
change. The rotations are the ones the vertex's shading integral already chose: :class:`Recorder`
keeps the :class:`~sphere3d.integrator.Members` the method's ``bsdf`` hook returned, and the vertex's
points as :class:`Onward` make the hook give a rotation to every sample whose path goes on (not only
to those that reach an emitter or the sky).

A sample the hook gave no rotation (its integrand and its path are 0) keeps μ, the identity. Paired
kernel samples (members traced along other directions than μ) have no single direction to go on
along and are refused by the method at depth > 1.

**Control variate of the carried radiance** (:func:`path_baseline`). The kernel weight's tangent
$\dot w = κ\, \dot R μ · ω$ has zero mean given the kernel's centre ω but is large (of order $\sqrt κ$
times the rotation's rate), and at depth > 1 it multiplies the whole radiance the path brings back,
which under a diffuse vertex is smooth and large: without help the gradient's standard error grows
about twentyfold on ``interreflection`` (docs/theory/radiometry, "Paths"). As for the sky
(theory/kernels), $c\, (q - \mathrm{detach}(q)) / p(μ)$, $q = p(Rμ)\, w$ (value 0, zero mean given
ω), is subtracted with $c = π \hat L(ω)$ any estimate that does not depend on μ given ω: here the
diffuse light the surface the kernel's centre hits reflects by one emitter-and-cosine MIS estimate at
that point, with the next vertex's own uniforms (common random numbers with the carried radiance,
which they do not make depend on μ). On paths of more vertices the carried radiance is also the
light the further vertices bring, so $\hat L(ω)$ is the whole path's: from the centre's hit the
estimate goes on along its cosine samples to the last vertex, every vertex with the uniforms the
carried path draws there (:func:`sphere3d.paths.carrier`). Without that the further light, large
where the next vertex lies in shadow, multiplies $\dot w$ unchecked, and $\dot w$ has no bound
where a moving point nears a static crease (docs/theory/radiometry, "Paths"). Unbiased whatever
c is; it only lowers the variance where $c ≈ π L$. Where $\dot q = 0$ (a sample whose rotation and
weight do not move: most, where the kernels see no moving triangle) the term is 0 whatever c, and c is
not estimated there. Not applied at glossy vertices (their samples' density is not the cosine one).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flatland.core.dual import Dual, detach, tangent
from sphere3d.bsdf import eval_ggx, pdf_ggx
from sphere3d.integrator import Identity, Members, Shading, irradiance_samples
from sphere3d.live import moves
from sphere3d.state import SceneState
from sphere3d.tracing import intersect_triangles
from sphere3d.vector import dot

__all__ = ["Onward", "Recorder", "Steer", "glossy_throughput", "path_baseline", "recorder", "steer"]


class Onward(Shading):
    """Shading points whose cosine (or BSDF) samples' paths go on: their integrand is also the radiance
    any reflecting surface they hit sends back, so :meth:`contributes` adds the samples that hit a
    surface of albedo > 0 (or varying), which the path goes on from. A subclass of the frozen
    dataclass :class:`~sphere3d.integrator.Shading` with its fields and constructor (no field of
    its own)."""

    @staticmethod
    def of(shading: Shading) -> Onward:
        return Onward(shading.state, shading.x, shading.n, shading.origin, shading.draws, shading.geometric)

    def contributes(self, mu: np.ndarray, hits: Any) -> np.ndarray:
        state = self.state
        shape = state.shape_of[np.where(hits.hit, hits.triangle, 0)]
        reflects = (detach(state.albedo)[shape] > 0.0) | state.albedo_varies[shape]
        up = dot(detach(self.n), mu) > 0.0
        return super().contributes(mu, hits) | (up & hits.hit & reflects)


@dataclass
class Recorder:
    """A method's :class:`~sphere3d.integrator.Transforms` that remembers the last
    :class:`~sphere3d.integrator.Members` its ``bsdf`` hook returned (every other hook passes through).

    One per path vertex call, read right after the shading integral that filled it."""

    inner: Any
    members: Members | None = field(default=None)

    def camera(self, *args: Any) -> Any:
        return self.inner.camera(*args)

    def emitter(self, *args: Any) -> Any:
        return self.inner.emitter(*args)

    def bsdf(self, shading: Any, mu: np.ndarray, hits: Any, lobe: Any = None) -> Members:
        self.members = (
            self.inner.bsdf(shading, mu, hits) if lobe is None else self.inner.bsdf(shading, mu, hits, lobe)
        )
        return self.members

    def shading_extra(self, *args: Any) -> Any:
        return self.inner.shading_extra(*args)

    def pixel_extra(self, *args: Any) -> Any:
        return self.inner.pixel_extra(*args)

    def take(self) -> Members | None:
        """The recorded members, and forget them (the next call records its own)."""
        members, self.members = self.members, None
        return members


def recorder(transforms: Any, state: SceneState) -> Recorder | None:
    """A :class:`Recorder` around ``transforms`` if it changes the BSDF strategy's variables and the state
    carries tangents; None otherwise (paths then go on along μ, as the naive estimator's)."""
    changes = getattr(type(transforms), "bsdf", None) is not Identity.bsdf
    return Recorder(transforms) if state.dual and changes else None


@dataclass(frozen=True)
class Steer:
    r"""Where m paths go on: the directions $Rμ$ (Dual, value μ) and the kernel weights w (Dual, value 1),
    or μ itself and None without a change of variables."""

    direction: Any
    weight: Any = None
    members: Members | None = None


def steer(members: Members | None, mu: np.ndarray, k: int | None) -> Steer:
    """The direction and weight every sample of ``mu`` (m, 3) goes on with under ``members`` (None: μ)."""
    if members is None:
        return Steer(mu)
    if members.directions is not None:
        raise ValueError("paired kernel samples have no single direction for a path to go on along")
    m = len(mu)
    rows = np.arange(m) if members.rows is None else members.rows
    direction = Dual(np.array(mu, dtype=np.float64), None, k)
    direction[rows] = members.rotated  # value μ, bit for bit (Rotation.apply)
    weight = Dual(np.ones(m), None, k)
    if members.weights is not None:
        weight[rows] = members.weights
    return Steer(direction, weight, members)


def glossy_throughput(
    shading: Any, wi: Any, mu: np.ndarray, d: Any, alpha: Any, albedo: Any, above: np.ndarray
) -> Any:
    r"""$f(w_i, Rμ)\, (n·Rμ) / p_f(μ)$ at glossy points, $p_f$ at θ0 (as
    :func:`~sphere3d.glossy.glossy_samples`' throughput, with the direction ``d`` = $Rμ$): 0 where μ lies
    below the surface. Value the plain throughput's, bit for bit."""
    n0, wi0, alpha0 = detach(shading.n), detach(wi), detach(alpha)
    p0 = pdf_ggx(mu, wi0, n0, alpha0)
    f = eval_ggx(wi, d, shading.n, alpha, albedo) * np.maximum(dot(shading.n, d), 0.0)
    return np.where(above, f / np.where(above, p0, 1.0), 0.0)


def path_baseline(
    shading: Shading,
    go: Steer,
    mu: np.ndarray,
    scale: Any,
    name: str,
    carry: Callable[[Shading, np.ndarray], Any] | None = None,
) -> Any:
    r"""The control variate of the radiance carried along cosine samples (module docstring), per
    shading point: a derivative-only Dual (value 0), $-s\, \hat L(ω)\, \dot q / p(μ)$ with s = ``scale``
    (ρ of a diffuse vertex, π at a fixed point: the throughput's factor before $\cos / p$; then
    $s\, q / p$ is the throughput and $c = π \hat L$ in the module's terms), or None where
    there is nothing to subtract. ``name``: the next vertex's uniforms (``"bounce.k"``).

    ``carry(at, u)``: the irradiance estimate at the centre's hit ``at`` (plain, detached) from its
    uniforms ``u``, with the further vertices the carried path has (:func:`sphere3d.paths.carrier`:
    their own uniforms, common random numbers with the carried radiance's); None: the direct
    irradiance only, one MIS estimate (the carried radiance of a path's last segment)."""
    members, state = go.members, shading.state
    if members is None or members.centre is None or members.weights is None:
        return None
    rows = np.arange(len(mu)) if members.rows is None else members.rows
    if not rows.size:
        return None
    # q / p(μ) = cos(n0·Rμ) w / cos(n0·μ): value 1, tangent with zero mean given ω. Where its tangent is 0
    # (a rotation and weight that do not move) the term is 0 whatever c: no c is estimated there
    n0_all = detach(shading.n)[rows]
    q_all = np.maximum(dot(n0_all, members.rotated), 0.0) * members.weights
    turning = np.flatnonzero(moves(q_all))
    if not turning.size:
        return None
    plain, sub = state.detached(), shading.take(rows[turning])
    centre = members.centre[turning]
    hits = sub.trace(centre)
    shape = state.shape_of[np.where(hits.hit, hits.triangle, 0)]
    rho = np.asarray(detach(state.albedo), dtype=np.float64)[shape]
    ok = np.flatnonzero(hits.hit & (rho > 0.0) & ~state.glossy[shape])
    if not ok.size:
        return None
    tri, d = hits.triangle[ok], centre[ok]
    it = intersect_triangles(detach(sub.x)[ok], d, plain.triangles[tri])
    side = np.where((dot(it.normal, d) < 0.0)[:, None], 1.0, -1.0)
    normal = plain.shading_normals(tri, it.b1, it.b2, it.normal) * side
    at = Shading.at(plain, it.point, normal, sub.draws.take(ok), it.normal * side)
    u = at.draws.uniforms(name, 5)  # the next vertex's own: common random numbers with the carried radiance
    e = irradiance_samples(at, u, Identity()) if carry is None else carry(at, u)
    c = rho[ok] / np.pi * detach(e)  # L = (ρ/π) E at the centre's hit
    rows, q = rows[turning][ok], q_all[turning[ok]]
    cos0 = dot(n0_all[turning[ok]], mu[rows])
    q_dot = tangent(q) / np.where(cos0 > 0.0, cos0, 1.0)
    term = np.zeros((*q_dot.shape[:-1], len(mu)))
    term[..., rows] = -c * q_dot
    return Dual(np.zeros(len(mu)), term * detach(scale), state.k)
