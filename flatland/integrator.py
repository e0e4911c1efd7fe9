"""The flatland integrator: pixel integrals and shading integrals, with hooks for the gradient methods.

Radiometry (theory/radiometry). Pixel j of the 1D film is ``I_j = ∫ k_j(t) L(t) dt``, with
k_j the pixel filter and L(t) the radiance arriving along film coordinate t; it is
estimated with t ~ k_j (the filter is its own sampling density). At the first hit
x, ``L = L_e(x) + (ρ/2) E(x)`` with the cosine-weighted incident radiance

    E(x) = ∫ L_i(x, φ) max(0, cos(φ - φ_n)) dφ,

L_i being the emission (or sky) the ray from x along φ meets: direct illumination.
E is estimated with one cosine-weighted sample and one emitter sample combined by
multiple importance sampling (balance heuristic): each sample φ contributes
``f(φ) / (p_cos(φ) + p_light(φ))``. All proposals are θ-free (evaluated on the
detached geometry), so the estimators differentiate cleanly (Loubet et al. 2019, Sec. 3.2).

Hooks. A gradient method changes *where* the integrands are evaluated, never the
samples: :class:`Hooks` maps each film sample t to evaluation points ``T(t)`` and
each direction sample φ to ``T(φ)`` (with a weight of value 1 that carries kernel
derivatives), may replace one sample by a pair (theory/kernels), and may add a
derivative-only term per shading point or per pixel (the boundary method). The
default hooks are the identity: the naive estimator.

Random numbers. Sample j of pixel p has the global index ``p * spp + j`` (batch
``j // (spp / batches)``), and every number drawn for it, its primary uniforms
(stream ``"samples"``) as much as a method's kernel or probe draws, is keyed on that
index (:class:`flatland.core.rng.Draws`). Every method therefore sees the same
primary samples for a seed, and an image does not depend on :data:`CHUNK` (how
samples are grouped for vectorization, which bounds memory) nor, sample for
sample, on the number of batches.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import special

from flatland.core.contract import MethodTable
from flatland.core.dual import Dual, detach, is_dual, tangent
from flatland.core.rng import Draws
from flatland.core.translation import paired_combine
from flatland.geometry import Attached, Hits, attach, cast, direction, film_direction, zeros
from flatland.lights import Lights
from flatland.sampling import sample_gaussian, sample_tent, sample_uniform
from flatland.scene import Geometry, Scene, bind

__all__ = [
    "CHUNK",
    "GRADIENT_METHODS",
    "BatchResult",
    "Context",
    "Hooks",
    "Job",
    "Members",
    "combine",
    "emitted",
    "filter_blurred",
    "filter_sample",
    "filter_value",
    "incident",
    "radiance_along_film",
    "run",
    "shade",
]

CHUNK = 1 << 15
"""Primary samples processed together (bounds memory; results do not depend on it, up to the
rounding of the per-pixel sums, which add the same numbers in another grouping)."""

N_UNIFORMS = 4  # per primary sample: film, cosine direction, emitter choice, point on emitter

GRADIENT_METHODS = MethodTable("gradient method")
"""Image gradient methods by name (``flatland.methods`` registers them): each is called as
``func(job, **options) -> BatchResult``."""


# ------------------------------------------------------------------ jobs and results
@dataclass(frozen=True)
class Job:
    """What to estimate: every pixel of the scene's camera, or E(x) at one point.

    ``point``/``normal`` select the point target (``spp`` then counts samples at the
    point and there is one "pixel"). ``batches`` independent batches of
    ``spp // batches`` samples per pixel give the standard errors.
    """

    scene: Scene
    param: Any  # Parameter or None
    spp: int
    seed: int
    batches: int
    point: tuple[float, float] | None = None
    normal: tuple[float, float] | None = None

    @property
    def pixels(self) -> int:
        return 1 if self.point is not None else self.scene.camera.pixels

    @property
    def per_batch(self) -> int:
        return self.spp // self.batches

    def geometry(self, theta: Any) -> Geometry:
        """The scene bound at parameter offset ``theta`` (float or Dual)."""
        return bind(self.scene, self.param, theta)


@dataclass(frozen=True)
class BatchResult:
    """Per-batch, per-pixel estimates of the value and the derivative, shape (batches, pixels)."""

    value: np.ndarray
    derivative: np.ndarray


@dataclass(frozen=True)
class Members:
    """Evaluation points for a set of samples: ``points`` (n, m), ``weights`` (n, m) or None.

    m = 1 for a single evaluation per sample, m = 2 for a pair sharing one transform
    that :func:`combine` merges with the paired-sample control variate (theory/kernels). ``density``
    (film only) replaces the pixel filter as the density of the sample the members
    were drawn around, when that is not the film sample itself.
    """

    points: Any
    weights: Any = None
    paired: bool = False
    density: np.ndarray | None = None

    def flat(self) -> tuple[Any, np.ndarray]:
        """All evaluation points as one flat array, and the index of each one's sample."""
        n, m = np.shape(detach(self.points))
        return self.points.reshape(-1), np.repeat(np.arange(n), m)

    def reduce(self, e_flat: Any) -> Any:
        """Per-sample estimates from the members' estimates ``e_flat`` (in :meth:`flat` order)."""
        e = e_flat.reshape(np.shape(detach(self.points)))
        if self.weights is not None:
            e = e * self.weights
        return combine(e, self.weights, self.paired)


