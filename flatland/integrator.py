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

Paths. With ``max_depth`` d > 1 (:class:`Context`), the path goes on from each shading point
along its cosine sample (the BSDF sample), and every further diffuse vertex y adds
$β (ρ_y/2) \hat E(y)$ with the same MIS estimate, up to d vertices (:func:`trace_paths`):
$L = L_e + \mathcal{T} L_e + … + \mathcal{T}^d L_e$ for the reflection operator $\mathcal{T}$
(theory/radiometry). d = 1 is the direct illumination above, bit for bit.

Glossy shapes. A point on a glossy shape (a ``roughness``, :mod:`flatland.glossy`) reflects
$L_r = ∫ L_i w\, dφ$ with the GGX lobe $w = f \cos$: :func:`shade` takes its BSDF sample in place of
the cosine sample in the same MIS, and a path goes on along it with throughput $w / p_\mathrm{bsdf}$
(theory/bsdf). Scenes without glossy shapes run the diffuse code alone, bit for bit.

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

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from flatland import glossy
from flatland.core.dual import Dual, detach, is_dual, k_of, tangent
from flatland.core.rng import Draws
from flatland.glossy import Lobe
from flatland.lights import Lights
from flatland.members import Members, combine
from flatland.sampling import filter_value, pdf_filter, sample_filter
from flatland.state import SceneState
from flatland.tracing import Attached, Hits, attach, cast, direction, film_direction, zeros

if TYPE_CHECKING:  # tasks.py builds on this module; the qualified name keeps the docs unambiguous
    import flatland.tasks

__all__ = [
    "PRIMARY_UNIFORMS",
    "Bounce",
    "Context",
    "Identity",
    "Members",
    "Transforms",
    "combine",
    "cosine_ratio",
    "emitted",
    "incident",
    "pixel_samples",
    "radiance_along_film",
    "radiance_along_rays",
    "shade",
    "trace_paths",
]

PRIMARY_UNIFORMS = 4
"""Uniforms per primary sample: film, cosine direction, emitter choice, point on emitter."""


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

    def directions(
        self,
        ctx: Context,
        x: Any,
        ignore: np.ndarray,
        phi: np.ndarray,
        draws: Draws,
        lobe: Lobe | None = None,
    ) -> Members:
        """Direction evaluation points for direction samples ``phi`` from shading points ``x``
        (``ctx.needed``: which samples can add something); ``lobe``: the rows' materials in glossy
        scenes (:class:`~flatland.glossy.Lobe`; None: every row diffuse)."""
        ...

    def shading_extra(
        self, ctx: Context, x: Any, normal: Any, ignore: np.ndarray, lobe: Lobe | None = None,
        draws: Draws | None = None,
    ) -> np.ndarray | None:  # fmt: skip
        """2D only: a derivative-only term added to E at each shading point, shape (n,), or (k, n) for
        k parameters (``ctx.geom.k``) (None: nothing). With a ``lobe`` (glossy scenes), a term of the
        reflected radiance $∫ L_i w$ instead (:mod:`flatland.glossy`). ``draws`` keys the n rows (for
        the paths the term may trace; ``ctx.vertex`` is the points' vertex on their paths)."""
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

    def directions(
        self,
        ctx: Context,
        x: Any,
        ignore: np.ndarray,
        phi: np.ndarray,
        draws: Draws,
        lobe: Lobe | None = None,
    ) -> Members:
        return Members(phi[:, None])

    def shading_extra(
        self, ctx: Context, x: Any, normal: Any, ignore: np.ndarray, lobe: Lobe | None = None,
        draws: Draws | None = None,
    ) -> np.ndarray | None:  # fmt: skip
        return None

    def pixel_extra(
        self, task: flatland.tasks.ImageTask, state: flatland.state.SceneState
    ) -> np.ndarray | None:
        return None


