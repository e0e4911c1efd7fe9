"""The default variant of ``reparam``: the paper's estimator with the extensions that follow each
discontinuity where one rotation per integral cannot (Loubet et al. 2019, Sec. 4.1-4.3).

:class:`ReparamTransforms` is the method's :class:`~sphere3d.integrator.Transforms`:

- ``camera``: the per-sample film kernel (:mod:`sphere3d.reparam.film_kernel`), with its
  extensions (the probe ring, bisection, snaps, junctions, one plane);
- ``emitter``: the rotation that follows the shadow edge (:mod:`sphere3d.reparam.emitter_probes`),
  then a field keeping every shadow edge the probes find (:mod:`sphere3d.reparam.emitter_field`), with
  the emitters' own edges held fixed by their boundary term (:mod:`sphere3d.boundary.emitters`);
- ``bsdf``: the vMF convolution of the cosine-sampled integral (at glossy points of the BSDF-sampled
  one, its concentration following the lobe's width: :mod:`sphere3d.reparam.lobe`), the probes on a
  ring around the kernel's centre, snapped onto the edge they straddle
  (:mod:`sphere3d.reparam.snaps`), at a smooth-shaded point the face's own plane
  (:mod:`sphere3d.reparam.face_plane`); a moving shape inside the ring followed by an affine map of the
  gnomonic chart (:mod:`sphere3d.reparam.shading_affine`); the light's border in the ring kept by a field
  after either (:mod:`sphere3d.reparam.kernel_border`); the kernel weights' control variate (theory page
  *kernels*).

:mod:`sphere3d.reparam.paper` is the estimator as published; the theory page *extensions* lists
what each extension adds and why.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core.dual import Dual, detach
from flatland.core.rng import Draws
from flatland.core.translation import unit_weight
from sphere3d.boundary.emitters import edge_table, emitter_edge_term
from sphere3d.film import FilmTransform
from sphere3d.integrator import EmitterChange, Identity, Members, Shading
from sphere3d.live import any_rows, moves
from sphere3d.reparam.emitter_probes import PROBES, emitter_map
from sphere3d.reparam.face_plane import below_face, face_plane_rotation
from sphere3d.reparam.film_affine import _shape_images
from sphere3d.reparam.film_corners import _corner_table
from sphere3d.reparam.film_kernel import (
    KAPPA_FILM,
    _film_hull,
    _moving_vertices,
    _plane_table,
    film_transform,
)
from sphere3d.reparam.kernel_border import border_field
from sphere3d.reparam.lobe import LOBE, lobe_kappa, lobe_radius
from sphere3d.reparam.outline import outline_table
from sphere3d.reparam.penumbra import cone_may_see_motion, moving_sphere, separating_planes
from sphere3d.reparam.probes import REFINE, Followed, follow_probes, ring_directions, vmf_spread_angle
from sphere3d.reparam.shading_affine import _moving_shapes, inner_shape_map
from sphere3d.reparam.snaps import angle_snap
from sphere3d.rotation import Rotation
from sphere3d.sampling import sample_cosine_hemisphere, sample_vmf, vmf_hemisphere_fraction
from sphere3d.state import SceneState
from sphere3d.tracing import Hits
from sphere3d.vector import dot

__all__ = ["ReparamTransforms"]


@dataclass(frozen=True)
class ReparamTransforms(Identity):
    r"""The rotations of the three integrals of :mod:`sphere3d.integrator` (defaults: the method's).

    The last ten switches turn one extension off each, for the tests and studies that measure
    what it adds (the method itself always uses them).

    Attributes
    ----------
    kappa : float or None
        vMF concentration of the convolution kernel of the cosine-sampled integral, in
        (0, :data:`KAPPA_MAX`];
        None: no kernel, one rotation per sample from probes drawn from the cosine
        density itself (Sec. 4.1 over a support too large for it: biased).
    kappa_film : float
        1 / variance of the Gaussian film kernel of the pixel integral, $\mathrm{pixels}^{-2}$
        (:mod:`sphere3d.reparam.film_kernel`).
    probes : int
        Probe rays per kernel, >= 1: its centre and a ring of ``probes - 1`` (film and cosine
        strategy); one probe (the centre) has no pair: its attached hit is followed, the
        identity where it misses (:mod:`sphere3d.reparam.probes`).
    emitter_probes : int
        Shadow probes per shading point uniform on the emitters' area, >= 1
        (:mod:`sphere3d.reparam.emitter_probes`).
    lobe : float or None
        At glossy points the kernel's ring of probes lies within ``lobe`` times the BSDF lobe's
        median radius $r_l = 2 \arctan(α) \cos θ_i$ (:func:`~sphere3d.reparam.lobe.lobe_kappa`:
        $κ_x = \max(κ, s^2 / (2 (1 - \cos(λ r_l))))$, s = ``spread``, λ = ``lobe``), > 0; None:
        ``kappa`` at every point.
    spread : float
        Radius of the ring of probes around a kernel's centre, in kernel standard
        deviations (:mod:`sphere3d.reparam.probes`), >= 0: any value has a ring, whose angle
        grows to π (:func:`~sphere3d.reparam.probes.vmf_spread_angle`); on the film, in film
        kernel standard deviations.
    refine : int
        Bisection rays that move a single probe's hit toward the silhouette next to
        it, >= 0 (:func:`~sphere3d.reparam.probes.select_points`).
    paired : bool
        Two kernel samples per outer sample share one rotation (theory/kernels).
    emitter_edges : bool
        Add the boundary term of the emitters' sharp edges to the emitter strategy
        (:mod:`sphere3d.boundary.emitters`), which holds them fixed under its rotation.
    film_one_plane : bool
        The identity for a camera sample whose film probes all hit one plane of a
        flat-shaded shape (:func:`~sphere3d.reparam.film_kernel.one_plane`; module
        :mod:`sphere3d.reparam.film_kernel`, Noise).
    film_junctions : bool
        Where a camera sample's film probes see a moving silhouette cross a static edge,
        follow their crossing (:mod:`sphere3d.reparam.junctions`).
    film_shapes : bool
        Where a moving shape's film image lies wholly within a camera sample's kernel's reach
        (:data:`~sphere3d.reparam.film_corners.REACH` σ), or is thin and reaches into it, follow it
        by an affine map of the film (:mod:`sphere3d.reparam.film_affine`).
    film_corners : bool
        Where a moving silhouette vertex's film image lies within a camera sample's kernel's reach
        (:data:`~sphere3d.reparam.film_corners.REACH` σ), follow both its silhouette edges by an affine
        map of the film
        (:mod:`sphere3d.reparam.film_corners`).
    film_corner_lines : bool
        Where such a ring also holds a static edge, keep the corner's edges and that edge by one
        field of the film (:mod:`sphere3d.reparam.corner_lines`); else the corner's fan drags the
        static edge. Applied with ``film_junctions`` and ``film_corners``.
    emitter_field : bool
        Where a shading point's shadow probes find shadow edges, map the emitter samples by one field
        that keeps them and the light's border (:mod:`sphere3d.reparam.emitter_field`); else the
        rotation follows one of them.
    shading_border : bool
        Where a cosine kernel's ring reaches the light's border, keep the border (and the edge the
        rotation follows) by a field after the rotation (:mod:`sphere3d.reparam.kernel_border`); else the
        rotation drags the border.
    shading_shapes : bool
        Where a moving shape's image from the shading point lies inside a cosine kernel's ring of
        probes, or is thin and reaches into it, follow it by an affine map of the gnomonic chart
        about the kernel's centre (:mod:`sphere3d.reparam.shading_affine`).
    baseline : bool
        The cosine strategy's control variate: $c(ω)\, \dot q / p(μ)$ subtracted, $c(ω) = π L(ω)$
        the sky radiance where the kernel centre's probe sees the sky (theory page *kernels*,
        :class:`~sphere3d.integrator.Members`); with a sky, every cosine sample gets its rotation.
    """

    kappa: float | None = 1000.0
    kappa_film: float = KAPPA_FILM
    probes: int = 7
    emitter_probes: int = PROBES
    spread: float = 3.0
    refine: int = REFINE
    paired: bool = False
    emitter_edges: bool = True
    film_one_plane: bool = True
    film_junctions: bool = True
    film_shapes: bool = True
    film_corners: bool = True
    baseline: bool = True
    shading_shapes: bool = True
    lobe: float | None = LOBE
    film_corner_lines: bool = True
    emitter_field: bool = True
    shading_border: bool = True

    def tables(self, state: SceneState) -> tuple[Callable[[SceneState], Any], ...]:
        """The per-state tables the options read where triangles move (:func:`sphere3d.execution.prepare`
        builds them at once); none otherwise (each is then asked for only where its rule applies)."""
        if not state.dual or not _moving_vertices(state).any():
            return ()
        film = (
            (_film_hull, _plane_table)
            + (_shape_images,) * self.film_shapes
            + (_corner_table,) * self.film_corners
        )
        shading = (_moving_shapes,) * self.shading_shapes + (outline_table,) * self.emitter_field
        return (*film, separating_planes, moving_sphere, edge_table, *shading)

    def camera(self, state: SceneState, x: np.ndarray, y: np.ndarray, draws: Draws) -> FilmTransform:
        """Pixel integral: one rotation per camera sample from probes around its film kernel's centre."""
        return film_transform(
            state, x, y, draws, self.kappa_film, self.probes, self.spread, self.refine, self.film_one_plane,
            self.film_junctions, self.film_shapes, self.film_corners, self.film_corner_lines,
        )  # fmt: skip

    def emitter(self, shading: Shading, visible: np.ndarray, bsdf: Any = None) -> EmitterChange:
        r"""Emitter sampling: one rotation per shading point from shadow probes (Sec. 4.3), following
        the occluder's silhouette between a shadowed and a lit probe, then (``emitter_field``) a field
        keeping every shadow edge the probes find (:func:`~sphere3d.reparam.emitter_probes.emitter_map`).
        With ``emitter_edges`` the emitters' sharp edges are held fixed under them by their boundary term
        (:func:`~sphere3d.boundary.emitters.emitter_edge_term`), at every point (any may have edge
        samples); else only where an emitter sample is visible. ``bsdf``: glossy points' lobe at θ0
        (:class:`~sphere3d.glossy.Lobe`), the edge term's integrand then $L_e f \cos θ_x$."""
        m = len(shading)
        rows = np.arange(m) if self.emitter_edges else np.flatnonzero(visible)
        sub = shading if rows.size == m else shading.take(rows)
        maps = emitter_map(sub, self.emitter_probes, field=self.emitter_field)
        field = maps.field if np.any(maps.field.slot >= 0) else None
        state = shading.state
        extra = emitter_edge_term(state, shading, maps.rotation, bsdf, field) if self.emitter_edges else None
        return EmitterChange(maps.rotation, rows, extra, field)

    def _probe_rotation(
        self, shading: Shading, centre: np.ndarray, kappa: float | np.ndarray | None = None
    ) -> tuple[Rotation, np.ndarray, Any, tuple[np.ndarray, Hits]]:
        """One rotation per shading point from a ring of probes around the kernel ``centre`` (of
        concentration ``kappa``: one, or one per point; None: the option's), whether the centre's
        probe sees the sky (above the horizon, no hit), the edges the rotation follows
        (:class:`~sphere3d.reparam.probes.Followed`) and the probes (directions (n, P, 3), hits).

        Without a kernel (``kappa`` None) the probes are drawn from the cosine lobe instead.
        """
        kappa = self.kappa if kappa is None else kappa
        snap = None
        if self.kappa is None:
            d = sample_cosine_hemisphere(
                shading.draws.uniforms("probes.bsdf", self.probes, 2), detach(shading.n)[:, None]
            )
        else:
            phase = shading.draws.uniforms("probes.bsdf.ring")
            ring = vmf_spread_angle(kappa, self.spread)
            # the centre and a ring of probes - 1, as on the film: edges within cos(π/6) of the ring
            d = ring_directions(centre, ring, self.probes, phase)
            # onto the edge, or its corner up to twice the ring's radius away (as on the film)
            snap = angle_snap(shading.state, centre, 2.0 * ring)
        hits = shading.state.tracer.intersect(shading.origin[:, None], d)
        # a probe below the horizon sees only the surface it leaves, where the integrand is 0
        # (cos θ < 0), not a discontinuity: it counts as a miss rather than as a point at distance ~ε;
        # so does one below the face's own plane at a smooth-shaded point (face_plane)
        normal = detach(shading.n)
        below = below_face(shading, d)
        hits = hits.without(below)
        spin = None if self.kappa is None else (centre, 1.0 / np.sqrt(kappa))
        sky = ~hits.hit[:, 0] & ~below[:, 0]
        planes = (
            normal if shading.geometric is None else np.stack([normal, detach(shading.geometric)], axis=1)
        )
        followed = follow_probes(
            shading.state, shading.x, shading.origin, d, hits, planes, self.refine, snap, spin
        )
        if self.kappa is None:
            return followed.rotation, sky, followed, (d, hits)
        # where it follows nothing, the face's plane in the kernel's reach (twice the ring, as the snaps)
        rotation = face_plane_rotation(shading, centre, 2.0 * ring, followed.rotation)
        return rotation, sky, Followed(rotation, followed.snapped), (d, hits)

    def _kernel_weight(
        self, rotated: Any, centre: np.ndarray, kappa: float | np.ndarray | None = None
    ) -> Any:
        r"""$w = k(Rμ, ω) / \mathrm{detach}(k(Rμ, ω))$ in log space: value exactly 1
        (Loubet et al. 2019, Sec. 4.2); ``kappa`` one, or one per row (None: the option's)."""
        kappa = self.kappa if kappa is None else kappa
        return unit_weight(kappa * dot(rotated, centre))  # the vMF normalization cancels in the ratio

    def kernel_kappa(self, lobe: Any, rows: np.ndarray) -> float | np.ndarray:
        """The kernel's concentration at points ``rows``: the option ``kappa`` at diffuse points (``lobe``
        None) or without ``lobe``; at glossy ones, per point, :func:`~sphere3d.reparam.lobe.lobe_kappa`
        of the lobe's radius at θ0 (:class:`~sphere3d.glossy.Lobe`), one float where that is κ at
        every point."""
        if lobe is None or self.lobe is None or self.kappa is None:
            return self.kappa
        radius = lobe_radius(lobe.wi[rows], lobe.n[rows], lobe.alpha[rows])
        kappa = lobe_kappa(self.kappa, self.spread, self.lobe, radius)
        # every lobe wide enough: the user's κ as one float, the scalar code path (bit for bit as without)
        return self.kappa if np.all(kappa == self.kappa) else kappa

    def bsdf(self, shading: Shading, mu: np.ndarray, hits: Hits, lobe: Any = None) -> Members:
        """Cosine-sampled integral (BSDF-sampled at glossy points, ``lobe`` their
        :class:`~sphere3d.glossy.Lobe`), reparameterized (with a vMF kernel unless ``kappa`` is None)."""
        if self.paired:  # evaluated at the two members only
            return self._paired(shading, mu)
        # samples whose integrand is 0 with zero derivative need no rotation (and no probes), unless
        # the control variate's c(ω) may be nonzero (a sky): its zero mean needs every sample
        sky = (float(detach(shading.state.sky)) != 0.0) or shading.state.sky_varies
        everywhere = self.baseline and self.kappa is not None and sky
        live = np.arange(len(mu)) if everywhere else np.flatnonzero(shading.contributes(mu, hits))
        sub, mu_l = shading.take(live), mu[live]
        if self.kappa is None:
            return Members(self._probe_rotation(sub, mu_l)[0].apply(mu_l), live)
        # kernel centre ω ~ k(·, μ) around the primary sample μ: the joint density of (μ, ω) is
        # the paper's "ω ~ p, μ ~ k(·, ω)" read the other way (k symmetric), and μ stays the
        # naive sample, so the primal is bit-identical to the naive one
        kappa = self.kernel_kappa(lobe, live)  # θ-free: fixed at the point, whatever μ (lobe.py)
        centre = sample_vmf(sub.draws.uniforms("kernel.bsdf", 2), mu_l, kappa)
        # a static point whose kernel's probes, snaps and shapes (within twice the ring) meet no changing
        # triangle can only follow static points: the identity (a zero derivative), without probes
        reach = 2.0 * vmf_spread_angle(kappa, self.spread) * (1.0 + 1e-6) + 1e-6
        state = shading.state
        sees = any_rows(moves(sub.x)) | cone_may_see_motion(state, detach(sub.x), centre, reach)
        if sees.all():
            rotated, weights, baseline = self._rotated(sub, mu_l, centre, kappa)
        else:
            rows = np.flatnonzero(sees)
            rotated, weights = Dual(mu_l.copy(), None, state.k), Dual(np.ones(len(mu_l)), None, state.k)
            baseline = np.zeros(len(mu_l))  # its term, c (q - detach q) / p, is 0 whatever c
            if rows.size:
                k_rows = kappa if np.ndim(kappa) == 0 else kappa[rows]
                r, w, b = self._rotated(sub.take(rows), mu_l[rows], centre[rows], k_rows)
                rotated[rows], weights[rows], baseline[rows] = r, w, b
        if not self.baseline:
            return Members(rotated, live, weights=weights)
        return Members(rotated, live, weights=weights, baseline=baseline, centre=centre)

    def _rotated(
        self, sub: Shading, mu_l: np.ndarray, centre: np.ndarray, kappa: float | np.ndarray
    ) -> tuple[Any, Any, np.ndarray]:
        """The rotated samples, their kernel weights and the control variate's c(ω) (the radiance the
        kernel's centre sees: the sky, or 0; π L(ω)), from probes around the kernel centres (of
        concentration ``kappa``: one, or one per point)."""
        rotation, sky, followed, probes = self._probe_rotation(sub, centre, kappa)
        rotated = rotation.apply(mu_l)
        jacobian = None
        ring = vmf_spread_angle(kappa, self.spread)
        k = rotated.k
        # a moving shape inside the kernel's ring: the chart's map that follows all its edges
        shape = inner_shape_map(sub, mu_l, centre, ring) if self.shading_shapes else None
        own = np.zeros(len(mu_l), dtype=bool)
        if self.shading_border:  # the light's border in the kernel: kept by a field after the rotation
            single = None if shape is None else shape.triangle
            field = border_field(sub, centre, ring, rotation, followed, single, probes, self.refine)
            # where an inner triangle's edges are kept with the border, the field after the identity
            own = (field.slot >= 0) & (single >= 0) if single is not None else own
            base = Dual(rotated.value, np.where(own[:, None], 0.0, rotated.tangent), k)
            rotated, jacobian = field.apply(mu_l, base)
        if shape is not None and (shape.mask & ~own).any():
            mask = shape.mask & ~own
            rotated = Dual(rotated.value, np.where(mask[:, None], shape.mu_dot, rotated.tangent), k)
            before = 0.0 if jacobian is None else jacobian.tangent
            # |J_T|: value 1
            jacobian = Dual(np.ones(len(mu_l)), np.where(mask, shape.log_jacobian_dot, before), k)
        # f(Tμ) k(Tμ, ω) |J_T| / (p(μ) k(μ, ω)): value f(μ)/p(μ), derivative with the kernel factor (Sec. 4.2)
        weights = self._kernel_weight(rotated, centre, kappa)
        if jacobian is not None:
            weights = weights * jacobian
        return rotated, weights, np.where(sky, np.pi * float(detach(sub.state.sky)), 0.0)

    def _paired(self, shading: Shading, mu: np.ndarray) -> Members:
        r"""The paper's order: outer $ω = μ \sim p$, two kernel samples share one rotation
        (theory/kernels)."""
        rotation = self._probe_rotation(shading, mu)[0]
        u = shading.draws.uniforms("kernel.bsdf.pair", 2, 2)
        members, rotated, weights, mass = [], [], [], []
        for j in range(2):  # the two members of each pair (not a loop over samples)
            member = sample_vmf(u[:, j], mu, self.kappa)
            r = rotation.apply(member)
            members.append(member)
            rotated.append(r)
            weights.append(self._kernel_weight(r, mu))  # |w| < SMALL_WEIGHT counts as 1 in paired_combine
            # centres ω are cosine samples, confined to the hemisphere: 1 / C(n·Rμ) restores the kernel
            # mass that lies below the horizon, ∫_H k(y, ω) dω = C(n·y)   (sampling.vmf_hemisphere_fraction)
            c = vmf_hemisphere_fraction(dot(r, detach(shading.n)), self.kappa)
            mass.append(np.where(detach(c) > 0.0, c, 1.0))  # C = 0 only far below the horizon, where f = 0
        return Members(tuple(rotated), None, tuple(members), tuple(weights), tuple(mass), paired=True)