def combine(e: Any, w: Any, paired: bool) -> Any:
    """Per-sample estimate from member estimates ``e`` (n, m) carrying weights ``w`` (value 1).

    Paired (theory/kernels): 0.5 (e0 - e1/w1 (w0 - detach w0)) + 0.5 (e1 - e0/w0 (w1 - detach w1)):
    each weight's derivative has zero mean given the pair's kernel centre and is
    independent of the other member, so it serves as the other's control variate.
    """
    if not paired:
        return e[:, 0]
    return paired_combine(e[:, 0], e[:, 1], w[:, 0], w[:, 1])


class Hooks:
    """Identity hooks: evaluate every integrand where it was sampled (the naive estimator)."""

    def film(self, ctx: Context, t: np.ndarray, pixel: np.ndarray, draws: Draws) -> Members:
        """Film evaluation points for film samples ``t`` of pixels ``pixel`` (``draws``: one row each)."""
        return Members(t[:, None])

    def directions(self, ctx: Context, x: Any, ignore: np.ndarray, phi: np.ndarray, draws: Draws) -> Members:
        """Direction evaluation points for direction samples ``phi`` from shading points ``x``."""
        return Members(phi[:, None])

    def shading_extra(self, ctx: Context, x: Any, normal: Any, ignore: np.ndarray) -> np.ndarray | None:
        """A derivative-only term added to E at each shading point (None: nothing)."""
        return None

    def pixel_extra(self, job: Job, geom: Geometry) -> np.ndarray | None:
        """A derivative-only term per batch and pixel, shape (batches, pixels) (None: nothing)."""
        return None


@dataclass(frozen=True)
class Context:
    """What the hooks may use: the geometry (θ-dependent and detached) and the emitters.

    Random numbers come with the rows they are for (a :class:`~flatland.core.rng.Draws`
    argument), keyed on the primary samples, never from a per-chunk stream.
    """

    geom: Geometry
    geom0: Geometry
    lights: Lights
    hooks: Hooks


# ------------------------------------------------------------------ pixel filters
def filter_value(kind: str, t: Any, center: Any, width: float) -> Any:
    """Pixel filter k_j(t) for pixel centres ``center`` and pixel width Δt (``t`` may be a Dual)."""
    x = t - center
    if kind == "box":
        return np.where(np.abs(detach(x)) <= 0.5 * width, 1.0 / width, 0.0)
    if kind == "tent":
        return np.maximum(1.0 - np.abs(x) / width, 0.0) / width
    sigma = 0.5 * width
    return np.exp(-0.5 * (x / sigma) * (x / sigma)) / (sigma * np.sqrt(2.0 * np.pi))


def filter_blurred(kind: str, y: np.ndarray, width: float, sigma: float) -> np.ndarray:
    """Density of t + σ z (t ~ pixel filter centred at 0, z ~ N(0, 1)) at offsets ``y``: k ⊛ N(0, σ²).

    Tent of radius w: (R(y + w) - 2 R(y) + R(y - w)) / w² with R(y) = y Φ(y/σ) + σ φ(y/σ)
    (the tent is a sum of ramps, and R is a ramp blurred by the Gaussian); Gaussian
    filter: N(0, (w/2)² + σ²).
    """
    y = np.asarray(y, dtype=np.float64)
    if kind == "gaussian":
        s2 = 0.25 * width * width + sigma * sigma
        return np.exp(-0.5 * y * y / s2) / np.sqrt(2.0 * np.pi * s2)
    if kind != "tent":
        raise ValueError(f"filter_blurred: no closed form for the {kind!r} filter")

    def ramp(z: np.ndarray) -> np.ndarray:
        return z * special.ndtr(z / sigma) + sigma * np.exp(-0.5 * (z / sigma) ** 2) / np.sqrt(2.0 * np.pi)

    return (ramp(y + width) - 2.0 * ramp(y) + ramp(y - width)) / (width * width)