@dataclass(frozen=True)
class Context:
    """What the transforms may use: the scene state (θ-dependent and detached) and the emitters;
    how many vertices a path has, ``max_depth`` (1: direct illumination), and which of them is being
    shaded, ``vertex`` (1: the camera's hit or a :class:`~flatland.tasks.PointTask`'s point).
    ``needed`` (``directions`` only; None: all): which direction samples may have a nonzero term or
    derivative where their rays go at θ0, or are ones a path goes on along (:func:`shade`). Elsewhere
    both are 0 at any evaluation point of the sample's value: unpaired transforms may leave them unmoved.

    Random numbers come with the rows they are for (a :class:`~flatland.core.rng.Draws`
    argument), keyed on the primary samples, never from a per-chunk stream.
    """

    geom: SceneState
    geom0: SceneState
    lights: Lights
    transforms: Transforms
    max_depth: int = 1
    vertex: int = 1
    needed: np.ndarray | None = None


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


def incident(
    geom: SceneState, origins: Any, dirs: Any, hits: Hits, keep: np.ndarray | None = None
) -> tuple[Any, Attached | None]:
    """Incident radiance along rays (sky on a miss) and the hits re-attached to ``geom``: every hit, or
    with ``keep`` (bool per ray) those of ``keep`` and those on an emitter (emission nonzero or moving),
    in ray order; elsewhere the radiance is 0 (value and derivative) without re-attaching."""
    lit = hits.hit & _live(geom.emission, hits.prim)  # on an emitter: the radiance needs the hit
    rows = np.flatnonzero(hits.hit if keep is None else lit | (hits.hit & keep))
    n = hits.prim.size
    k = geom.k if geom.differentiable else k_of(origins, dirs)
    out = zeros((n,), geom.differentiable or is_dual(origins) or is_dual(dirs), k) + geom.sky * (~hits.hit)
    if not rows.size:
        return out, None
    o = origins[rows] if np.ndim(detach(origins)) == 2 else origins
    att = attach(geom, hits, rows, o, dirs[rows])
    on = np.flatnonzero(lit[rows])  # elsewhere the emission, 0 and static, leaves 0
    if on.size:
        r = rows[on]
        out[r] = emitted(geom, hits.prim[r], att.u[on], detach(att.normal)[on], detach(dirs)[r])
    return out, att


@dataclass(frozen=True)
class Bounce:
    r"""Where the cosine (BSDF) sample of each shading point leads: the continuation of a path.

    ``hit`` (n,) whether its ray met a primitive, ``prim`` (n,) which one, ``point`` and
    ``normal`` (h, 2) the hits re-attached to θ (rows of ``hit`` only, geometric normal),
    ``dirs`` (n, 2) the ray directions and ``cosine`` (n,) the cosine $d · n(θ)$ at the
    shading point (a Dual when the normal moves; its value is the density's $2 p_\mathrm{cos}$).
    ``throughput`` (n,), shading with a :class:`~flatland.glossy.Lobe` only: the BSDF sample's weight
    $w(φ) / p_\mathrm{bsdf}(φ)$ with w Dual and the density θ-free (0 where the density is 0).
    ``weight`` (n,): the transforms' kernel weight of the BSDF sample (value 1; None for the identity),
    which multiplies everything the path gathers beyond this vertex (the authors' path reparameterization).
    """

    hit: np.ndarray
    prim: np.ndarray
    point: Any
    normal: Any
    dirs: Any
    cosine: Any
    throughput: Any = None
    weight: Any = None


