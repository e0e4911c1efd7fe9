r"""The flatland integrator: pixel and shading integrals, with the change of variables left to the method.

Radiometry (theory/radiometry). Pixel j of the 1D film is $I_j = ∫ k_j(t) L(t) dt$, with
$k_j$ the pixel filter and $L(t)$ the radiance arriving along film coordinate t; it is
estimated with $t \sim k_j$ (the filter is its own sampling density). At the first hit
x, $L = L_e(x) + (ρ/2) E(x)$ with the cosine-weighted incident radiance

    $E(x) = ∫ L_i(x, φ) \max(0, \cos(φ - φ_n))\, dφ$,

$L_i$ being the emission (or sky) the ray from x along φ meets: direct illumination.
E is estimated with one cosine-weighted sample and one emitter sample combined by
multiple importance sampling (balance heuristic): each sample φ contributes
$f(φ) / (p_\mathrm{cos}(φ) + p_\mathrm{light}(φ))$. All proposals are θ-free (evaluated on the
detached geometry), so the estimators differentiate cleanly (Loubet et al. 2019, Sec. 3.2).

Transforms. A gradient method changes *where* the integrands are evaluated, never the
samples: its :class:`Transforms` maps each film sample t to evaluation points $T(t)$
(``camera``) and each direction sample φ to $T(φ)$ (``directions``), with a weight
of value 1 that carries kernel derivatives, and may replace one sample by a pair
(theory/kernels). Two extension points exist in 2D only, for the boundary method: a
derivative-only term per shading point (``shading_extra``) and per pixel
(``pixel_extra``). :class:`Identity` changes nothing: the naive estimator.

Random numbers. Sample j of pixel p has the global index ``p * spp + j`` (batch
``j // (spp / batches)``), and every number drawn for it, its primary uniforms
(stream ``"samples"``) as much as a method's kernel or probe draws, is keyed on that
index (:class:`flatland.core.rng.Draws`). Every method therefore sees the same
primary samples for a seed, and an image does not depend on
:data:`~flatland.tasks.CHUNK` (how samples are grouped for vectorization, which
bounds memory) nor, sample for sample, on the number of batches. The loop over
samples and batches is :meth:`flatland.tasks.ImageTask.evaluate` (and
:class:`~flatland.tasks.PointTask` for E at one point), as in sphere3d.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from flatland.core.dual import Dual, detach, is_dual, k_of, tangent
from flatland.core.rng import Draws
from flatland.core.translation import paired_combine
from flatland.lights import Lights
from flatland.sampling import filter_value, pdf_filter, sample_filter
from flatland.state import SceneState
from flatland.tracing import Attached, Hits, attach, cast, direction, film_direction, zeros

if TYPE_CHECKING:  # tasks.py builds on this module; the qualified name keeps the docs unambiguous
    import flatland.tasks

__all__ = [
    "PRIMARY_UNIFORMS",
    "Context",
    "Identity",
    "Members",
    "Transforms",
    "combine",
    "emitted",
    "incident",
    "pixel_samples",
    "radiance_along_film",
    "shade",
]

PRIMARY_UNIFORMS = 4
"""Uniforms per primary sample: film, cosine direction, emitter choice, point on emitter."""


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


class Transforms(Protocol):
    """How a method changes variables in the integrals (see the module docstring).

    ``camera`` and ``directions`` are the change of variables of the pixel and of the
    shading integral, as in sphere3d; ``shading_extra`` and ``pixel_extra`` are
    2D-only extension points for terms that are not a change of variables (the
    boundary method's jump terms). :class:`Identity` implements all four; a method
    usually subclasses it and overrides what it changes.
    """

    def camera(self, ctx: Context, t: np.ndarray, pixel: np.ndarray, draws: Draws) -> Members:
        """Film evaluation points for film samples ``t`` of pixels ``pixel`` (``draws``: one row each)."""
        ...

    def directions(self, ctx: Context, x: Any, ignore: np.ndarray, phi: np.ndarray, draws: Draws) -> Members:
        """Direction evaluation points for direction samples ``phi`` from shading points ``x``."""
        ...

    def shading_extra(self, ctx: Context, x: Any, normal: Any, ignore: np.ndarray) -> np.ndarray | None:
        """2D only: a derivative-only term added to E at each shading point, shape (n,), or (k, n) for
        k parameters (``ctx.geom.k``) (None: nothing)."""
        ...

    def pixel_extra(
        self, task: flatland.tasks.ImageTask, state: flatland.state.SceneState
    ) -> np.ndarray | None:
        """2D only: a derivative-only term per batch and pixel, shape (batches, pixels), or
        (k, batches, pixels) for k parameters (None: nothing)."""
        ...


class Identity:
    """No change of variables: evaluate every integrand where it was sampled (the naive estimator)."""

    def camera(self, ctx: Context, t: np.ndarray, pixel: np.ndarray, draws: Draws) -> Members:
        return Members(t[:, None])

    def directions(self, ctx: Context, x: Any, ignore: np.ndarray, phi: np.ndarray, draws: Draws) -> Members:
        return Members(phi[:, None])

    def shading_extra(self, ctx: Context, x: Any, normal: Any, ignore: np.ndarray) -> np.ndarray | None:
        return None

    def pixel_extra(
        self, task: flatland.tasks.ImageTask, state: flatland.state.SceneState
    ) -> np.ndarray | None:
        return None


@dataclass(frozen=True)
class Context:
    """What the transforms may use: the scene state (θ-dependent and detached) and the emitters.

    Random numbers come with the rows they are for (a :class:`~flatland.core.rng.Draws`
    argument), keyed on the primary samples, never from a per-chunk stream.
    """

    geom: SceneState
    geom0: SceneState
    lights: Lights
    transforms: Transforms


# ------------------------------------------------------------------ radiance
def emitted(geom: SceneState, prim: np.ndarray, u: Any, normal0: np.ndarray, dirs0: np.ndarray) -> Any:
    r"""Radiance $L_e$ leaving primitives ``prim`` at coordinate ``u`` toward the ray origins.

    Emission × the fade profile $\min(1, u / f, (1 - u) / f)$ × (one-sided emitters: 1 on
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


def incident(geom: SceneState, origins: Any, dirs: Any, hits: Hits) -> tuple[Any, Attached | None]:
    """Incident radiance along rays (sky on a miss) and the hits re-attached to ``geom``."""
    rows = np.flatnonzero(hits.hit)
    n = hits.prim.size
    k = geom.k if geom.differentiable else k_of(origins, dirs)
    out = zeros((n,), geom.differentiable or is_dual(origins) or is_dual(dirs), k) + geom.sky * (~hits.hit)
    if not rows.size:
        return out, None
    o = origins[rows] if np.ndim(detach(origins)) == 2 else origins
    att = attach(geom, hits, rows, o, dirs[rows])
    out[rows] = emitted(geom, hits.prim[rows], att.u, detach(att.normal), detach(dirs)[rows])
    return out, att


def shade(ctx: Context, x: Any, normal: Any, ignore: np.ndarray, u: np.ndarray, draws: Draws) -> Any:
    r"""MIS estimate of $E(x) = ∫ L_i(x, φ) \max(0, \cos(φ - φ_n))\, dφ$
    at shading points ``x`` (n, 2).

    ``normal`` (n, 2) is the unit normal on the side being shaded, ``ignore`` the
    primitive each point lies on (-1 for none), ``u`` (n, 3) the primary uniforms,
    ``draws`` the keys of the n rows for anything the transforms draw.
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
    members = ctx.transforms.directions(ctx, xr, ign, phi, draws.tile(techniques))
    flat, rep = members.flat()
    d = direction(flat)
    hits = cast(ctx.geom0, x0r[rep], detach(d), ign[rep])
    li, _ = incident(ctx.geom, xr[rep], d, hits)
    nr = normal[idx][rep]
    cos = d[:, 0] * nr[:, 0] + d[:, 1] * nr[:, 1]
    f = li * np.where(detach(cos) > 0.0, cos, 0.0)
    total = members.reduce(f * inv[rep]).reshape(techniques, n).sum(axis=0)
    extra = ctx.transforms.shading_extra(ctx, x, normal, ignore)
    if extra is not None:
        total = total + Dual(np.zeros(n), extra, ctx.geom.k)
    return total


# ------------------------------------------------------------------ the pixel integral
def radiance_along_film(ctx: Context, t_eval: Any, u: np.ndarray, draws: Draws) -> Any:
    """$L(t)$ for film evaluation points ``t_eval`` (n,): emission at the hit + $(ρ/2) E$ there."""
    geom = ctx.geom
    d = film_direction(geom, t_eval)
    hits = cast(ctx.geom0, detach(geom.cam_o), detach(d))
    radiance, att = incident(geom, geom.cam_o, d, hits)
    rows = np.flatnonzero(hits.hit)
    if not rows.size:
        return radiance
    prim = hits.prim[rows]
    rho = geom.albedo[prim]
    moving = tangent(rho) != 0.0
    if moving.ndim > np.ndim(detach(rho)):  # k tangents: an albedo moving with any parameter
        moving = np.any(moving, axis=0)
    live = (detach(rho) != 0.0) | moving
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


def pixel_samples(ctx: Context, pixel: np.ndarray, u: np.ndarray, draws: Draws) -> Any:
    """Per-sample pixel estimates $k_j(T t) / k_j(t) · L(T t) · w$ (combined over members)."""
    cam = ctx.geom.camera
    centers = cam.pixel_centers()[pixel]
    width = cam.pixel_width
    t = sample_filter(cam.filter, u[:, 0], centers, width)
    members = ctx.transforms.camera(ctx, t, pixel, draws)
    flat, rep = members.flat()
    m = np.shape(detach(members.points))[1]
    u_shade = u[rep, 1:]
    if m > 1:  # the other members of a pair get their own shading samples
        extra = draws.uniforms("paired", m - 1, 3)
        u_shade = np.concatenate([u[:, None, 1:], extra], axis=1).reshape(-1, 3)
    radiance = radiance_along_film(ctx, flat, u_shade, draws.repeat(m))
    k_eval = filter_value(cam.filter, flat, centers[rep], width)
    k_sample = pdf_filter(cam.filter, t, centers, width) if members.density is None else members.density
    k_sample = k_sample[rep]
    ratio = k_eval / np.where(k_sample > 0.0, k_sample, 1.0)
    return members.reduce(ratio * radiance)
