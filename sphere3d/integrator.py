r"""The renderer's integrals, written once, with the change of variables left to the method.

Three nested integrals per pixel (direct illumination; paths of more vertices: :mod:`sphere3d.paths`):

1. **Pixel integral** over the film, $∫ k(s) L(ω(s)) ds$, written over directions
   $∫ k(\mathrm{film}(ω)) J(ω) L(ω) dω$ (J: film area per solid angle). Film offsets are
   drawn from :func:`~sphere3d.sampling.sample_filter` and weighted by $k / p$; a
   method may rotate their directions, $ω → R·ω_i$, and the factor
   $k J (Rω) / \mathrm{detach}(k J (Rω))$ (value exactly 1) carries the change of the
   filter under the rotation (Loubet et al. 2019, Sec. 4.1; theory/pixel_filters). Its
   tangent has zero mean, which :class:`~sphere3d.tasks.ImageTask` uses as a
   control variate.
2. **Radiance** along the ray: the sky where it misses; at a hit, front-side emission
   (with the border fade) plus $ρ/π · E$ for diffuse surfaces.
3. **Irradiance** $E = ∫ L_i(ω) \cos θ\, dω$ at the hit point, by multiple importance
   sampling (balance heuristic) of two strategies:

   - *emitter sampling*: a point y uniform on the emitters' area, its direction ω and
     the solid-angle density $p_L = d^2 / (A \cos θ_y)$; a method may rotate ω;
     the emitter hit is re-attached to the triangle the sample lies on (without its
     edges: a method that sets ``emitter_edges`` gets their boundary term added,
     :mod:`sphere3d.boundary.emitters`);
   - *cosine sampling*: $ω \sim \cos θ / π$; the method owns this estimator (it may add a
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

from flatland.core.dual import Dual, detach, tangent
from flatland.core.rng import Draws
from flatland.core.translation import paired_combine, unit_weight
from sphere3d.film import FilmTransform
from sphere3d.live import emitters_change, moves, moving_rows, on_rows, take_rows, triangles_change
from sphere3d.rotation import Rotation
from sphere3d.sampling import (
    emitter_directions,
    filter_value,
    log_filter_value,
    pdf_cosine_hemisphere,
    pdf_filter,
    sample_cosine_hemisphere,
    sample_filter,
    solid_angle_pdf,
)
from sphere3d.state import SceneState
from sphere3d.tracing import Hits, face_normals, intersect_triangles
from sphere3d.vector import dot, scatter

__all__ = [
    "PRIMARY_UNIFORMS",
    "EmitterChange",
    "Identity",
    "Members",
    "PixelSamples",
    "Shading",
    "Transforms",
    "add_tangent",
    "camera_radiance",
    "direct",
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
    ``geometric`` is n_g (θ-dependent, as given), None where it is n.
    """

    state: SceneState
    x: Any
    n: Any
    origin: np.ndarray
    draws: Draws
    geometric: Any = None

    @staticmethod
    def at(state: SceneState, x: Any, n: Any, draws: Draws, geometric: Any = None) -> Shading:
        """Shading points ``x``, shading normals ``n`` (offset along the ``geometric`` normals when
        given); ``draws`` keys their random numbers on their samples."""
        offset = detach(n if geometric is None else geometric)
        return Shading(state, x, n, detach(x) + state.epsilon * offset, draws, geometric)

    def __len__(self) -> int:
        return len(self.origin)

    def take(self, index: np.ndarray) -> Shading:
        x, n, g = (None if v is None else v[index] for v in (self.x, self.n, self.geometric))
        return type(self)(self.state, x, n, take_rows(self.origin, index), self.draws.take(index), g)

    def trace(self, mu: np.ndarray) -> Hits:
        """First hits along directions ``mu`` from the shading points (detached)."""
        return self.state.tracer.intersect(self.origin, mu)

    def contributes(self, mu: np.ndarray, hits: Hits) -> np.ndarray:
        """Where the cosine-strategy integrand can be non-zero near θ0: above the surface, and the
        ray escapes to a non-zero sky or reaches the front of an emitter (on paths, also where the
        path goes on: :class:`~sphere3d.path_changes.Onward`).

        Elsewhere the integrand :meth:`evaluate_bsdf` computes is 0 with zero derivative,
        whatever the rotation, so a method may skip those samples.
        """
        state = self.state
        up = dot(detach(self.n), mu) > 0.0
        sky = (float(detach(state.sky)) != 0.0) or state.sky_varies
        emitting = hits.hit & np.isin(hits.triangle, state.emitters)
        tri = np.asarray(detach(state.triangles))[np.where(emitting, hits.triangle, 0)]
        front = dot(face_normals(tri), mu) < 0.0
        return up & ((~hits.hit & sky) | (emitting & front))

    def evaluate_bsdf(self, mu: np.ndarray, rotated: Any, hits: Hits) -> Any:
        r"""The cosine-strategy integrand $L_i(Rμ) \cos θ(Rμ) w_C(Rμ)$ at rotated directions.

        Parameters
        ----------
        mu : ndarray, shape (m, 3)
            Directions drawn independently of θ, along which ``hits`` were traced.
        rotated : Dual or ndarray, shape (m, 3)
            $R·μ$ (value μ); the integrand is re-attached along it.
        hits : Hits, shape (m,)
            :meth:`trace` of ``mu``.
        """
        state = self.state
        m = len(mu)
        cos_x = np.maximum(dot(self.n, rotated), 0.0)
        up = detach(cos_x) > 0.0
        out = scatter(m, np.flatnonzero(up & ~hits.hit), state.sky, state.dual, k=state.k)  # sky: w_C = 1
        e = np.flatnonzero(up & hits.hit & np.isin(hits.triangle, state.emitters))
        if e.size:
            tri = hits.triangle[e]
            it = intersect_triangles(self.x[e], rotated[e], state.triangles[tri])
            cos_y = -dot(it.normal, rotated[e])
            front = detach(cos_y) > 0.0
            e, cos_y, tri, it_t, b1, b2 = (v[front] for v in (e, cos_y, tri, it.t, it.b1, it.b2))
            p_light = solid_angle_pdf(1.0 / state.emitter_area, it_t, cos_y)
            p_cos = cos_x[e] * INV_PI
            # balance heuristic at the rotated direction, θ-dependent on both sides   (MIS, see module doc)
            out[e] = state.emitted(tri, b1, b2) * (p_cos / (p_cos + p_light))
        return out * cos_x