def shade(
    ctx: Context,
    x: Any,
    normal: Any,
    ignore: np.ndarray,
    u: np.ndarray,
    draws: Draws,
    bounce: bool = False,
    lobe: Lobe | None = None,
) -> Any:
    r"""MIS estimate of $E(x) = ∫ L_i(x, φ) \max(0, \cos(φ - φ_n))\, dφ$
    at shading points ``x`` (n, 2).

    ``normal`` (n, 2) is the unit normal on the side being shaded, ``ignore`` the
    primitive each point lies on (-1 for none), ``u`` (n, 3) the primary uniforms,
    ``draws`` the keys of the n rows for anything the transforms draw. With ``bounce``,
    returns ``(E, Bounce)``: the cosine sample's ray, which a path continues along
    (:func:`trace_paths`; one evaluation point per sample, the identity transforms).

    With a ``lobe`` (:mod:`flatland.glossy`, scenes with glossy shapes) the estimate is of the
    reflected radiance $L_r = ∫ L_i(x, φ) w(φ)\, dφ$ instead, the BSDF sample taking the place of
    the cosine sample in the same balance heuristic: $w / (p_\mathrm{bsdf} + p_\mathrm{light})$ per
    sample, w evaluated where the transforms put the sample (theory/bsdf).
    """
    n = ignore.size
    x0, n0 = detach(x), detach(normal)
    phi_n0 = np.arctan2(n0[:, 1], n0[:, 0])
    # cosine sampling: φ - φn = arcsin(2u - 1)   (theory/radiometry)
    if lobe is None:
        phis = [phi_n0 + np.arcsin(2.0 * u[:, 0] - 1.0)]
    else:  # the BSDF sample: cosine on diffuse rows, visible GGX normals on glossy ones
        phis = [glossy.sample(lobe, u[:, 0], phi_n0)]
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
    if lobe is None:
        denom = np.maximum(cos0, 0.0) * 0.5
    else:
        lobes = lobe.take(idx)
        p_bsdf = glossy.pdf(lobes, phi, phi_n0[idx])
        denom = p_bsdf
    if not ctx.lights.empty:
        denom = denom + ctx.lights.pdf(phi, x0r)
    keep_all = np.concatenate(keep) & (denom > 0.0)
    inv = np.where(keep_all, 1.0 / np.where(keep_all, denom, 1.0), 0.0)

    xr = x[idx]
    # where each sample's ray goes at θ0: an emitter (or the sky) there, or a path going on along it,
    # is what can make the sample's term or its derivative nonzero, whatever its evaluation point's tangent
    d0 = direction(phi)
    hits = cast(ctx.geom0, x0r, d0, ign)
    needed = None
    if type(ctx.transforms).directions is not Identity.directions:  # a method that moves the samples
        needed = keep_all & _live(ctx.geom.emission, hits.prim, ctx.geom.sky)
        one = np.flatnonzero(needed & hits.hit & ctx.geom.one_sided[np.maximum(hits.prim, 0)])
        if one.size:  # a one-sided emitter met from behind emits nothing (:func:`emitted`'s test)
            nrm = attach(ctx.geom0, hits, one, x0r[one], d0[one]).normal
            needed[one] = (nrm[:, 0] * d0[one, 0] + nrm[:, 1] * d0[one, 1]) < 0.0
        needed |= bounce & hits.hit & (np.arange(phi.size) < n)  # the first n: the BSDF samples, paths go on
    told = ctx if needed is None else replace(ctx, needed=needed)
    tiled = draws.tile(techniques)
    if lobe is None:
        members = ctx.transforms.directions(told, xr, ign, phi, tiled)
    else:  # the rows' lobes, for a method whose kernels follow their width
        members = ctx.transforms.directions(told, xr, ign, phi, tiled, lobes)
    flat, rep = members.flat()
    at_samples = flat.shape[0] == phi.size and np.array_equal(detach(flat), phi)  # else: members elsewhere
    d = d0 if at_samples and not is_dual(flat) else direction(flat)
    if not at_samples:
        hits = cast(ctx.geom0, x0r[rep], detach(d), ign[rep])
    # re-attached: the hits a path goes on from (the first n, the BSDF samples) and those on emitters
    li, att = incident(ctx.geom, xr[rep], d, hits, bounce & (np.arange(rep.size) < n))
    nr = normal[idx][rep]
    cos = d[:, 0] * nr[:, 0] + d[:, 1] * nr[:, 1]
    if lobe is None:
        f = li * np.where(detach(cos) > 0.0, cos, 0.0)
    else:  # the lobe where the transforms put the sample: w(T φ) with φ_i, n, α, F as Duals
        w = glossy.weight(lobes.take(rep), flat, glossy.angle_of_vector(nr), cos)
        f = li * w
    total = members.reduce(f * inv[rep]).reshape(techniques, n).sum(axis=0)
    extra = ctx.transforms.shading_extra(ctx, x, normal, ignore, lobe, draws=draws)
    if extra is not None:
        total = total + Dual(np.zeros(n), extra, ctx.geom.k)
    if not bounce:
        return total
    if flat.shape[0] != techniques * n:
        raise ValueError("a path continues only under one evaluation point per sample (identity transforms)")
    hit = hits.hit[:n]  # the cosine technique's rows come first, and so do their attached hits
    h = int(np.count_nonzero(hit))
    point = att.point[:h] if h else None
    nrm = att.normal[:h] if h else None
    throughput = None
    if lobe is not None:  # w / p_bsdf on the BSDF sample's rows (the first n)
        p0 = p_bsdf[:n]
        throughput = np.where(p0 > 0.0, w[:n] / np.where(p0 > 0.0, p0, 1.0), 0.0)
    # a path goes on along the sample where the transforms put it, carrying its kernel weight
    weight = None if members.weights is None else members.weights[:n, 0]
    return total, Bounce(hit, hits.prim[:n], point, nrm, d[:n], cos[:n], throughput, weight)


