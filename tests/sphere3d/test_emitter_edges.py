"""The boundary term of the emitters' sharp edges (:mod:`sphere3d.boundary.emitters`), against closed forms.

A point at the origin (normal +z) under the 0.6 × 0.4 rectangle light of
``test_closed_forms`` (emission 5, facing -z at height 1.5, no fade). Nothing in the
scene depends on θ (the parameter moves a floor below the point, which no ray from
it reaches), so the exact derivative of E is 0. A transform forces a known rotation
on the emitter strategy, R(θ) with angular velocity Ω, and leaves the cosine strategy
alone (identity, zero derivative):

- without the edge term the estimator differentiates the emitter integral over the
  rotated light, ``d/dθ ∫_A0 h(R(θ) w(y)) cos θ_y / d² dA(y)``, h = L cos θ_x w_L
  re-attached to the light's plane (the edge dragged along): computed here by
  Gauss–Legendre quadrature on the rectangle with Duals, sharing no code with the
  renderer;
- with it, the light's edge is held fixed and the derivative is 0.

Statistics: |estimate - expected| <= Z · stderr with Z the two-sided 99.99 % normal
quantile (Šidák over the file's 3 comparisons: family-wise level 3e-4); fixed seeds.
"""

from __future__ import annotations

import functools
from dataclasses import fields

import numpy as np

import sphere3d as s3
from flatland.core.dual import Dual, tangent, variable
from flatland.core.stats import normal_quantile
from sphere3d.boundary.emitters import edge_table, emitter_edge_term
from sphere3d.integrator import EmitterChange, Identity
from sphere3d.rotation import Rotation
from sphere3d.scene import load_scene
from sphere3d.state import build_state
from sphere3d.tasks import PointTask

Z = normal_quantile(0.9999)
LIGHT = {"centre": (0.5, 0.2, 1.5), "size": (0.6, 0.4), "emission": 5.0}
A = np.array([0.0, 0.0, 1.0])
A_DOT = np.array([0.4, -0.3, 0.0])
OMEGA = np.cross(A, A_DOT)
"""Angular velocity of the forced rotation: R follows a → a + θ ȧ, so Ṙω = (a × ȧ) × ω (sphere3d.rotation)."""
N = 1 << 17


def _scene(fade=0.0):
    light = {
        "name": "light", "type": "rectangle", "size": list(LIGHT["size"]), "translate": list(LIGHT["centre"]),
        "rotate": [np.pi, 0.0, 0.0], "emission": LIGHT["emission"], "albedo": 0.0, "fade": fade,
    }  # fmt: skip
    floor = {"name": "floor", "type": "rectangle", "translate": [0.0, 0.0, -1.0], "albedo": 0.0}
    camera = {"position": [0, -3, 1], "look_at": [0, 0, 0], "fov": 0.8, "width": 8, "height": 8}
    return {"name": "spin", "camera": camera, "sky": 0.0, "shapes": [light, floor]}


class Spin(Identity):
    """The emitter strategy turned by the forced rotation at every point, with the emitter edges'
    boundary term (:func:`~sphere3d.boundary.emitters.emitter_edge_term`) or without; the cosine
    strategy as ``naive``."""

    def __init__(self, emitter_edges: bool) -> None:
        self.emitter_edges = emitter_edges

    def emitter(self, shading, visible):
        m = len(shading)
        rotation = Rotation.following(Dual(np.tile(A, (m, 1)), np.tile(A_DOT, (m, 1))))
        extra = emitter_edge_term(shading.state, shading, rotation) if self.emitter_edges else None
        return EmitterChange(rotation, np.arange(m), extra)


@functools.cache
def _estimate(emitter_edges, fade=0.0, seed=3):
    task = PointTask(
        load_scene(_scene(fade)), "floor.translate.x", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), N, seed, 16
    )
    tally = task.evaluate(variable(0.0), Spin(emitter_edges))
    d = tally.derivative
    return float(np.mean(d)), float(np.std(d, ddof=1) / np.sqrt(len(d))), tally.value