@dataclass(frozen=True)
class PixelSamples:
    r"""Per camera sample: the radiance $L(Rω)$ and the filter weight $k/p · kJ(Rω)/\mathrm{detach}(kJ(Rω))$.

    The estimate of the pixel integral is ``radiance * weight``; the weight's tangent
    has zero mean for a continuous filter (the filter integrates to 1 whatever the
    rotation), which :class:`~sphere3d.tasks.ImageTask` uses as a control variate.
    """

    radiance: Any
    weight: Any
    slot: Any = None  # film splatting: (n, m) stencil slots of the pixels each weight is for (-1: none)

    @property
    def estimate(self) -> Any:
        return self.radiance * self.weight


@dataclass(frozen=True)
class EmitterChange:
    """A method's change of variables of the emitter-sampling strategy at a set of shading points.

    Attributes
    ----------
    rotation : Rotation
        One rotation per row of ``rows``, applied to the emitter samples' directions.
    rows : ndarray of int
        The shading points the rotations are for; every point with an unoccluded emitter sample
        must be among them (the others' samples contribute 0).
    extra : tuple of (ndarray of int, ndarray), optional
        A derivative-only term of E the method adds beside its change of variables: the points
        and their tangents (``reparam``'s emitter edges, :mod:`sphere3d.boundary.emitters`).
    field : optional
        A map per row that replaces the rotation where it has one, with a Jacobian weight:
        ``field.take(rows).apply(ω, rotated) -> (directions, weight or None)``
        (:class:`~sphere3d.reparam.chart_field.ChartField`); None: the rotations only.
    """

    rotation: Rotation
    rows: np.ndarray
    extra: tuple[np.ndarray, np.ndarray] | None = None
    field: Any = None

    def directions(self, place: np.ndarray, omega: np.ndarray) -> tuple[Any, Any]:
        """The evaluation directions of emitter samples ``omega`` (plain, (n, 3)) at rows ``place`` of the
        change, and their Jacobian weight (value 1; None: 1, a rotation's)."""
        rotated = self.rotation.take(place).apply(omega)
        return (rotated, None) if self.field is None else self.field.take(place).apply(omega, rotated)