def filter_sample(kind: str, u: np.ndarray, center: np.ndarray, width: float) -> np.ndarray:
    """Film samples t ~ k_j from uniforms ``u`` (box: one pixel; tent: radius Δt; gaussian: σ = Δt/2)."""
    if kind == "box":
        return sample_uniform(u, center - 0.5 * width, center + 0.5 * width)
    if kind == "tent":
        return sample_tent(u, center, width)
    return sample_gaussian(u, center, 0.5 * width)


# ------------------------------------------------------------------ radiance
def emitted(geom: Geometry, prim: np.ndarray, u: Any, normal0: np.ndarray, dirs0: np.ndarray) -> Any:
    """Radiance L_e leaving primitives ``prim`` at coordinate ``u`` toward the ray origins.

    Emission × the fade profile min(1, u / f, (1 - u) / f) × (one-sided emitters: 1 on
    the side the geometric normal points to, 0 behind).
    """
    e = geom.emission[prim]
    fade = geom.fade[prim]
    faded = fade > 0.0
    if np.any(faded):
        ramp = np.minimum(u, 1.0 - u) / np.where(faded, fade, 1.0)
        e = e * np.where(faded, np.minimum(ramp, 1.0), 1.0)
    front = (normal0[:, 0] * dirs0[:, 0] + normal0[:, 1] * dirs0[:, 1]) < 0.0
    return e * np.where(geom.one_sided[prim] & ~front, 0.0, 1.0)


def incident(geom: Geometry, origins: Any, dirs: Any, hits: Hits) -> tuple[Any, Attached | None]:
    """Incident radiance along rays (sky on a miss) and the hits re-attached to ``geom``."""
    rows = np.flatnonzero(hits.hit)
    n = hits.prim.size
    out = zeros((n,), geom.differentiable or is_dual(origins) or is_dual(dirs)) + geom.sky * (~hits.hit)
    if not rows.size:
        return out, None
    o = origins[rows] if np.ndim(detach(origins)) == 2 else origins
    att = attach(geom, hits, rows, o, dirs[rows])
    out[rows] = emitted(geom, hits.prim[rows], att.u, detach(att.normal), detach(dirs)[rows])
    return out, att


def shade(ctx: Context, x: Any, normal: Any, ignore: np.ndarray, u: np.ndarray, draws: Draws) -> Any:
    """MIS estimate of E(x) = ∫ L_i(x, φ) max(0, cos(φ - φ_n)) dφ at shading points ``x`` (n, 2).

    ``normal`` (n, 2) is the unit normal on the side being shaded, ``ignore`` the
    primitive each point lies on (-1 for none), ``u`` (n, 3) the primary uniforms,
    ``draws`` the keys of the n rows for anything the hooks draw.
    """
    n = ignore.size
    x0, n0 = detach(x), detach(normal)
    phi_n0 = np.arctan2(n0[:, 1], n0[:, 0])
    # cosine sampling: φ - φn = arcsin(2u - 1)   (theory/radiometry)
    phis = [phi_n0 + np.arcsin(2.0 * u[:, 0] - 1.0)]
    keep = [np.ones(n, dtype=bool)]
    if not ctx.lights.empty:
        phi_l, chosen = ctx.lights.sample(u[:, 1], u[:, 2], x0)
        phis.append(phi_l)
        keep.append(chosen != ignore)  # a point's own emitter is sampled only along its surface: f = 0
    techniques = len(phis)
    phi = np.concatenate(phis)
    idx = np.tile(np.arange(n), techniques)
    x0r, ign = x0[idx], ignore[idx]
    cos0 = np.cos(phi - phi_n0[idx])
    # balance heuristic with one sample per technique: w_s f / p_s = f / (p_cos + p_light)
    denom = np.maximum(cos0, 0.0) * 0.5
    if not ctx.lights.empty:
        denom = denom + ctx.lights.pdf(phi, x0r)
    keep_all = np.concatenate(keep) & (denom > 0.0)
    inv = np.where(keep_all, 1.0 / np.where(keep_all, denom, 1.0), 0.0)

    xr = x[idx]
    members = ctx.hooks.directions(ctx, xr, ign, phi, draws.tile(techniques))
    flat, rep = members.flat()
    d = direction(flat)
    hits = cast(ctx.geom0, x0r[rep], detach(d), ign[rep])
    li, _ = incident(ctx.geom, xr[rep], d, hits)
    nr = normal[idx][rep]
    cos = d[:, 0] * nr[:, 0] + d[:, 1] * nr[:, 1]
    f = li * np.where(detach(cos) > 0.0, cos, 0.0)
    total = members.reduce(f * inv[rep]).reshape(techniques, n).sum(axis=0)
    extra = ctx.hooks.shading_extra(ctx, x, normal, ignore)
    if extra is not None:
        total = total + Dual(np.zeros(n), extra)
    return total


