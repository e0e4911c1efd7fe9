r"""The estimator as published: one rotation per integral from probe rays, vMF kernels, paired samples.

Loubet et al. 2019, Sec. 4.1-4.3, with the reference parameters of the authors' implementation
(``reparam`` option ``variant="paper"``). Every integral's samples ω are evaluated at
$R(θ)·ω$, R the identity at θ0 that moves like one point p chosen by probe rays,
$|\det J| = 1$ (Sec. 4.1). The three integrals of :mod:`sphere3d.integrator`:

- **pixel integral**: a Gaussian film kernel g of concentration ``kappa_film`` (the authors'
  camera kernel $κ = 1 / (1 - \cos(0.4 · \mathrm{pixel\ angle}))$ read on the film), one kernel
  per camera sample; ``probes`` probe rays drawn from the kernel around its centre choose R
  (Sec. 4.2, 4.3); the weight $g(\mathrm{film}(Rω) - c) / \mathrm{detach}(\cdot)$ (value 1) next to the
  filter's. The kernel's centre c is drawn around the filter sample s, $c \sim g(· - s)$, the
  paper's order $ω \sim p, μ \sim k(·, ω)$ read the other way (g is symmetric: the same joint
  density), so the evaluation stays at s and the primal is the naive one;
- **emitter sampling**: ``emitter_probes`` shadow rays to points uniform on the emitters; R follows the
  mean attached hit of the occluded ones, one rotation for all light samples of a shading
  point (the authors' rule); the identity where none is occluded;
- **cosine sampling**: the vMF convolution of concentration ``kappa`` in the paper's order: the
  cosine sample ω is the kernel's centre, two kernel samples μ ~ vMF(ω, κ) share the rotation
  chosen by ``probes`` probes drawn from the same kernel, and the paired-sample control
  variate of the authors' implementation combines them (theory/kernels); the kernel mass below
  the horizon is restored (:func:`~sphere3d.sampling.vmf_hemisphere_fraction`).

The probe rule (:func:`choose`, Sec. 4.3): pair probe 0 with the last probe that sees a
different shape; if only one of the two hits, follow its hit; if both hit and exactly one's
tangent plane separates the other hit from the ray origin, follow the point on that occluder;
nearly parallel normals ($|n_0·n_1| >$ :data:`PARALLEL`): p0; else the intersection of the two
tangent planes with the plane through o spanned by the two probe directions (p0 where that
system is degenerate or the point lies behind o). The point is attached: recomputed from the
hit triangle's θ-dependent vertices with detached barycentrics.

Where it is biased (derived in the theory pages *probes* and *extensions*; measured in the
generated measurement tables): a kernel whose random probes miss a discontinuity inside its
support (the probes are few and random); a rotation that follows an interior point of a
shape rather than its silhouette drifts from the silhouette's motion by the point's distance
times the image's rate of scaling or turning; discontinuities that move differently inside
one kernel (a T-junction, the corner of a small triangle); and the emitters' own sharp
edges, which the emitter rotation drags whenever it follows an occluder (the authors used
emitters whose radiance fades to zero at the border, ``fade`` in the scene files, to avoid
them). :mod:`sphere3d.reparam.default` adds the extensions that remove these.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core.dual import detach
from flatland.core.rng import Draws
from flatland.core.translation import unit_weight
from sphere3d.film import FilmTransform
from sphere3d.integrator import EmitterChange, Identity, Members, Shading
from sphere3d.rotation import Rotation
from sphere3d.sampling import sample_mesh, sample_vmf, vmf_hemisphere_fraction
from sphere3d.state import SceneState
from sphere3d.tracing import Hits, attached_points, face_normals
from sphere3d.vector import cross, dot, norm

__all__ = [
    "DEGENERATE",
    "PARALLEL",
    "PaperTransforms",
    "ProbeChoice",
    "choose",
    "direction_towards",
    "mean_point_direction",
    "pair_index",
]

PARALLEL = 0.99
"""|n0·n1| above which the two tangent planes count as parallel (Loubet et al. 2019, Sec. 4.3)."""
DEGENERATE = 1e-6
"""|det| of the plane system below which the intersection is ill-conditioned."""


# ------------------------------------------------------------------ the probe rule (Sec. 4.3)
def pair_index(shape: np.ndarray) -> np.ndarray:
    """Per row, the last probe whose shape differs from probe 0's (0 if none, as always with one probe).

    Parameters
    ----------
    shape : ndarray of int, shape (m, P)
        Hit shape per probe, -1 for a miss.
    """
    if shape.shape[1] < 2:  # a single probe has no partner: it stands alone (argmax of nothing fails)
        return np.zeros(shape.shape[0], dtype=np.intp)
    different = shape[:, 1:] != shape[:, :1]
    last = shape.shape[1] - 1 - np.argmax(different[:, ::-1], axis=1)
    return np.where(different.any(axis=1), last, 0)


@dataclass
class ProbeChoice:
    """The rule's decision per row of probes: the pair, its attached hits, which point is followed.

    ``p0``, ``p1`` (Duals, (m, 3)) are the attached hits of probe 0 and its partner ``j``;
    ``use_p1`` / ``use_cross`` say whether p1 or the tangent planes' crossing is followed (else
    p0); ``single`` are the rows that follow one probe's hit while its partner sees something
    else (``first``: that probe is probe 0), where the point could be moved toward the
    silhouette between the two (:mod:`sphere3d.reparam.probes`). Mutable: a refinement
    replaces ``p0`` / ``p1`` at ``single`` before :meth:`point`.
    """

    j: np.ndarray
    d0: np.ndarray
    d1: np.ndarray
    h0: Hits
    h1: Hits
    t0: Any
    t1: Any
    p0: Any
    p1: Any
    o: Any
    mv: np.ndarray
    use_p1: np.ndarray
    use_cross: np.ndarray
    found: np.ndarray
    single: np.ndarray
    first: np.ndarray

    def point(self) -> Any:
        """The followed point per row (Dual, (m, 3)); meaningful where :attr:`found`."""
        point = np.where(np.repeat(self.use_p1[:, None], 3, axis=1), self.p1, self.p0)
        c = np.flatnonzero(self.use_cross)
        if c.size:  # with tangents only where the crossing is used (row by row the same numbers)
            n0, n1 = face_normals(self.t0[c]), face_normals(self.t1[c])
            point[c] = _crossing(n0, n1, self.p0[c], self.p1[c], self.o[c], self.mv[c])[0]
        return point


def _crossing(n0: Any, n1: Any, p0: Any, p1: Any, o: Any, mv: Any) -> tuple[Any, Any]:
    r"""Where the tangent planes $(p_k, n_k)$ and the plane through o with unit normal m meet:
    $x = (h_0 (n_1 × m) + h_1 (m × n_0) + h_2 (n_0 × n_1)) / (n_0 · (n_1 × m))$, $h_k = n_k · p_k$,
    $h_2 = m · o$; and the determinant. The same expression on values and on Duals."""
    n1xm = cross(n1, mv)
    det = dot(n0, n1xm)
    safe_det = np.where(np.abs(detach(det)) > DEGENERATE, det, 1.0)
    return (dot(n0, p0)[:, None] * n1xm + dot(n1, p1)[:, None] * cross(mv, n0)
            + dot(mv, o)[:, None] * cross(n0, n1)) / safe_det[:, None], det  # fmt: skip


def choose(state: SceneState, origin: Any, directions: np.ndarray, hits: Hits) -> ProbeChoice:
    """The probe rule of Sec. 4.3 (module docstring) per row of probes.

    Parameters
    ----------
    state : SceneState
        For the θ-dependent triangles.
    origin : Dual or ndarray, shape (m, 3) or (3,)
        The probe rays' origin, re-attached (it may move with θ).
    directions : ndarray, shape (m, P, 3)
        Probe directions (θ-free).
    hits : Hits, shape (m, P)
        Their first hits; probes below a shading point's horizon must count as misses.
    """
    m = directions.shape[0]
    rows = np.arange(m)
    j = pair_index(hits.shape)
    hit0 = hits.shape[:, 0] >= 0
    hit1 = (hits.shape[rows, j] >= 0) & (j != 0)
    d0, d1 = directions[:, 0], directions[rows, j]
    h0, h1 = hits.take((rows, 0)), hits.take((rows, j))
    t0 = state.triangles[np.maximum(h0.triangle, 0)]
    t1 = state.triangles[np.maximum(h1.triangle, 0)]
    p0 = attached_points(t0, h0.u, h0.v)
    p1 = attached_points(t1, h1.u, h1.v)
    # the normals' values for every row; their tangents only where the crossing is used (ProbeChoice.point)
    n0v, n1v = face_normals(detach(t0)), face_normals(detach(t1))
    o = origin + 0.0 * p0  # broadcast to (m, 3)
    p0v, p1v, ov = detach(p0), detach(p1), detach(o)
    # tangent plane k separates the other hit from the origin: shape k occludes the other   (Sec. 4.3)
    occ0 = dot(n0v, p1v - p0v) * dot(n0v, ov - p0v) < 0.0
    occ1 = dot(n1v, p0v - p1v) * dot(n1v, ov - p1v) < 0.0
    parallel = np.abs(dot(n0v, n1v)) > PARALLEL
    # the plane through o spanned by the two probe directions, unit normal m
    mv = cross(d0, d1)
    m_len = norm(mv)
    mv = mv / np.where(m_len > 0.0, m_len, 1.0)[:, None]
    crossing, det = _crossing(n0v, n1v, p0v, p1v, ov, mv)
    ok = (np.abs(det) > DEGENERATE) & (m_len > 1e-12)
    ok = ok & (dot(crossing - ov, d0 + d1) > 0.0)  # in front of o, between the probes

    both = hit0 & hit1
    use_cross = both & ~(occ0 ^ occ1) & ~parallel & ok
    use_p1 = (hit1 & ~hit0) | (both & occ1 & ~occ0)
    use_p0 = hit0 & ~use_p1 & ~use_cross
    single = np.flatnonzero((use_p0 | use_p1) & (j != 0))
    return ProbeChoice(
        j, d0, d1, h0, h1, t0, t1, p0, p1, o, mv, use_p1, use_cross, hit0 | hit1, single, use_p0[single]
    )


def direction_towards(point: Any, origin: Any, found: np.ndarray) -> tuple[Any, np.ndarray]:
    """point - origin (Dual), and ``found`` cleared where its direction is undefined."""
    to = point - origin
    length = norm(detach(to))  # the value only
    return to, found & (length > 0.0) & np.isfinite(length)


def mean_point_direction(origin: Any, points: Any, mask: np.ndarray) -> tuple[Any, np.ndarray]:
    """Direction (not normalized) from ``origin`` (m, 3) to the mean of the attached ``points``
    (m, P, 3) where ``mask`` (m, P), and where some probe counts (the rotation is the identity
    elsewhere)."""
    count = mask.sum(axis=1)
    total = np.einsum("mpk,mp->mk", points, mask.astype(np.float64))
    return direction_towards(total / np.maximum(count, 1)[:, None], origin, count > 0)


def follow(state: SceneState, origin: Any, directions: np.ndarray, hits: Hits) -> Rotation:
    """The rotation following the point the rule chooses (the identity where no probe hits)."""
    choice = choose(state, origin, directions, hits)
    to, found = direction_towards(choice.point(), origin, choice.found)
    return Rotation.following(to, found)


# ------------------------------------------------------------------ the three integrals
@dataclass(frozen=True)
class PaperTransforms(Identity):
    r"""The published estimator's changes of variables (module docstring).

    Attributes
    ----------
    kappa : float
        vMF concentration of the cosine strategy's kernel (the authors' 1000).
    kappa_film : float
        1 / variance of the Gaussian film kernel, $\mathrm{pixels}^{-2}$.
    probes : int
        Probe rays per kernel (the authors' 4), all drawn from the kernel.
    emitter_probes : int
        Shadow probes per shading point, uniform on the emitters (the authors' 4).
    """

    kappa: float
    kappa_film: float
    probes: int
    emitter_probes: int

    def camera(self, state: SceneState, x: np.ndarray, y: np.ndarray, draws: Draws) -> FilmTransform:
        """One rotation per camera sample from probes drawn from its film kernel (Sec. 4.2, 4.3)."""
        cam = state.camera
        sigma = 1.0 / math.sqrt(self.kappa_film)
        # c ~ g(· - s) around the sample s: the paper's order read the other way (module docstring)
        centre = np.stack([x, y], axis=-1) + sigma * draws.normals("kernel.film", 2)
        film = centre[:, None] + sigma * draws.normals("probes.film.kernel", self.probes, 2)
        d = cam.directions(film[..., 0], film[..., 1])
        hits = state.tracer.intersect(detach(cam.origin), d)
        return FilmTransform((follow(state, cam.origin, d, hits),), (centre,), self.kappa_film)

    def emitter(self, shading: Shading, visible: np.ndarray, bsdf: Any = None) -> EmitterChange:
        """The mean attached hit of the occluded shadow probes, one rotation per shading point."""
        rows = np.flatnonzero(visible)
        sub = shading.take(rows)
        state = shading.state
        u = sub.draws.uniforms("probes.emitter", self.emitter_probes, 3)
        emitters = np.asarray(detach(state.triangles))[state.emitters]
        y, _ = sample_mesh(u, emitters)
        to = y - detach(sub.x)[:, None]
        dist = norm(to)
        w = to / np.where(dist > 0.0, dist, 1.0)[..., None]
        # light samples the strategy could use: above the surface, beyond the rays' offsets
        usable = (dot(w, detach(sub.n)[:, None]) > 0.0) & (dist > 4.0 * state.epsilon)
        tmax = np.maximum(dist - 2.0 * state.epsilon, 0.0)
        hits = state.tracer.intersect(sub.origin[:, None], w, tmax)
        occluded = hits.hit & usable
        points = attached_points(state.triangles[np.where(occluded, hits.triangle, 0)], hits.u, hits.v)
        to_point, found = mean_point_direction(sub.x, points, occluded)
        return EmitterChange(Rotation.following(to_point, found), rows)

    def _kernel_rotation(self, shading: Shading, centre: np.ndarray) -> Rotation:
        """The rotation from ``probes`` probes drawn from the vMF kernel around ``centre`` (m, 3)."""
        u = shading.draws.uniforms("probes.bsdf.kernel", self.probes, 2)
        d = sample_vmf(u, centre[:, None], self.kappa)
        hits = shading.state.tracer.intersect(shading.origin[:, None], d)
        # a probe below the horizon sees the surface it leaves, where the integrand is 0: a miss
        hits = hits.without(dot(d, detach(shading.n)[:, None]) <= 0.0)
        return follow(shading.state, shading.x, d, hits)

    def bsdf(self, shading: Shading, mu: np.ndarray, hits: Hits, lobe: Any = None) -> Members:
        r"""Two kernel samples around the cosine sample share one rotation (paired samples); one κ at
        every point (``lobe`` unused: the published kernel, refused on glossy shapes)."""
        rotation = self._kernel_rotation(shading, mu)
        u = shading.draws.uniforms("kernel.bsdf.pair", 2, 2)
        members, rotated, weights, mass = [], [], [], []
        for j in range(2):  # the two members of each pair (not a loop over samples)
            member = sample_vmf(u[:, j], mu, self.kappa)
            r = rotation.apply(member)
            members.append(member)
            rotated.append(r)
            # k(Rμ, ω) / detach(k(Rμ, ω)): value 1 (Sec. 4.2); the vMF normalization cancels
            weights.append(unit_weight(self.kappa * dot(r, mu)))
            # ∫_H k(y, ω) dω = C(n·y): the kernel mass below the horizon restored (sampling)
            c = vmf_hemisphere_fraction(dot(r, detach(shading.n)), self.kappa)
            mass.append(np.where(detach(c) > 0.0, c, 1.0))
        return Members(tuple(rotated), None, tuple(members), tuple(weights), tuple(mass), paired=True)