@dataclass(frozen=True)
class Members:
    r"""Where a method evaluates the cosine-sampled integrand: per sample, one or two members.

    Member j of sample i is estimated as $f(R d_j)\, w_j / (p(μ_i)\, s_j)$; two members are
    combined as a pair (theory/kernels) when ``paired``.

    Attributes
    ----------
    rotated : Dual or ndarray, shape (r, 3), or a tuple of them, one per member
        $R·d$: the evaluation directions (values ``d``, tangents the rotation's).
    rows : ndarray of int, optional
        The samples evaluated; the others contribute 0 (their integrand is 0 with zero
        derivative, :meth:`Shading.contributes`). None: every sample.
    directions : tuple of ndarray, shape (r, 3) each, optional
        θ-free member directions d to trace, one array per member; None: one member, the
        samples μ themselves (their hits reused).
    weights : Dual, shape (r,), or a tuple of them, optional
        Kernel weights of value 1 (Loubet et al. 2019, Sec. 4.2); None: none.
    scale : tuple of Dual, shape (r,) each, optional
        With ``directions``: divides each member's estimate (a kernel mass restored).
    paired : bool
        Two members combined with the paired-sample control variate
        (:func:`~flatland.core.translation.paired_combine`).
    baseline : ndarray, shape (r,), optional
        With one member and ``weights``: a radiance $c$ per sample, known before θ moves and
        depending on the kernel's centre ω only (not on μ). Its control variate (theory/kernels)
        is subtracted: $c\, (q - \mathrm{detach}(q)) / p(μ)$ with $q = p(Rμ)\, w$, value 0.
    centre : ndarray, shape (r, 3), optional
        With ``weights``: the kernels' centres ω (plain, unit), for a control variate of the radiance
        a path carries on along the samples (:mod:`sphere3d.path_changes`).
    """

    rotated: Any
    rows: np.ndarray | None = None
    directions: np.ndarray | None = None
    weights: Any = None
    scale: Any = None
    paired: bool = False
    baseline: np.ndarray | None = None
    centre: np.ndarray | None = None


class Transforms(Protocol):
    """How a method changes variables in the renderer's integrals, and the terms it adds (module docstring).

    The same seam as flatland's (:class:`flatland.integrator.Transforms`): one change of variables
    per integral, and derivative-only terms through ``shading_extra`` and ``pixel_extra``.
    :class:`Identity` implements all five; a method subclasses it and overrides what it changes.
    """

    def camera(self, state: SceneState, x: np.ndarray, y: np.ndarray, draws: Draws) -> FilmTransform:
        """One rotation (and film kernel) per camera sample at film point (x, y), pixels; one row of
        ``draws`` per sample."""
        ...

    def emitter(self, shading: Shading, visible: np.ndarray, bsdf: Any = None) -> EmitterChange:
        """Rotations for the emitter-sampling strategy at least where ``visible`` (bool, one per shading
        point: its emitter sample is unoccluded); draws: ``shading.draws``; ``bsdf``: glossy points'
        :class:`~sphere3d.glossy.Lobe` (None: diffuse), for the ``extra`` term's integrand."""
        ...

    def bsdf(self, shading: Shading, mu: np.ndarray, hits: Hits, lobe: Any = None) -> Members:
        r"""Where to evaluate the cosine-sampled integrand for samples $μ \sim \cos$ (``hits``: their
        first hits, :meth:`Shading.trace`); random numbers from ``shading.draws``. ``lobe``: at glossy
        points (BSDF samples), their :class:`~sphere3d.glossy.Lobe` at θ0 (None: diffuse)."""
        ...

    def shading_extra(self, shading: Shading, weight: Any = None) -> np.ndarray | None:
        r"""A derivative-only term added to E at each shading point (None: nothing); with ``weight(rows,
        ω)`` (plain BSDF values at θ0, :mod:`sphere3d.glossy`) the term of $∫ L_i\, weight \cos θ\, dω$."""
        ...

    def pixel_extra(self, task: Any, state: SceneState) -> np.ndarray | None:
        """A derivative-only term per batch and pixel, shape (batches, height, width) (None: nothing)."""
        ...