# ------------------------------------------------------------------ paths
def _live(rho: Any, prim: np.ndarray | None = None, miss: float = 0.0) -> np.ndarray:
    """Rows whose albedo reflects or moves with a parameter (any of k tangents): the rest reflect nothing.
    With ``prim``: for rays that hit primitives ``prim`` (-1: a miss, live if ``miss`` is not 0), whether
    the per-primitive ``rho`` (an emission) of their hit is live."""
    moving = tangent(rho) != 0.0
    if moving.ndim > np.ndim(detach(rho)):  # k tangents: an albedo moving with any parameter
        moving = np.any(moving, axis=0)
    live = (detach(rho) != 0.0) | moving
    return live if prim is None else np.where(prim >= 0, live[np.maximum(prim, 0)], miss != 0.0)


def cosine_ratio(cosine: Any) -> Any:
    r"""$\cos_θ / \cos_{θ_0}$ of a cosine sample (0 where $\cos_{θ_0} \le 0$): value exactly 1, the derivative
    of the cosine in the integrand over the θ-free density $p_\mathrm{cos} = \cos_{θ_0} / 2$."""
    c0 = detach(cosine)
    ok = c0 > 0.0
    return np.where(ok, cosine / np.where(ok, c0, 1.0), 0.0)


def trace_paths(
    ctx: Context, total: Any, rows: np.ndarray, beta: Any, bounce: Bounce, draws: Draws, depth: int
) -> Any:
    r"""Add vertices ``depth`` … ``ctx.max_depth`` to ``total[rows]``, the paths leaving along ``bounce``.

    Vertex k (a diffuse hit y of the previous vertex's cosine sample) adds
    $β_k (ρ_y / 2) \hat E(y)$, $\hat E$ the MIS estimate of :func:`shade` (emitter and cosine sample,
    balance heuristic), and the path goes on along that cosine sample with
    $β_{k+1} = β_k f \cos / p_\mathrm{cos} = β_k ρ_y \cos_θ / \cos_{θ_0}$. The emission a
    continuation ray meets is counted once, inside the previous vertex's $\hat E$ with its MIS
    weight; its indirect part is this vertex. ``beta`` is the throughput of ``rows`` into this
    vertex (ρ of the camera's hit, or 2 from a :class:`~flatland.tasks.PointTask`'s point).
    Vertex k's uniforms are the stream ``"bounce.k"`` keyed on the primary sample (``draws``), so
    paths do not depend on chunking. Paths end at ``max_depth`` (no Russian roulette: no bias, no
    early end), on a miss, or at an albedo of 0 that no parameter moves.
    """
    geom = ctx.geom
    glossy_scene = bool(np.any(geom.glossy))
    while depth <= ctx.max_depth:
        prim = bounce.prim[bounce.hit]
        rho = geom.albedo[prim]
        live = _live(rho)
        if glossy_scene:  # a glossy sample below the surface has throughput 0: that path ends here
            live &= _live(beta[np.flatnonzero(bounce.hit)])
        sel = np.flatnonzero(live)  # among the hits
        keep = np.flatnonzero(bounce.hit)[sel]  # among the current rows
        if not keep.size:
            break
        n_geo, d = bounce.normal[sel], bounce.dirs[keep]
        # shade the side the path arrives on: flip the geometric normal where the ray meets its back
        facing = np.sum(detach(n_geo) * detach(d), axis=1) < 0.0
        n_shade = n_geo * np.where(facing, 1.0, -1.0)[:, None]
        rows, beta, draws, rho = rows[keep], beta[keep], draws.take(keep), rho[sel]
        last = depth == ctx.max_depth
        u = draws.uniforms(f"bounce.{depth}", 3)  # keyed on (sample, depth): chunking changes nothing
        lobe = glossy.lobe_at(geom, prim[sel], d)
        out = shade(
            replace(ctx, vertex=depth), bounce.point[sel], n_shade, prim[sel], u, draws, not last, lobe
        )
        e, bounce = (out, None) if last else out
        total[rows] = total[rows] + (beta * 0.5 * rho * e if lobe is None else beta * e)
        if last:
            break
        beta = beta * rho * cosine_ratio(bounce.cosine) if lobe is None else beta * bounce.throughput
        beta = beta if bounce.weight is None else beta * bounce.weight
        depth += 1
    return total