def dragged_edge_term(nodes=64):
    """d/dθ of the emitter integral over the rotated light, by quadrature (module docstring)."""
    g, wq = np.polynomial.legendre.leggauss(nodes)
    (cx, cy, cz), (sx, sy) = LIGHT["centre"], LIGHT["size"]
    px, py = np.meshgrid(cx + 0.5 * sx * g, cy + 0.5 * sy * g, indexing="ij")
    y = np.stack([px, py, np.full_like(px, cz)], axis=-1)
    d0 = np.linalg.norm(y, axis=-1)
    w = y / d0[..., None]
    area_jacobian = w[..., 2] / d0**2  # cos θ_y / d² at θ0 (the light faces -z)
    theta = variable(0.0)
    omega = w + theta * np.cross(OMEGA, w)  # R(θ) w to first order (unit to first order: Ω × w ⟂ w)
    t = cz / omega[..., 2]  # the rotated ray meets the light's plane z = cz (no edge)
    cos = omega[..., 2]  # cos θ_x = cos θ_y = ω_z here
    p_light = t * t / (sx * sy * cos)
    p_cos = cos / np.pi
    h = LIGHT["emission"] * cos * p_light / (p_light + p_cos)
    weights = np.outer(wq, wq) * (0.25 * sx * sy)
    return float(tangent(np.sum(h * area_jacobian * weights)))


def test01_the_closed_form_of_the_dragged_edge_term_is_a_rotation_of_the_light():
    # the quadrature itself: its value is E_L = ∫ L w_L cos cos / d² dA, converged in the nodes,
    # and its derivative is nonzero (a rotation that drags the edge changes the integral)
    assert abs(dragged_edge_term(64) - dragged_edge_term(96)) < 1e-12
    assert abs(dragged_edge_term()) > 0.01


def test02_without_the_edge_term_the_forced_rotation_drags_the_light_edge():
    mean, se, _ = _estimate(False)
    exact = dragged_edge_term()
    assert abs(mean - exact) <= Z * se, (mean, se, exact)
    assert abs(mean) > Z * se  # the bias: the exact derivative is 0


def test03_with_the_edge_term_the_derivative_is_exact():
    mean, se, _ = _estimate(True)
    assert abs(mean) <= Z * se, (mean, se)


def test04_the_term_has_no_value_and_vanishes_at_a_faded_border():
    # bit-identity is the claim: the term adds to tangents only, and F_in = 0 where the fade is 0
    _, _, with_term = _estimate(True)
    _, _, without = _estimate(False)
    assert np.array_equal(with_term, without)
    task = PointTask(
        load_scene(_scene(0.2)), "floor.translate.x", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 4096, 5, 4
    )
    faded = [task.evaluate(variable(0.0), Spin(e)).derivative for e in (True, False)]
    assert np.array_equal(faded[0], faded[1])


def test05_reparam_keeps_the_primal_of_naive_bit_for_bit():
    kwargs = {"spp": 2, "seed": 7}
    naive = s3.render_gradient("hard_shadow", "occluder.translate.x", method="naive", **kwargs)
    reparam = s3.render_gradient("hard_shadow", "occluder.translate.x", method="reparam", **kwargs)
    assert np.array_equal(naive.value, reparam.value)


def test06_the_edge_table_is_built_once_per_state_and_read_only():
    # identity of the cached object is the claim; a fresh build gives the same numbers
    state = build_state(load_scene(_scene()), "floor.translate.x", variable(0.0))
    table = edge_table(state)
    assert edge_table(state) is table
    fresh = edge_table.__wrapped__(state)  # built anew, not from the cache
    for f in fields(table):
        assert np.array_equal(getattr(table, f.name), getattr(fresh, f.name))
        assert not getattr(table, f.name).flags.writeable
    other = build_state(load_scene(_scene()), "floor.translate.x", variable(0.0))
    assert edge_table(other) is not table
