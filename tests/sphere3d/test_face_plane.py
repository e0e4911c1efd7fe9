"""The face's own plane in a cosine kernel at a smooth-shaded point (:mod:`sphere3d.reparam.face_plane`).

A point x on a large black triangle under a constant sky, its shading normal n_s tilted by β from the
face's normal n_g: the directions between the shading horizon and the face's plane meet the face
(black), those above the plane see the sky. The irradiance is the cosine integral over the two
hemispheres' intersection, closed form E = (π/2) (1 + n_s·n_g) (the lune between the two planes holds
(π/2) (1 - cos β) of the hemisphere's π), with n_s fixed: dE/dθ = (π/2) n_s·ṅ_g.

Predicted and checked:

1. the rule's rotation keeps every direction of the plane's great circle on the moving circle
   (ω̇·n_g + ω·ṅ_g = 0), for one parameter and for k at once;
2. under a translation in its plane the circle does not move and nothing else does: every sample's
   derivative is exactly 0 (without the rule a probe below the plane hits the face at distance
   ε / sin and the kernel follows that point, turning at |ẋ - v| / distance, x fixed on the sliding face);
3. the primal is within its Student-t quantile of E, and under a turn of the face the derivative is
   within its quantile of (π/2) n_s·ṅ_g, which is resolved from 0 (the identity's answer).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import sphere3d as s3
from flatland.core.dual import Dual, detach, tangent, variable
from flatland.core.rng import Draws
from flatland.core.stats import sidak
from sphere3d.closed_form import sky_triangle_scene
from sphere3d.integrator import Shading, irradiance_samples
from sphere3d.reparam.default import ReparamTransforms
from sphere3d.reparam.face_plane import face_plane_rotation
from sphere3d.rotation import Rotation
from sphere3d.state import build_state
from sphere3d.tracing import face_normals

BETA, PHI = 0.3, 0.7
N_S = np.array([np.sin(BETA) * np.cos(PHI), np.sin(BETA) * np.sin(PHI), np.cos(BETA)])
FACE = np.array([[-20.0, -20.0, 0.0], [20.0, -20.0, 0.0], [0.0, 20.0, 0.0]])
"""A triangle in the plane z = 0 facing +z, its centroid (where rotations act) at x = 0."""
ALPHA, BATCHES, PER_BATCH = 1e-3, 16, 1 << 14
TURNS = ("tri.rotate.x", "tri.rotate.y")


def _shading(params, n: int, seed: int = 0) -> Shading:
    """n shading points fixed at the face's centroid (on the face under its turns about the centroid and
    its translations in its plane, as a camera ray's hit slides on a moving face), shading normal N_S."""
    state = build_state(s3.load_scene(sky_triangle_scene(FACE - FACE.mean(axis=0))), params, variable(0.0))
    tri = state.triangles[np.zeros(n, dtype=np.intp)]
    x = Dual(np.zeros((n, 3)), None, state.k)
    n_s = Dual(np.tile(N_S, (n, 1)), None, state.k)
    return Shading.at(state, x, n_s, Draws.of(seed, np.arange(n)), face_normals(tri))


@pytest.mark.parametrize("params", ["tri.rotate.x", "tri.rotate.y", ["tri.rotate.x", "tri.rotate.y"]])
def test01_the_circle_stays_on_the_moving_plane(params):
    n = 64
    shading = _shading(params, n)
    rng = np.random.default_rng(1)
    g = shading.geometric
    # kernel centres within 0.1 rad of the circle, above the shading horizon
    az = rng.uniform(0.0, 2.0 * np.pi, n)
    el = rng.uniform(-0.1, 0.1, n)
    centre = np.stack([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)], axis=1)
    rotation = face_plane_rotation(shading, centre, 0.2, Rotation.identity((n,), shading.state.k))
    assert rotation.active.all()
    g0, g_dot = np.asarray(detach(g)), tangent(g)
    for offset in (-0.15, 0.0, 0.15):  # directions of the circle about each centre's foot
        foot = centre - np.sum(centre * g0, axis=1)[:, None] * g0
        foot /= np.linalg.norm(foot, axis=1)[:, None]
        along = np.cross(g0, foot)
        omega = np.cos(offset) * foot + np.sin(offset) * along
        omega_dot = tangent(rotation.apply(omega))
        stays = np.sum(omega_dot * g0, axis=-1) + np.sum(omega * g_dot, axis=-1)
        assert np.abs(stays).max() < 1e-12


@pytest.mark.parametrize("param", ["tri.translate.x", "tri.translate.y"])
def test02_a_translation_leaves_every_sample_unchanged(param):
    shading = _shading(param, 4096)
    estimate = irradiance_samples(shading, shading.draws.uniforms("samples", 5), ReparamTransforms())
    assert np.all(tangent(estimate) == 0.0)
    assert np.mean(detach(estimate)) > 0.0


@pytest.fixture(scope="module", params=TURNS)
def turning(request):
    """Batch means of E and dE/dθ under a turn of the face, and their closed forms."""
    param = request.param
    values, derivatives = [], []
    for b in range(BATCHES):
        shading = _shading(param, PER_BATCH, seed=b)
        estimate = irradiance_samples(shading, shading.draws.uniforms("samples", 5), ReparamTransforms())
        values.append(np.mean(detach(estimate)))
        derivatives.append(np.mean(tangent(estimate)))
    g = _shading(param, 1).geometric
    exact = 0.5 * np.pi * (1.0 + N_S @ np.asarray(detach(g))[0])
    exact_dot = 0.5 * np.pi * (N_S @ tangent(g)[0])
    return np.array(values), np.array(derivatives), exact, exact_dot


Q = stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, 3 * len(TURNS)), BATCHES - 1)


def test03_a_turning_face_matches_the_closed_form(turning):
    values, derivatives, exact, exact_dot = turning
    se = lambda a: a.std(ddof=1) / np.sqrt(len(a))  # noqa: E731
    assert abs(values.mean() - exact) <= Q * se(values)
    assert abs(derivatives.mean() - exact_dot) <= Q * se(derivatives)
    # the identity (no rule) would give 0: the closed form is resolved from it
    assert abs(exact_dot) > Q * se(derivatives)