class Identity:
    """No change of variables: the renderer as it stands (the naive estimator, Sec. 3.1)."""

    def camera(self, state: SceneState, x: np.ndarray, y: np.ndarray, draws: Draws) -> FilmTransform:
        return FilmTransform.identity(x.shape, state.k)

    def emitter(self, shading: Shading, visible: np.ndarray, bsdf: Any = None) -> EmitterChange:
        rows = np.flatnonzero(visible)
        return EmitterChange(Rotation.identity((len(rows),), shading.state.k), rows)

    def bsdf(self, shading: Shading, mu: np.ndarray, hits: Hits, lobe: Any = None) -> Members:
        return Members(mu if not shading.state.dual else Dual(mu, None, shading.state.k))

    def shading_extra(self, shading: Shading, weight: Any = None) -> np.ndarray | None:
        return None

    def pixel_extra(self, task: Any, state: SceneState) -> np.ndarray | None:
        return None


def _emitter_term(shading: Shading, u: np.ndarray, transforms: Transforms) -> Any:
    """Emitter-sampling estimate of E, MIS-weighted, per shading point."""
    state = shading.state
    m = len(shading)
    e = emitter_directions(
        u, np.asarray(detach(state.triangles))[state.emitters], detach(shading.x), detach(shading.n)
    )
    tri, w, dist, cos_y = state.emitters[e.index], e.w, e.dist, e.cos_y
    valid = (cos_y > 1e-9) & (e.cos_x > 0.0) & (dist > 4.0 * state.epsilon)
    idx = np.flatnonzero(valid)
    origin, direction = take_rows(shading.origin, idx), take_rows(w, idx)
    blocked = state.tracer.occluded(origin, direction, dist[idx] - 2.0 * state.epsilon)
    vis = idx[~blocked]
    visible = np.isin(np.arange(m), vis)  # bool, True at the unoccluded samples
    change = transforms.emitter(shading, visible)
    if vis.size == 0 and change.extra is None:
        return scatter(m, vis, 0.0, state.dual, k=state.k)
    place = np.empty(m, dtype=np.intp)  # row of each point's rotation in the change
    place[change.rows] = np.arange(len(change.rows))
    # tangents only where the point moves, its rotation turns, or an emitter changes (sphere3d.live)
    points_move, lights_change = moving_rows(vis, shading.x, shading.n), emitters_change(state)
    live = change.rotation.active[place[vis]] | points_move | lights_change
    plain, inv_area = state.detached(), 1.0 / float(detach(state.emitter_area))
    # operands whose tangents are all 0 enter plain: the Dual rules give a constant the tangent 0, the same
    # numbers (flatland.core.dual_ufuncs), and skip the products with it
    lights, attached = (state if lights_change else plain), bool(points_move.any())

    def estimate(dual: bool, x: Any, n: Any, omega: np.ndarray, row: Any, t: Any, d: Any, c: Any) -> tuple:
        st, (rotated, jacobian) = (lights, change.directions(row, omega)) if dual else (plain, (omega, None))
        x, n = (x, n) if attached else (detach(x), detach(n))
        # re-attach: the rotated ray from the moving shading point meets the sampled emitter triangle
        it = intersect_triangles(x, rotated, st.triangles[t])
        cos_x_d = np.maximum(dot(n, rotated), 0.0)
        cos_y_d = -dot(it.normal, rotated)
        p_light = solid_angle_pdf(1.0 / st.emitter_area, it.t, cos_y_d)
        p_cos = cos_x_d * INV_PI
        f = st.emitted(t, it.b1, it.b2) * cos_x_d
        # divided by the θ-free sampling density in solid angle: p_A d² / cos θ_y, p_A = 1 / area at θ0
        f = f * (p_light / (p_light + p_cos)) / solid_angle_pdf(inv_area, d, c)
        return (f if jacobian is None else f * jacobian,)  # a field's change of variables: its |J|

    (f,) = on_rows(estimate, vis, live, shading.x, shading.n, w, place, tri, dist, cos_y)
    out = scatter(m, vis, f, state.dual)
    return out if change.extra is None else add_tangent(out, *change.extra)