# ------------------------------------------------------------------ the pixel integral
def radiance_along_film(ctx: Context, t_eval: Any, u: np.ndarray, draws: Draws) -> Any:
    """$L(t)$ for film evaluation points ``t_eval`` (n,): emission at the hit + $(ρ/2) E$ there, and
    with ``ctx.max_depth`` > 1 the further vertices of its path (:func:`trace_paths`)."""
    geom = ctx.geom
    return radiance_along_rays(ctx, geom.cam_o, film_direction(geom, t_eval), None, u, draws)


def radiance_along_rays(
    ctx: Context, origins: Any, d: Any, ignore: np.ndarray | None, u: np.ndarray, draws: Draws
) -> Any:
    r"""Radiance arriving at ``origins`` ((2,) or (n, 2)) along directions ``d`` (n, 2): the emission $L_e$
    the ray meets plus the radiance its hit reflects along paths of up to ``ctx.max_depth`` vertices,
    the hit being vertex 1 (uniforms ``u`` (n, 3) for its shading, ``draws`` keying the rest).
    ``ignore`` (n,): the primitive each origin lies on (None: none)."""
    geom = ctx.geom
    hits = cast(ctx.geom0, detach(origins), detach(d), ignore)
    radiance, att = incident(geom, origins, d, hits)
    rows = np.flatnonzero(hits.hit)
    if not rows.size:
        return radiance
    prim = hits.prim[rows]
    rho = geom.albedo[prim]
    live = _live(rho)
    if not np.any(live):
        return radiance
    sub = np.flatnonzero(live)
    n_geo = att.normal[sub]
    # shade the side facing the camera: flip the geometric normal where the ray meets its back
    facing = np.sum(detach(n_geo) * detach(d)[rows[sub]], axis=1) < 0.0
    n_shade = n_geo * np.where(facing, 1.0, -1.0)[:, None]
    paths = ctx.max_depth > 1
    lobe = glossy.lobe_at(geom, prim[sub], d[rows[sub]])
    out = shade(ctx, att.point[sub], n_shade, prim[sub], u[rows[sub]], draws.take(rows[sub]), paths, lobe)
    e, bounce = out if paths else (out, None)
    radiance[rows[sub]] = radiance[rows[sub]] + (0.5 * rho[sub] * e if lobe is None else e)
    if paths:  # a diffuse vertex's cosine sample weight: f cos / p = (ρ/2) cos_θ / (cos_θ0 / 2)
        beta = rho[sub] * cosine_ratio(bounce.cosine) if lobe is None else bounce.throughput
        beta = beta if bounce.weight is None else beta * bounce.weight
        radiance = trace_paths(ctx, radiance, rows[sub], beta, bounce, draws.take(rows[sub]), 2)
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