# ------------------------------------------------------------------ the pixel integral
def radiance_along_film(ctx: Context, t_eval: Any, u: np.ndarray, draws: Draws) -> Any:
    """L(t) for film evaluation points ``t_eval`` (n,): emission at the hit + (ρ/2) E there."""
    geom = ctx.geom
    d = film_direction(geom, t_eval)
    hits = cast(ctx.geom0, detach(geom.cam_o), detach(d))
    radiance, att = incident(geom, geom.cam_o, d, hits)
    rows = np.flatnonzero(hits.hit)
    if not rows.size:
        return radiance
    prim = hits.prim[rows]
    rho = geom.albedo[prim]
    live = (detach(rho) != 0.0) | (tangent(rho) != 0.0)
    if not np.any(live):
        return radiance
    sub = np.flatnonzero(live)
    n_geo = att.normal[sub]
    # shade the side facing the camera: flip the geometric normal where the ray meets its back
    facing = np.sum(detach(n_geo) * detach(d)[rows[sub]], axis=1) < 0.0
    n_shade = n_geo * np.where(facing, 1.0, -1.0)[:, None]
    e = shade(ctx, att.point[sub], n_shade, prim[sub], u[rows[sub]], draws.take(rows[sub]))
    radiance[rows[sub]] = radiance[rows[sub]] + 0.5 * rho[sub] * e
    return radiance


def _film_pass(ctx: Context, job: Job, pixel: np.ndarray, u: np.ndarray, draws: Draws) -> Any:
    """Per-sample pixel estimates k_j(T t) / k_j(t) · L(T t) · w (combined over members)."""
    cam = job.scene.camera
    centers = cam.pixel_centers()[pixel]
    width = cam.pixel_width
    t = filter_sample(cam.filter, u[:, 0], centers, width)
    members = ctx.hooks.film(ctx, t, pixel, draws)
    flat, rep = members.flat()
    m = np.shape(detach(members.points))[1]
    u_shade = u[rep, 1:]
    if m > 1:  # the other members of a pair get their own shading samples
        extra = draws.uniforms("paired", m - 1, 3)
        u_shade = np.concatenate([u[:, None, 1:], extra], axis=1).reshape(-1, 3)
    radiance = radiance_along_film(ctx, flat, u_shade, draws.repeat(m))
    k_eval = filter_value(cam.filter, flat, centers[rep], width)
    k_sample = filter_value(cam.filter, t, centers, width) if members.density is None else members.density
    k_sample = k_sample[rep]
    ratio = k_eval / np.where(k_sample > 0.0, k_sample, 1.0)
    return members.reduce(ratio * radiance)


# ------------------------------------------------------------------ work plan and driver
def _chunks(job: Job) -> Iterator[np.ndarray]:
    """Global sample indices ``pixel * spp + j`` in consecutive ranges of at most :data:`CHUNK`."""
    total = job.pixels * job.spp
    for lo in range(0, total, CHUNK):
        yield np.arange(lo, min(lo + CHUNK, total), dtype=np.int64)


def run(job: Job, geom: Geometry, hooks: Hooks) -> BatchResult:
    """Estimate every pixel (or the point) in every batch with ``hooks``; values and derivatives."""
    geom0 = geom.detached()
    ctx = Context(geom, geom0, Lights.of(geom0), hooks)
    size = job.batches * job.pixels
    sums_v = np.zeros(size)
    sums_t = np.zeros(size)
    for index in _chunks(job):
        pixel, j = np.divmod(index, job.spp)
        batch = j // job.per_batch
        draws = Draws.of(job.seed, index)
        u = draws.uniforms("samples", N_UNIFORMS)  # the primary sample, the same for every method
        if job.point is None:
            est = _film_pass(ctx, job, pixel, u, draws)
        else:
            n = pixel.size
            x = np.tile(np.array(job.point, dtype=np.float64), (n, 1))
            normal = np.tile(np.array(job.normal, dtype=np.float64), (n, 1))
            est = shade(ctx, x, normal, np.full(n, -1), u[:, 1:], draws)
        key = batch * job.pixels + pixel
        sums_v += np.bincount(key, weights=detach(est), minlength=size)
        sums_t += np.bincount(key, weights=tangent(est), minlength=size)
    value = (sums_v / job.per_batch).reshape(job.batches, job.pixels)
    deriv = (sums_t / job.per_batch).reshape(job.batches, job.pixels)
    extra = hooks.pixel_extra(job, geom)
    if extra is not None:
        deriv = deriv + extra
    return BatchResult(value, deriv)
