r"""reparam's emitter strategy (:mod:`sphere3d.reparam.emitter_probes`, :mod:`sphere3d.boundary.emitters`)
and the cosine strategy beside it, at single points of a penumbra, against what their structure predicts.

**A straight shadow edge across a rectangular light.** The point is the origin (normal +z); a
light of radiance L faces down at height H; a black rectangle at height HO, moving in x
(``occluder.translate.x``), covers everything left of its edge x = e. The light's visible part is
the rectangle X >= e H / HO of the light's plane, so E is Lambert's formula on it, and every
derivative below is a flux through its sides. In the plane's area measure the integrand is
$g = L \cos θ_x \cos θ_y / d^2$, split by the MIS weights $w_L = p_L / (p_L + p_C)$,
$p_L = d^2 / (A \cos θ_y)$, $p_C = \cos θ_x / π$ (A the light's area), into the emitter and the
cosine strategy's shares. The shadow edge moves at U = (H / HO, 0, 0) (exact derivative: its flux
$∫ g\, U·N\, dL$, N the outward normal), the light's sides do not move.

A strategy that evaluates its samples at $R(θ) ω$ differentiates only the smooth part of its
integrand: its expectation is the exact derivative minus the boundary terms of the discontinuities
that still move in the sample frame, whose velocity there is the true one minus the rotation's,
$Ω × ω$ (Loubet et al. 2019, Sec. 4.1). For a rotation following an occluder point a (attached,
velocity v = (1, 0, 0)), $Ω = \hat a × \dot{\hat a}$, $\dot{\hat a} = (v - (v·\hat a)\hat a) / |a|$. Hence,
for the emitter strategy and that rotation:

- with the emitters' edge term (the default; the light's sides held fixed): the flux of the
  rotation's velocity through the shadow edge, $∫_{\rm shadow} g w_L\, (U_R·N)\, dL$ ($U_R$: the
  velocity $Ω × ω$ carried to the light's plane). It is the exact share when the followed point is
  the foot of the perpendicular from the point to the edge's line; from a point $y_0$ along the
  edge beyond the foot, the rotation (no turn about $\hat a$ itself) turns the edge's great circle
  about a slightly wrong axis: the edge's normal speed at y is off by $y_0 (y_0 - y) / |a|^2$ of
  itself (the twist);
- without it (``ReparamTransforms(emitter_edges=False, emitter_field=False)``: the rotation alone,
  without the field of :mod:`sphere3d.reparam.emitter_field`; and the paper variant): the flux
  through the whole visible part's border, which is $∫_V ∂_θ h(R_θ ω)\, dω$ (divergence theorem,
  $\mathrm{div}(Ω × ω) = 0$), h = L cos θ_x w_L: only the integrand's slow change under the
  rotation survives, the shadow edge's term is cancelled by the light edge dragged with it.

The set of points a the method can follow is known, so each prediction is an interval: its
extremes over that set (a grid, widened by the largest step between grid neighbours). Test01 checks
the closed forms themselves, test02-04 the estimates against them.

**The hard_shadow scenes** (a sphere or a cube in front of a square light, d/d
``occluder.translate.x`` at ground points of the penumbra, :class:`~sphere3d.tasks.PointTask`):
``boundary`` (unbiased) is the reference; without the edge term, or as published, the dragged
light edge leaves far less than half the derivative (test05), and the default is significantly
closer to the reference than both (test06).

Statistics: an estimate's mean over 16 batches and its standard error, Student's t at 15 degrees
of freedom, two-sided, at the Šidák level over the file's :data:`COMPARISONS` claims (family-wise
1e-3); an interval claim holds when the estimate lies within the predicted interval widened by q
standard errors. Fixed seeds.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import pytest
from scipy import stats

import sphere3d as s3
from flatland.core.dual import Dual, detach, tangent, variable
from flatland.core.stats import sidak
from sphere3d.integrator import Identity
from sphere3d.methods import GRADIENT_METHODS
from sphere3d.methods.reparam import PROBES as KERNEL_PROBES
from sphere3d.reparam.default import ReparamTransforms
from sphere3d.reparam.emitter_probes import PROBES, REFINE, _aimed_points
from sphere3d.reparam.film_kernel import KAPPA_FILM
from sphere3d.reparam.paper import PaperTransforms
from sphere3d.reparam.penumbra import may_see_motion
from sphere3d.sampling import sample_mesh
from sphere3d.state import build_state
from sphere3d.tasks import PointTask
from tests.sphere3d.helpers import lambert, over_batches

PARAM = "occluder.translate.x"
BATCHES = 16
COMPARISONS = 23
"""test02: 1, test03: 2, test04: 4 (2 geometries), test05: 8 (4 points, 2 estimators), test06: 8."""
Q = float(stats.t.ppf(1.0 - 0.5 * sidak(1e-3, COMPARISONS), BATCHES - 1))
L, H, HO = 5.0, 2.0, 1.0
"""Radiance of the light, its height and the occluder's."""
KAPPA = GRADIENT_METHODS.get("reparam").options["kappa"].default