def add_tangent(estimate: Dual, index: np.ndarray, term: np.ndarray) -> Dual:
    """``estimate`` with ``term`` added to the tangents at ``index`` (for k tangents ``term`` is (k, n),
    added to every slot): the value, bit for bit, unchanged."""
    t = estimate.tangent.copy()
    np.add.at(t, index if estimate.k is None else (slice(None), index), term)
    return Dual(estimate.value, t, estimate.k)


def _bsdf_term(shading: Shading, mu: np.ndarray, pdf: np.ndarray, transforms: Transforms, hits: Hits) -> Any:
    """Cosine-sampling estimate of E per shading point, at the method's :class:`Members` (``hits``: μ's)."""
    members = transforms.bsdf(shading, mu, hits)
    rows = members.rows
    sub, p = (shading, pdf) if rows is None else (shading.take(rows), pdf[rows])
    if members.directions is None:  # the samples μ themselves
        mu_r, hits_r = (mu, hits) if rows is None else (mu[rows], hits.take(rows))
        f = sub.evaluate_bsdf(mu_r, members.rotated, hits_r)
        est = f / p if members.weights is None else f * members.weights / p
        if members.baseline is not None:
            # ∫ p(R_ω μ) k(R_ω μ, ω) |J| dμ = ∫ p(y) k(y, ω) dy for every ω: the tangent of
            # q = p(Rμ) w (the cosine density at the rotated direction, about the detached normal,
            # times the kernel weight) has zero mean given ω, and c(ω) q / p(μ) is a control
            # variate for f w / p wherever the integrand is c cos θ around the kernel's centre
            q = np.maximum(dot(detach(sub.n), members.rotated), 0.0) * INV_PI * members.weights
            est = est - members.baseline * (q - detach(q)) / p
    else:  # one or two members per sample, traced here
        e = []
        for d, rotated, w, scale in zip(
            members.directions, members.rotated, members.weights, members.scale, strict=True
        ):  # a loop over the members, not over samples
            e.append(sub.evaluate_bsdf(d, rotated, sub.trace(d)) * w / (p * scale))
        # each weight's derivative has zero mean given the kernel centre and is independent of the other
        # member: a control variate scaled by the other member's estimate   (paired samples, theory/kernels)
        est = paired_combine(*e, *members.weights) if members.paired else e[0]
    return est if rows is None else scatter(len(mu), rows, est, shading.state.dual)


