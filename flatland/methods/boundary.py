"""The boundary method: naive interior term plus the exact discontinuity terms (edge sampling in 2D).

Where the integrator calls it: one ``task.evaluate(task.dual_offset(), BoundaryTransforms())``
(``variable(0.0)``, or ``variables(k)`` for k parameters: one pass, the jump terms times each
parameter's velocity).
``camera`` and ``directions`` stay the identity (the naive interior term); the
2D-only extension points of :class:`~flatland.integrator.Transforms` carry the rest:
``shading_extra`` adds the jump terms seen from each shading point inside
:func:`~flatland.integrator.shade`, after its MIS estimate; ``pixel_extra`` adds the
camera's jump terms per batch and pixel after the sums (images only).

Loubet et al. 2019 compare against edge sampling (Li et al. 2018); in flatland the
discontinuities of every integrand are points that can be enumerated, so the
Leibniz rule's jump term (theory/leibniz, theory/boundary) is computed exactly instead of sampled.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flatland import glossy
from flatland.core.dual import detach, tangent
from flatland.core.rng import Draws, stream
from flatland.glossy import Lobe
from flatland.integrator import Context, Identity, incident, radiance_along_film
from flatland.lights import Lights
from flatland.methods._common import GRADIENT_METHODS, direct_only
from flatland.sampling import filter_value
from flatland.state import SceneState
from flatland.tasks import ImageTask, PointTask, Tally
from flatland.tracing import cast, direction, film_coordinate, silhouette_angles

__all__ = ["BoundaryTransforms", "boundary"]

EPS_ANGLE = 1e-7
"""Angular offset (radians) of the two rays traced beside a candidate discontinuity."""

MAX_CANDIDATES = 1 << 18
"""Shading points × candidate discontinuities handled together (bounds memory in vertex-rich scenes)."""

EPS_FILM = 1e-7
"""Film-coordinate offset (relative to $1 + |t|$) of the two camera rays beside a candidate."""


class BoundaryTransforms(Identity):
    """Identity transforms plus the jump terms at the shading points and at the pixels."""

    def shading_extra(
        self, ctx: Context, x: Any, normal: Any, ignore: np.ndarray, lobe: Lobe | None = None
    ) -> np.ndarray:
        r"""$Σ_c [f(c^-) - f(c^+)] φ_c'(θ)$ of the integrand $f = L_i \cos$ of E at each shading point.

        Candidates c are the angles of all vertices and circle tangent points seen from
        x(θ) (Duals: they move with the geometry and with x); only those in front of the
        surface (cos > 0) can matter, since f vanishes behind it. The jump is found by
        tracing at $c ∓ ε$ on the detached geometry. For k parameters the term has a leading
        axis of k: the same jumps times each parameter's $φ_c'$. With a ``lobe`` (glossy scenes) the
        integrand is $L_i w$ of the reflected radiance (:mod:`flatland.glossy`): the lobe w is continuous
        in φ, so the jump is $w(c) [L_i(c^-) - L_i(c^+)]$, w evaluated at the jump direction.
        """
        n, k = ignore.size, ctx.geom.k
        out = np.zeros(n if k is None else (k, n))
        m = np.shape(detach(ctx.geom.vertices))[0] + 2 * ctx.geom.n_circ
        step = max(1, MAX_CANDIDATES // max(m, 1))
        for lo in range(0, n, step):  # blocks of shading points: (points x candidates) stays bounded
            sl = slice(lo, min(n, lo + step))
            part = None if lobe is None else lobe.take(np.arange(sl.start, sl.stop))
            out[..., sl] = self._jumps(ctx, x[sl], detach(normal)[sl], ignore[sl], part)
        return out

    @staticmethod
    def _jumps(
        ctx: Context, x: Any, n0: np.ndarray, ignore: np.ndarray, lobe: Lobe | None
    ) -> np.ndarray | float:
        n = ignore.size
        phi_c, exists = silhouette_angles(ctx.geom, x)
        if phi_c.shape[1] == 0:
            return 0.0
        phi0 = detach(phi_c)
        phi_n0 = np.arctan2(n0[:, 1], n0[:, 0])
        cos_c = np.cos(phi0 - phi_n0[:, None])
        rows, cols = np.nonzero(exists & (cos_c > 1e-12))
        if not rows.size:
            return 0.0
        phi = phi0[rows, cols]
        origins = detach(x)[rows]
        sides = []
        for sign in (-1.0, 1.0):  # c⁻ then c⁺
            d = direction(phi + sign * EPS_ANGLE)
            hits = cast(ctx.geom0, origins, d, ignore[rows])
            sides.append(incident(ctx.geom0, origins, d, hits)[0])
        # the integrand's smooth factor at c: the cosine of E, or the lobe w(c) of L_r
        w = cos_c[rows, cols] if lobe is None else glossy.weight_plain(lobe.take(rows), phi, phi_n0[rows])
        # discontinuity term: (f(c-) - f(c+)) * dc/dtheta   (Leibniz rule, theory/leibniz)
        term = (sides[0] - sides[1]) * w * tangent(phi_c[rows, cols])
        if term.ndim == 1:
            return np.bincount(rows, weights=term, minlength=n)
        return np.stack([np.bincount(rows, weights=slot, minlength=n) for slot in term])  # k parameters

    def pixel_extra(self, task: ImageTask, geom: SceneState) -> np.ndarray | None:
        """$Σ_c k_j(t_c) [L(t_c^-) - L(t_c^+)] t_c'(θ)$ per batch and pixel (the camera's silhouettes).

        Candidates are the film coordinates $t_c(θ)$ of every vertex and circle tangent
        point seen from the camera (in front of it), as Duals: $t_c'$ includes the motion
        of the shapes and of the camera. The jump of the full radiance $L = L_e + (ρ/2) E$
        is estimated per batch with ``spp / batches`` shading samples on each side, the
        same samples on both sides (common random numbers), so a candidate hidden
        behind something else contributes exactly zero. For k parameters: shape
        (k, batches, pixels), the same jumps times each parameter's $t_c'$.
        """
        k = geom.k
        out = np.zeros((task.batches, task.pixels) if k is None else (k, task.batches, task.pixels))
        phi_c, exists = silhouette_angles(geom, geom.cam_o)
        if phi_c.shape[1] == 0:
            return out
        v = direction(phi_c[0])
        v0 = detach(v)
        f0 = detach(geom.cam_f)
        ahead = exists[0] & (v0 @ f0 > 1e-9)
        t_c = film_coordinate(geom, v[ahead])
        cam = task.scene.camera
        t0 = detach(t_c)
        weights = filter_value(cam.filter, t0[:, None], cam.pixel_centers()[None, :], cam.pixel_width)
        keep = np.any(weights > 0.0, axis=1)
        if not np.any(keep):
            return out
        t0, weights, speed = t0[keep], weights[keep], tangent(t_c[keep])
        geom0 = geom.detached()
        m, n_s = t0.size, task.per_batch
        eps = EPS_FILM * (1.0 + np.abs(t0))
        t_eval = np.concatenate([np.repeat(t0 - eps, n_s), np.repeat(t0 + eps, n_s)])
        lights = Lights.of(geom0)
        ctx = Context(geom0, geom0, lights, Identity())
        for b in range(task.batches):
            u = stream(task.seed, "boundary", b).random((m * n_s, 3))
            # identity transforms draw nothing; the rows are keyed on the edge sample, the same on both sides
            draws = Draws.of(task.seed, np.arange(m * n_s)).tile(2)
            radiance = radiance_along_film(
                ctx, t_eval, np.concatenate([u, u]), draws
            )  # same samples both sides
            jump = (radiance[: m * n_s] - radiance[m * n_s :]).reshape(m, n_s).mean(axis=1)
            # discontinuity term: k_j(t_c) (L(t_c-) - L(t_c+)) * dt_c/dtheta   (Leibniz rule, theory/leibniz)
            if k is None:
                out[b] = (weights * (jump * speed)[:, None]).sum(axis=0)
            else:  # per parameter, summed as for one (numpy's order of a sum depends on the shape)
                for i in range(k):
                    out[i, b] = (weights * (jump * speed[i])[:, None]).sum(axis=0)
        return out


@GRADIENT_METHODS.register("boundary")
def boundary(task: ImageTask | PointTask) -> Tally:
    r"""Naive interior term plus every discontinuity term, computed explicitly (theory/boundary).

    For the pixel integral $I_j = ∫ k_j(t) L(t) dt$ and for every shading integral
    $E(x) = ∫ L_i(x, φ) \max(0, \cos(φ - φ_n)) dφ$ the Leibniz rule reads
    $d/dθ ∫ f = ∫ ∂f/∂θ + Σ_c [f(c^-) - f(c^+)] c'(θ)$. The interior term is the naive
    estimator (θ-free samples, forward AD through the re-attached hits). In 2D the
    discontinuities c are directions toward segment endpoints and circle tangent
    points (the only places where visibility, and so the integrand, can jump:
    emission, albedo and normals are constant or continuous along each primitive,
    and a fading emitter's end is continuous). They are enumerated from the camera
    and from every shading point; the jump is measured by tracing just beside c,
    and $c'(θ)$ (film coordinate or angle) comes from forward AD of the candidate's
    position. The pixel filter is static in t, so it adds no term, whatever its shape
    (box included).

    Unbiased whenever the enumeration is complete, which it is for direct
    illumination of these scenes; the camera-side jumps are themselves Monte Carlo
    estimates (unbiased). Cost: two rays per candidate per shading point. Its
    failure modes: two discontinuities within ``EPS_ANGLE`` of each other, and
    candidates seen exactly edge-on, both of measure zero.
    """
    direct_only(task, "boundary", "jump terms")
    return task.evaluate(task.dual_offset(), BoundaryTransforms())