@dataclass(frozen=True)
class StraightEdge:
    """The scene of the module docstring: the light centred at (``centre``, 0, H), ``size`` (sx, sy),
    the occluder's edge at x = ``edge``; the closed forms of its fluxes."""

    centre: float
    size: tuple[float, float]
    edge: float

    def scene(self) -> dict:
        light = {
            "name": "light", "type": "rectangle", "size": list(self.size), "translate": [self.centre, 0.0, H],
            "rotate": [np.pi, 0.0, 0.0], "emission": L, "albedo": 0.0, "fade": 0.0,
        }  # fmt: skip
        occluder = {
            "name": "occluder", "type": "rectangle", "size": [4.0, 4.0],
            "translate": [self.edge - 2.0, 0.0, HO], "albedo": 0.0,
        }  # fmt: skip
        camera = {"position": [0, -3, 1], "look_at": [0, 0, 0], "fov": 0.8, "width": 8, "height": 8}
        return {"name": "straight_edge", "camera": camera, "sky": 0.0, "shapes": [light, occluder]}

    @property
    def visible(self) -> np.ndarray:
        """The visible part's corners on the light's plane, counter-clockwise from above; side k runs
        from corner k to k + 1, side 3 is the shadow edge X = e H / HO."""
        xs, x1, half = self.edge * H / HO, self.centre + 0.5 * self.size[0], 0.5 * self.size[1]
        return np.array([[xs, -half, H], [x1, -half, H], [x1, half, H], [xs, half, H]])

    def weights(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """g = L cos θ_x cos θ_y / d² and w_L at light points ``p`` (the point at the origin, both
        cosines H / d)."""
        d2 = np.sum(p * p, axis=-1)
        cos = H / np.sqrt(d2)
        p_light, p_cos = d2 / (self.size[0] * self.size[1] * cos), cos / np.pi
        return L * cos * cos / d2, p_light / (p_light + p_cos)

    def flux(self, velocity, sides, share: str = "emitter") -> float:
        r"""$∫ g w\, (U·N)\, dL$ over ``sides`` of the visible part, w = w_L (``"emitter"``), 1 - w_L
        (``"cosine"``) or 1 (``"all"``); ``velocity(p)`` (n, 3) the boundary's velocity at the points p."""
        nodes, w = np.polynomial.legendre.leggauss(64)
        total = 0.0
        for k in sides:
            a, b = self.visible[k], self.visible[(k + 1) % 4]
            p = a + (0.5 * (nodes + 1.0))[:, None] * (b - a)
            length = 0.5 * w * np.linalg.norm(b - a)
            e = (b - a) / np.linalg.norm(b - a)
            normal = np.array([e[1], -e[0], 0.0])  # outward for a counter-clockwise polygon
            g, w_light = self.weights(p)
            mis = {"emitter": w_light, "cosine": 1.0 - w_light, "all": 1.0}[share]
            total += float(np.sum(g * mis * (velocity(p) @ normal) * length))
        return total

    def shadow_velocity(self, p: np.ndarray) -> np.ndarray:
        return np.broadcast_to([H / HO, 0.0, 0.0], p.shape)

    def exact(self, share: str = "emitter") -> float:
        """The exact derivative's share: the shadow edge's flux."""
        return self.flux(self.shadow_velocity, [3], share)

    def predicted(self, points: np.ndarray, sides) -> tuple[float, float]:
        """The emitter strategy's expectation under rotations following ``points`` (rows, cols, 3):
        the flux of their velocity through ``sides``; the extremes over the grid, widened by the
        largest step between neighbours."""
        values = np.array(
            [[self.flux(functools.partial(rotation_velocity, a), sides) for a in row] for row in points]
        )
        step = max(
            np.abs(np.diff(values, axis=0)).max(initial=0.0), np.abs(np.diff(values, axis=1)).max(initial=0.0)
        )
        return float(values.min() - step), float(values.max() + step)

    def silhouette_points(self) -> np.ndarray:
        """What the default's emitter rotation can follow: a point of the occluder on its edge's crossing
        of the light's cone, or beside it by the bisection's residue (REFINE halvings of a probe pair's
        gap, at most the light's extent)."""
        half = 0.5 * self.size[1] * HO / H
        residue = np.hypot(*self.size) * HO / H / 2**REFINE
        return _grid(self.edge - residue, self.edge, -half, half)

    def hidden_points(self) -> np.ndarray:
        """What the paper variant's can follow: the mean of occluded probes' hits, a point of the
        occluder in front of the light's hidden part (a convex set)."""
        x0, half = (self.centre - 0.5 * self.size[0]) * HO / H, 0.5 * self.size[1] * HO / H
        return _grid(x0, self.edge, -half, half)


def _grid(x0: float, x1: float, y0: float, y1: float) -> np.ndarray:
    x, y = np.meshgrid(np.linspace(x0, x1, 9), np.linspace(y0, y1, 17), indexing="ij")
    return np.stack([x, y, np.full_like(x, HO)], axis=-1)


def angular_velocity(a: np.ndarray) -> np.ndarray:
    """Ω of the rotation following the attached occluder point ``a`` from the origin (module docstring)."""
    r = np.linalg.norm(a)
    unit, v = a / r, np.array([1.0, 0.0, 0.0])
    return np.cross(unit, (v - (v @ unit) * unit) / r)


def rotation_velocity(a: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The velocity on the light's plane z = H of the light points ``p`` under the rotation following
    ``a``: ω = p / |p| moves at Ω × ω, and p = t ω with t = H / ω_z, so ṗ = t (ω̇ - (ω̇_z / ω_z) ω)."""
    omega = p / np.linalg.norm(p, axis=-1)[:, None]
    turn = np.cross(angular_velocity(a), omega)
    return (H / omega[:, 2])[:, None] * (turn - (turn[:, 2] / omega[:, 2])[:, None] * omega)


STRIP = StraightEdge(centre=1.0, size=(1.0, 0.1), edge=0.5)
"""A light narrow along the shadow edge (the twist is negligible), the edge across its middle, 0.5
beside the foot of the perpendicular."""
WIDE = StraightEdge(centre=0.0, size=(1.0, 1.0), edge=0.1)
"""A square light, 0.3 of it visible: cosine kernels meet the shadow edge or a side, seldom both."""
SLIVER = StraightEdge(centre=0.0, size=(1.0, 1.0), edge=0.225)
"""The same light of which a sliver 0.05 wide stays visible beside its side X = 0.5."""


@dataclass(frozen=True)
class EmitterAlone(ReparamTransforms):
    """The default's emitter strategy; the cosine strategy as ``naive`` (its derivative is 0 here:
    only visibility moves, which it does not differentiate)."""

    def bsdf(self, shading, mu, hits):
        return Identity.bsdf(self, shading, mu, hits)


@dataclass(frozen=True)
class PaperEmitterAlone(PaperTransforms):
    """The published emitter strategy (the mean occluded probe hit); the cosine strategy as ``naive``."""

    def bsdf(self, shading, mu, hits):
        return Identity.bsdf(self, shading, mu, hits)


@functools.cache
def _batches(geometry: StraightEdge, transforms, n: int = 1 << 14, seed: int = 3) -> np.ndarray:
    task = PointTask(
        s3.load_scene(geometry.scene()), PARAM, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), n, seed, BATCHES
    )
    return task.evaluate(variable(0.0), transforms).derivative


def _within(batches: np.ndarray, interval: tuple[float, float]) -> bool:
    mean, se = over_batches(batches)
    print(f"{mean:+.5f} +- {se:.5f} in [{interval[0]:+.5f}, {interval[1]:+.5f}]")
    return interval[0] - Q * se <= mean <= interval[1] + Q * se


def test01_the_closed_forms_are_lamberts_formula_and_the_rotated_integral():
    # the exact derivative: Lambert's formula on the visible rectangle with its shadow side moving
    # (Duals), against the shadow edge's flux
    for geometry in (STRIP, WIDE, SLIVER):
        corners = geometry.visible
        moving = np.zeros_like(corners)
        moving[[0, 3], 0] = H / HO
        e = L * lambert(Dual(corners, moving))
        assert float(tangent(e)) == pytest.approx(geometry.exact("all"), rel=1e-12)
        assert geometry.exact("emitter") + geometry.exact("cosine") == pytest.approx(
            geometry.exact("all"), rel=1e-14
        )
    # without the edge term: the border's flux is d/dθ ∫_V h(R_θ ω) dω over the fixed visible part,
    # here by central differences of a 2D quadrature with the rotation R_θ = exp(θ [Ω]×)
    a = np.array([STRIP.edge - 0.1, 0.02, HO])
    nodes, w = np.polynomial.legendre.leggauss(48)
    (x0, y0, _), (x1, y1, _) = STRIP.visible[0], STRIP.visible[2]
    px, py = np.meshgrid(
        x0 + (x1 - x0) * 0.5 * (nodes + 1), y0 + (y1 - y0) * 0.5 * (nodes + 1), indexing="ij"
    )
    p = np.stack([px, py, np.full_like(px, H)], axis=-1).reshape(-1, 3)
    area = np.outer(w, w).ravel() * 0.25 * (x1 - x0) * (y1 - y0)
    omega = angular_velocity(a)

    def rotated_integral(theta):
        k = np.cross(np.eye(3), omega / np.linalg.norm(omega))  # [unit Ω]×
        angle = theta * np.linalg.norm(omega)
        r = np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)
        d = p / np.linalg.norm(p, axis=1)[:, None]
        moved = d @ r.T  # R_θ ω
        _, w_light = STRIP.weights(moved * (H / moved[:, 2])[:, None])
        jacobian = d[:, 2] ** 3 / H**2  # dω / dA = cos θ_y / d²
        return float(np.sum(L * moved[:, 2] * w_light * jacobian * area))

    step = 1e-4
    central = (rotated_integral(step) - rotated_integral(-step)) / (2.0 * step)
    border = STRIP.flux(functools.partial(rotation_velocity, a), range(4))
    assert border == pytest.approx(central, rel=1e-6)
    # the rotation following the foot of the perpendicular moves the shadow edge like the edge itself
    foot = np.array([STRIP.edge, 0.0, HO])
    assert STRIP.flux(functools.partial(rotation_velocity, foot), [3]) == pytest.approx(
        STRIP.exact(), rel=1e-12
    )


def test02_with_its_edge_term_the_emitter_strategy_follows_a_straight_shadow_edge():
    """On the narrow light the prediction is the exact share to a fraction of a percent (the twist
    and the bisection's residue), and the estimate lies within it."""
    interval = STRIP.predicted(STRIP.silhouette_points(), [3])
    assert interval[0] <= STRIP.exact() <= interval[1]
    assert interval[1] - interval[0] < 0.01 * abs(STRIP.exact())
    assert _within(_batches(STRIP, EmitterAlone()), interval)


def test03_without_the_edge_term_and_as_published_the_light_edge_is_dragged():
    """Both follow the occluder and drag the light's far side with it: only the integrand's slow change
    under the rotation is left, far less than half the exact share and of its sign (the
    predictions); the paper variant follows the mean occluded hit, or nothing (0) where no probe is
    occluded, so its expectation lies in the hull of 0 and its interval."""
    exact = STRIP.exact()
    dragged = STRIP.predicted(STRIP.silhouette_points(), range(4))
    published = STRIP.predicted(STRIP.hidden_points(), range(4))
    published = (min(published[0], 0.0), max(published[1], 0.0))
    for lo, hi in (dragged, published):
        assert exact < 0.0 and -0.5 * abs(exact) < lo <= hi <= 0.0
    # the rotation alone (its field, which keeps the edges it finds, changes what the light edge drags)
    assert _within(_batches(STRIP, EmitterAlone(emitter_edges=False, emitter_field=False)), dragged)
    assert _within(
        _batches(STRIP, PaperEmitterAlone(KAPPA, KAPPA_FILM, KERNEL_PROBES["paper"], PROBES)), published
    )


@pytest.mark.parametrize("geometry", [WIDE, SLIVER], ids=["wide", "sliver"])
def test04_the_cosine_strategy_keeps_between_none_and_all_of_its_mis_share(geometry):
    r"""A cosine kernel's rotation follows the shadow edge or nothing (its probes see only the light or
    only the occluder, both static inside). Following the edge keeps the kernel's share of its term,
    the probes' ring and spin turning the rotation with the edge's great circle (WIDE); where the
    visible part is narrower than the kernel (SLIVER) the rotation moves both sides of it alike and
    their terms cancel, but for the change of $h_C = g (1 - w_L)$ across it; following nothing loses
    the kernel's share. No kernel moves an edge faster than the shadow edge moves, so the strategy's
    derivative lies between 0 and its MIS share $∫_{\rm shadow} g (1 - w_L)\, U·N\, dL$: however the
    cosine strategy drags the light's side, the default loses at most that share. The cosine part
    is the default's estimate minus its emitter strategy's alone, paired per batch (same seed: the
    emitter strategy's numbers are the same). The emitter strategy on this wide light lies in its
    interval, as wide as the twist."""
    emitter = _batches(geometry, EmitterAlone())
    cosine = _batches(geometry, ReparamTransforms()) - emitter
    share = geometry.exact("cosine")
    assert share < 0.0
    assert _within(cosine, (share, 0.0))
    assert _within(emitter, geometry.predicted(geometry.silhouette_points(), [3]))


POINTS = [("hard_shadow", -0.3), ("hard_shadow", 0.57), ("hard_shadow_cube", -0.2), ("hard_shadow_cube", 1.2)]
"""Ground points (x, -0.1, 0) of the penumbras: the lit and the umbra's side of each."""


@functools.cache
def _point(scene: str, x: float, estimator: str, n: int = 1 << 13) -> np.ndarray:
    task = PointTask(s3.load_scene(scene), PARAM, (x, -0.1, 0.0), (0.0, 0.0, 1.0), n, 11, BATCHES)
    if estimator == "without edges":
        return task.evaluate(variable(0.0), ReparamTransforms(emitter_edges=False)).derivative
    method, options = {
        "boundary": ("boundary", {}),
        "default": ("reparam", {}),
        "paper": ("reparam", {"variant": "paper"}),
    }[estimator]
    return GRADIENT_METHODS.run(method, task, **options).derivative


@pytest.mark.parametrize(("scene", "x"), POINTS)
def test05_without_the_edge_term_and_as_published_less_than_half_the_penumbras_derivative_is_left(scene, x):
    r"""As in test03: what the dragged edge leaves is the integrand's slow change across the light (its
    cosines and MIS weight) and the cosine strategy's share, $\max w_C$ of it (well below a tenth
    here, p_L = d² / (A cos θ_y) with d >= 2.5, A = 1): |estimate| + q se < |boundary| / 2, at 4x the
    samples of the other tests (hard_shadow_cube's lit side leaves about 0.41 of it)."""
    reference, reference_se = over_batches(_point(scene, x, "boundary"))
    for estimator in ("without edges", "paper"):
        mean, se = over_batches(_point(scene, x, estimator, 1 << 15))
        print(f"{scene} {x} {estimator}: {mean:+.3f} +- {se:.3f} of {reference:+.3f}")
        assert abs(mean) + Q * np.hypot(se, reference_se) < 0.5 * abs(reference), estimator


@pytest.mark.parametrize(("scene", "x"), POINTS)
def test06_the_default_is_closer_to_boundary_than_without_the_edge_term_and_as_published(scene, x):
    """Per batch b (same seed: the same primary samples), D_b = |other_b - B| - |default_b - B|, B the
    reference's mean; its mean over the batches significantly positive (one-sided)."""
    reference = float(np.mean(_point(scene, x, "boundary")))
    default = np.abs(_point(scene, x, "default") - reference)
    for estimator in ("without edges", "paper"):
        gain, se = over_batches(np.abs(_point(scene, x, estimator) - reference) - default)
        assert gain > Q * se, (estimator, gain, se)


@pytest.mark.parametrize("scene", ["hard_shadow", "hard_shadow_cube"])
def test07_points_skipped_without_probes_cannot_see_the_occluder_in_front_of_the_light(scene):
    """The cull of :func:`sphere3d.reparam.penumbra.may_see_motion` is conservative: every ground or
    occluder point from which one of 64 rays to the light meets the moving occluder is kept,
    and the cull skips a good share of the ground (else it would be pointless)."""
    loaded = s3.load_scene(scene)
    state = build_state(loaded, PARAM, variable(0.0))
    rng = np.random.default_rng(5)
    x = np.column_stack([rng.uniform(-2.5, 2.5, 4000), rng.uniform(-2.5, 2.5, 4000), np.zeros(4000)])
    occluder = np.asarray(detach(state.triangles))[state.shape_of == loaded.shape_index("occluder")]
    on_occluder, _ = sample_mesh(rng.uniform(size=(1000, 1, 3)), occluder)
    x = np.concatenate([x + np.array([0.0, 0.0, 1e-6]), on_occluder[:, 0]])
    y, _ = sample_mesh(rng.uniform(size=(len(x), 64, 3)), np.asarray(detach(state.triangles))[state.emitters])
    to = y - x[:, None]
    dist = np.linalg.norm(to, axis=-1)
    hits = state.tracer.intersect(np.broadcast_to(x[:, None], to.shape), to / dist[..., None])
    moving = np.any(np.asarray(state.triangles.tangent) != 0.0, axis=(1, 2))
    sees = np.any(hits.hit & moving[np.maximum(hits.triangle, 0)] & (hits.t < dist), axis=1)
    kept = may_see_motion(state, x)
    assert sees.sum() > 100 and np.all(kept[sees])
    assert 0.2 < np.mean(~kept[:4000]) < 1.0


def test08_aimed_probes_point_where_the_light_is_first_covered():
    """:func:`sphere3d.reparam.emitter_probes._aimed_points` on ``hard_shadow`` (the occluder's bounding
    sphere is centred on the icosphere's centre (0.1, 0, 0.8)): from (0.3, -0.2, 0) the axis meets
    the light inside, at (-0.325, 0.425, 2.5) (2.5 / 0.8 times (-0.2, 0.2, 0.8) on), the nearest
    point; from the outer lit edge (-0.34, -0.1, 0), where the sphere hides a sliver of the light
    that area probes mostly miss, the nearest point on the border is hidden; from (2, 2, 0) the
    light lies outside the occluder's bounding cone and the point gets no aimed ray."""
    state = build_state(s3.load_scene("hard_shadow"), PARAM, variable(0.0))
    x = np.array([[0.3, -0.2, 0.0], [-0.34, -0.1, 0.0], [2.0, 2.0, 0.0]])
    points, worth = _aimed_points(state, x, np.zeros(3, dtype=bool), 2)
    assert np.allclose(points[0, 0], [-0.325, 0.425, 2.5], atol=1e-9)
    to = points[1, 0] - x[1]
    dist = np.linalg.norm(to)
    origin = x[1:2] + np.array([0.0, 0.0, 1e-6])
    assert state.tracer.occluded(origin, (to / dist)[None], np.array([dist - 1e-4]))[0]
    assert worth.tolist() == [True, True, False]