def irradiance_samples(shading: Shading, u: np.ndarray, transforms: Transforms, bounce: bool = False) -> Any:
    r"""One MIS estimate of $E = ∫ L_i \cos θ\, dω$ per shading point
    (uniforms ``u``: 3 emitter + 2 cosine).

    With ``bounce``, ``(E, μ, hits)``: also the cosine samples μ (plain, unit) and their first hits,
    the rays a path continues along (:mod:`sphere3d.paths`).
    """
    state = shading.state
    total = 0.0
    if len(state.emitters):
        total = total + _emitter_term(shading, u[:, 0:3], transforms)
    n0 = detach(shading.n)
    mu = sample_cosine_hemisphere(u[:, 3:5], n0)
    pdf = pdf_cosine_hemisphere(mu, n0)
    hits = shading.trace(mu)
    bsdf = _bsdf_term(shading, mu, pdf, transforms, hits)
    extra = transforms.shading_extra(shading)
    if extra is not None:
        bsdf = bsdf + Dual(np.zeros(len(shading)), extra, state.k)  # the value is untouched (+ 0.0)
    return (total + bsdf, mu, hits) if bounce else total + bsdf


def direct(shading: Shading, u: np.ndarray, albedo: Any, transforms: Transforms, shape: Any = None) -> Any:
    r"""The radiance $ρ/π\, E$ a diffuse surface of ``albedo`` reflects at shading points: direct
    illumination, the default ``vertex`` of :func:`camera_radiance` (``shape``, the points' shapes,
    unused: every shape of a scene without glossy ones is diffuse)."""
    return albedo * INV_PI * irradiance_samples(shading, u, transforms)


def pixel_samples(
    state: SceneState,
    transforms: Transforms,
    rows: np.ndarray,
    cols: np.ndarray,
    u: np.ndarray,
    draws: Draws,
    splat: Any = None,
    vertex: Any = None,
) -> Any:
    """One estimate of the pixel integral per sample (pixel ``rows``, ``cols``; uniforms ``u``).

    With tangents, ``transforms.camera`` gives each sample its rotations and film kernels.
    The estimate is ``radiance * weight`` (:class:`PixelSamples`); both are Duals when the
    state carries tangents. ``draws`` keys the samples' further random numbers on their indices.
    ``splat(x, y)``: a :class:`~sphere3d.film.Splat` of the film points (x, y), whose weights
    (n, m), one per reached pixel, replace k / p (film splatting, :mod:`sphere3d.film`). ``vertex``:
    what a diffuse hit reflects, as in :func:`camera_radiance`.
    """
    cam = state.camera
    offsets = sample_filter(u[:, 0:2], cam.filter)
    weight = filter_value(offsets, cam.filter) / pdf_filter(offsets, cam.filter)  # k / p, θ-free
    cx, cy = cols + 0.5, rows + 0.5
    x, y = cx + offsets[:, 0], cy + offsets[:, 1]
    d = cam.directions(x, y)
    if splat is not None:
        splat = splat(x, y)
        weight = splat.weight  # k(s - p) / q(s) per reached pixel p, θ-free
    if state.dual:
        film = transforms.camera(state, x, y, draws)
        # only rows where a rotation moves: elsewhere every tangent below is exactly 0
        live = np.flatnonzero(np.any([film.active(m) for m in range(len(film.rotations))], axis=0))
        k = state.k  # None, or k parameters: the tangents' leading axis
        r_dot, w_dot = (np.zeros(s if k is None else (k, *s)) for s in (d.shape, np.shape(weight)))
        for member in range(len(film.rotations)):  # one or two (not a loop over samples)
            r, affine = film.directions(member, cam, take_rows(d, live), live)
            fx, fy = cam.film(r)
            log_j = film.log_jacobian(cam, r, affine)
            # k(film(Rω)) J(Rω) g(film(Rω) - c) / detach(...): value 1, derivative of the filter and the
            # film kernel under the rotation (theory/pixel_filters; Loubet et al. 2019, Sec. 4.2)
            if splat is None:
                log_k = log_filter_value(np.stack([fx - cx[live], fy - cy[live]], axis=-1), cam.filter)
                w = unit_weight(log_k + log_j + film.log_kernel(member, fx, fy, live))
                w_dot[live if k is None else (slice(None), live)] += tangent(w)
            else:  # the same with each reached pixel's centre (sphere3d.film): its tangent only
                rest = log_j + film.log_kernel(member, fx, fy, live)
                w_dot[live if k is None else (slice(None), live)] += splat.weight_tangents(
                    fx, fy, rest, live, cam.filter
                )
            r_dot[live if k is None else (slice(None), live)] += tangent(r)
        # the mean of the estimates under each rotation, w L(Rω) averaged: the radiance's tangent is
        # linear in the direction's, so one evaluation along the mean tangent gives the mean of
        # the tangents; values exactly ω and 1 (the primal stays the naive one)
        m = len(film.rotations)
        if splat is None:
            rotated, weight = Dual(d, r_dot / m, k), weight * Dual(np.ones(np.shape(weight)), w_dot / m, k)
        else:  # the same product, written out: value weight, tangent weight · ẇ / m
            rotated, weight = Dual(d, r_dot / m, k), Dual(weight, weight * (w_dot / m), k)
    else:
        rotated = d
    slot = None if splat is None else splat.slot
    radiance = camera_radiance(state, transforms, d, rotated, u[:, 2:7], draws, vertex=vertex)
    return PixelSamples(radiance, weight, slot)


