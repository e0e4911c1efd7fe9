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
from flatland.integrator import Context, Identity, incident, radiance_along_film, radiance_along_rays
from flatland.lights import Lights
from flatland.methods._common import GRADIENT_METHODS
from flatland.sampling import filter_value
from flatland.state import SceneState
from flatland.tasks import ImageTask, PointTask, Tally
from flatland.tracing import cast, direction, film_coordinate, silhouette_angles

__all__ = ["BoundaryTransforms", "boundary"]

EPS_ANGLE = 1e-7
"""Angular offset (radians) of the two rays traced beside a candidate discontinuity."""

MAX_CANDIDATES = 1 << 18
"""Shading points × candidate discontinuities handled together (bounds memory in vertex-rich scenes)."""

SIDE_PATHS = 1 << 48
"""Offset of the key words (:class:`~flatland.core.rng.Draws` ``path``) of the paths traced from a jump's
two sides, above every word of the primary paths: their random numbers are their own."""

EPS_FILM = 1e-7
"""Film-coordinate offset (relative to $1 + |t|$) of the two camera rays beside a candidate."""


class BoundaryTransforms(Identity):
    """Identity transforms plus the jump terms at the shading points and at the pixels."""

    def shading_extra(
        self, ctx: Context, x: Any, normal: Any, ignore: np.ndarray, lobe: Lobe | None = None,
        draws: Draws | None = None,
    ) -> np.ndarray:  # fmt: skip
        r"""$Σ_c [f(c^-) - f(c^+)] φ_c'(θ)$ of the integrand $f = L_i \cos$ of E at each shading point.

        Candidates c are the angles of all vertices and circle tangent points seen from
        x(θ) (Duals: they move with the geometry and with x); only those in front of the
        surface (cos > 0) can matter, since f vanishes behind it. The jump is found by
        tracing at $c ∓ ε$ on the detached geometry. For k parameters the term has a leading
        axis of k: the same jumps times each parameter's $φ_c'$. With a ``lobe`` (glossy scenes) the
        integrand is $L_i w$ of the reflected radiance (:mod:`flatland.glossy`): the lobe w is continuous
        in φ, so the jump is $w(c) [L_i(c^-) - L_i(c^+)]$, w evaluated at the jump direction.

        On paths (the points are vertex v = ``ctx.vertex`` of paths of up to d = ``ctx.max_depth``
        vertices, v < d), $L_i(c^\pm)$ is the emission the side ray meets plus what its hit reflects
        along paths of up to d - v further vertices: each side is estimated by one path
        (:func:`~flatland.integrator.radiance_along_rays` on the detached scene, identity transforms),
        both sides from the same random numbers (keyed on the row, the vertex and the candidate, apart
        from the primary paths' by :data:`SIDE_PATHS`). Each side's estimate is unbiased for its
        $L_i$, so the jump term is unbiased given the vertex; its variance adds the two paths' (less
        their covariance, large where both sides see the same surface). The caller's path multiplies
        the term by the throughput's value into the vertex; the throughput's own derivative (the
        vertices moving) is the naive interior term's, and the side paths carry no tangent.
        """
        n, k = ignore.size, ctx.geom.k
        out = np.zeros(n if k is None else (k, n))
        m = np.shape(detach(ctx.geom.vertices))[0] + 2 * ctx.geom.n_circ
        step = max(1, MAX_CANDIDATES // max(m, 1))
        for lo in range(0, n, step):  # blocks of shading points: (points x candidates) stays bounded
            sl = slice(lo, min(n, lo + step))
            part = None if lobe is None else lobe.take(np.arange(sl.start, sl.stop))
            rows = None if draws is None else draws.take(np.arange(sl.start, sl.stop))
            out[..., sl] = self._jumps(ctx, x[sl], detach(normal)[sl], ignore[sl], part, rows)
        return out

    @staticmethod
    def _jumps(
        ctx: Context, x: Any, n0: np.ndarray, ignore: np.ndarray, lobe: Lobe | None, draws: Draws | None
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
        further = ctx.max_depth - ctx.vertex  # vertices the side paths may have beyond this one
        if further > 0:  # one side path per row and candidate, the same numbers on both sides
            key = SIDE_PATHS + (draws.path[rows] * 64 + ctx.vertex) * phi_c.shape[1] + cols
            side = Draws(draws.seed, draws.sample[rows], key)
            u, side_ctx = (
                side.uniforms("boundary.side", 3),
                Context(ctx.geom0, ctx.geom0, ctx.lights, Identity(), further),
            )
        for sign in (-1.0, 1.0):  # c⁻ then c⁺
            d = direction(phi + sign * EPS_ANGLE)
            if further > 0:  # L_i(c±) = L_e + the radiance reflected along the rest of the path
                sides.append(radiance_along_rays(side_ctx, origins, d, ignore[rows], u, side))
                continue
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
        ctx = Context(geom0, geom0, lights, Identity(), task.max_depth)
        for b in range(task.batches):
            u = stream(task.seed, "boundary", b).random((m * n_s, 3))
            # paths beyond vertex 1 draw keyed on (batch, edge sample), the same on both sides and apart
            # from the primary paths (SIDE_PATHS); identity transforms draw nothing at depth 1
            index = np.tile(b * m * n_s + np.arange(m * n_s), 2)
            draws = Draws(task.seed, index, np.full(index.size, SIDE_PATHS - 1, dtype=np.int64))
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

    Paths (``max_depth`` d > 1): every vertex's shading integral gets its jump terms, added inside
    :func:`~flatland.integrator.shade` and so multiplied by the value of the path throughput into
    the vertex; the radiance on each side of a jump is the emission there plus one path of the
    remaining depth traced from the side ray (:meth:`BoundaryTransforms.shading_extra`), and the
    camera's jumps see paths of d vertices. The throughput's own derivative (vertices sliding on
    moving shapes, cosines, the glossy lobe at moved directions) is the naive interior term's forward
    tangents; the side paths are traced on the detached scene and carry none, so no term is counted
    twice: this is the Leibniz rule applied to each nested integral in turn.

    Unbiased whenever the enumeration is complete, which it is for these scenes (every visibility
    jump, at every vertex, is toward a segment end or a circle's tangent point); the camera-side
    jumps and the jumps' sides on paths are themselves Monte Carlo estimates (unbiased). Cost: two
    rays per candidate per shading point, on paths two paths of the remaining depth. Its failure
    modes: two discontinuities within ``EPS_ANGLE`` of each other, and candidates seen exactly
    edge-on, both of measure zero.
    """
    return task.evaluate(task.dual_offset(), BoundaryTransforms())