def camera_radiance(
    state: SceneState,
    transforms: Transforms,
    d: np.ndarray,
    rotated: Any,
    u: np.ndarray,
    draws: Draws,
    hits: Hits | None = None,
    vertex: Any = None,
) -> Any:
    r"""Radiance arriving at the camera along unit directions ``d`` (plain), re-attached along ``rotated``.

    Emission of the first hit's front side plus $ρ/π\, E$ at diffuse hits, E estimated
    with the shading uniforms ``u`` (n, 5) under ``transforms``; the sky where a ray misses.
    ``hits``: the rays' hits if the caller knows them (only ``shape`` and ``triangle`` are
    read), else they are traced. ``vertex(shading, u, albedo, transforms, shape)``: the radiance the hits
    reflect; None: :func:`direct` (the paths and glossy shapes of :mod:`sphere3d.paths` pass theirs).
    """
    n = len(d)
    cam = state.camera
    if hits is None:
        hits = state.tracer.intersect(detach(cam.origin), d)
    hit = np.flatnonzero(hits.hit)
    miss = np.flatnonzero(~hits.hit)
    radiance = scatter(n, miss, state.sky, state.dual, k=state.k)
    if hit.size:
        tri, plain = hits.triangle[hit], state.detached()

        def attach(dual: bool, direction: Any, t: np.ndarray) -> tuple[Any, ...]:
            st = state if dual else plain
            it = intersect_triangles(st.camera.origin, direction, st.triangles[t])
            front = dot(detach(it.normal), detach(direction)) < 0.0  # arriving on the side the normal faces
            side = np.where(front[:, None], 1.0, -1.0)
            # smooth shapes shade with interpolated vertex normals; face normals otherwise (the same object)
            normal = st.shading_normals(t, it.b1, it.b2, it.normal)
            geometric = it.normal * side
            shade_n = geometric if normal is it.normal else normal * side
            return it.point, geometric, shade_n, st.emitted(t, it.b1, it.b2) * front

        # tangents only where the direction turns, the camera or the hit triangle moves (sphere3d.live)
        live = moving_rows(hit, rotated) | triangles_change(state)[tri] | np.any(moves(cam.origin))
        if state.dual:
            point, geometric, shade_n, value = on_rows(attach, hit, live, rotated, hits.triangle)
        else:
            point, geometric, shade_n, value = attach(False, rotated[hit], tri)
        shape = state.shape_of[tri]
        albedo = state.albedo[shape]
        diffuse = (detach(albedo) > 0.0) | state.albedo_varies[shape]
        s = np.flatnonzero(diffuse)
        if s.size:
            s = slice(None) if s.size == hit.size else s  # all diffuse: views, not copies
            shading = Shading.at(state, point[s], shade_n[s], draws.take(hit[s]), geometric[s])
            reflected = (vertex or direct)(shading, u[hit[s]], albedo[s], transforms, shape[s])
            value = value + scatter(hit.size, s, reflected, state.dual)
        radiance[hit] = value
    return radiance
