"""The chart map of a small shape in a cosine kernel (:mod:`sphere3d.reparam.shading_affine`).

Predicted by the module's construction, checked here:

1. for one triangle the affine map of the gnomonic chart is exact: at the directions of the
   triangle's vertices its velocity is the vertices' own (d/dθ of the unit direction to each);
2. its Jacobian's log-derivative is the surface divergence of its velocity field on the sphere
   (central differences of the map's velocity at nearby directions, same kernel);
3. only kernels whose ring holds the shape's image (or a thin image reaching into it, or reaches a
   shape of one triangle) get the map, and not where another shape hides it;
4. on Lambert's closed form (a black triangle 0.1 rad across under a constant sky, scaling, moving
   in depth, tilting), reparam is within its Student-t quantile of the exact derivative with the
   map, and without it (``shading_shapes=False``) its bias is resolved: the map is what removes it;
5. the fan's cone is bounded by two consecutive vertices of the anchors' hull;
6. on a small black icosahedron under the sky (Lambert over its facing faces), reparam is unbiased
   under every motion, the turns included.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats
from scipy.spatial import ConvexHull

import sphere3d as s3
from flatland.core.dual import Dual, detach, tangent, variable
from flatland.core.rng import Draws
from sphere3d.closed_form import occluded_sky_irradiance, sky_triangle_scene
from sphere3d.integrator import Shading
from sphere3d.reparam.default import ReparamTransforms
from sphere3d.reparam.shading_affine import _hull_cone, inner_shape_map
from sphere3d.state import build_state
from sphere3d.tasks import PointTask

ORIGIN, NORMAL = np.zeros(3), np.array([0.5, 0.0, np.sqrt(0.75)])
REACH = 0.095  # a ring's angular radius (the default kernel's: 3 standard deviations of κ = 1000)


def _vertices(size: float, tilt_deg: float = 90.0) -> np.ndarray:
    """An equilateral triangle ``size`` rad across at distance 1 above the origin, its plane tilted
    about x so that the line of sight meets it at ``tilt_deg`` degrees."""
    angles = 2.0 * np.pi * np.arange(3) / 3.0 + 0.3
    r = np.tan(0.5 * size) / np.cos(np.pi / 6.0)
    local = np.stack([r * np.cos(angles), r * np.sin(angles), np.zeros(3)], axis=1)
    a = np.radians(90.0 - tilt_deg)
    turn = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(a), -np.sin(a)], [0.0, np.sin(a), np.cos(a)]])
    return local @ turn.T + np.array([0.0, 0.0, 1.0])


def _shading(scene: dict, param: str, n: int) -> Shading:
    state = build_state(s3.load_scene(scene), param, variable(0.0))
    return Shading.at(state, Dual(np.zeros((n, 3))), Dual(np.tile(NORMAL, (n, 1))), Draws.of(3, np.arange(n)))


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@pytest.mark.parametrize("param", ["tri.scale", "tri.translate.z", "tri.rotate.x", "tri.rotate.z"])
def test01_one_triangle_is_followed_exactly_at_its_vertices(param):
    scene = sky_triangle_scene(_vertices(0.1, 40.0))
    shading = _shading(scene, param, 3)
    tri = shading.state.triangles[0]  # Dual (3, 3)
    d = tri / np.sqrt(np.sum(tri * tri, axis=-1))[:, None]
    centre = np.tile(_unit(np.asarray(detach(tri)).mean(axis=0)), (3, 1))  # the ring holds the triangle
    out = inner_shape_map(shading, np.asarray(detach(d)), centre, REACH)
    assert out.mask.all()
    assert np.allclose(out.mu_dot, np.asarray(tangent(d)), rtol=1e-9, atol=1e-12)


def test02_the_jacobian_is_the_divergence_of_the_velocity():
    scene = sky_triangle_scene(_vertices(0.1, 60.0))
    centre = _unit(np.asarray(_vertices(0.1, 60.0)).mean(axis=0))
    rng = np.random.default_rng(4)
    mu = _unit(centre + 0.04 * rng.normal(size=(5, 3)))
    h = 1e-5
    for k in range(len(mu)):
        # a tangent frame at mu: the divergence on the sphere is the 2D divergence in it
        e1 = _unit(np.cross(mu[k], [0.3, 0.1, 1.0]))
        e2 = np.cross(mu[k], e1)
        pts = _unit(np.array([mu[k] + h * e1, mu[k] - h * e1, mu[k] + h * e2, mu[k] - h * e2, mu[k]]))
        shading = _shading(scene, "tri.scale", len(pts))
        out = inner_shape_map(shading, pts, np.tile(centre, (len(pts), 1)), REACH)
        assert out.mask.all()
        v = out.mu_dot
        div = (v[0] - v[1]) @ e1 / (2 * h) + (v[2] - v[3]) @ e2 / (2 * h)
        assert out.log_jacobian_dot[4] == pytest.approx(div, rel=1e-5, abs=1e-8)


def test03_only_kernels_whose_ring_holds_a_visible_shape_get_the_map():
    small = _vertices(0.05)
    scene = sky_triangle_scene(small)
    centre = _unit(small.mean(axis=0))
    far = _unit(centre + np.array([0.5, 0.0, 0.0]))
    shading = _shading(scene, "tri.scale", 2)
    out = inner_shape_map(shading, np.array([centre, far]), np.array([centre, far]), REACH)
    assert out.mask.tolist() == [True, False]
    # a mesh (two triangles: a quadrilateral) wider than the ring and not thin: no map; one triangle
    # as wide: the map wherever the ring reaches it (exact for a triangle)
    wide = _vertices(0.6)
    quad = sky_triangle_scene(wide)
    quad["shapes"][0]["vertices"].append((wide[1] + wide[2] - 2.0 * wide[0] + wide.mean(axis=0)).tolist())
    quad["shapes"][0]["faces"].append([1, 3, 2])
    out = inner_shape_map(_shading(quad, "tri.scale", 1), centre[None], centre[None], REACH)
    assert not out.mask.any()
    one = _shading(sky_triangle_scene(wide), "tri.scale", 1)
    out = inner_shape_map(one, centre[None], centre[None], REACH)
    assert out.mask.all()
    # a second, fixed triangle between the point and the moving one hides it
    hidden = sky_triangle_scene(small)
    hidden["shapes"].append({**hidden["shapes"][0], "name": "screen", "scale": 3.0, "translate": [0, 0, 0.5]})
    out = inner_shape_map(_shading(hidden, "tri.scale", 1), centre[None], centre[None], REACH)
    assert not out.mask.any()


CASES = [("tri.scale", 90.0), ("tri.translate.z", 90.0), ("tri.rotate.x", 30.0)]
N, BATCHES = 1 << 18, 16
Q = stats.t.ppf(1.0 - 0.5 * (1.0 - (1.0 - 0.01) ** (1.0 / (2 * len(CASES)))), BATCHES - 1)


@pytest.fixture(scope="module", params=CASES, ids=lambda c: f"{c[0]}-{c[1]:g}deg")
def estimates(request):
    param, tilt = request.param
    scene = s3.load_scene(sky_triangle_scene(_vertices(0.1, tilt)))
    _, exact = occluded_sky_irradiance(scene, ORIGIN, NORMAL, param)
    out = {}
    for on in (True, False):
        task = PointTask(scene, param, tuple(ORIGIN), tuple(NORMAL), N, 8, BATCHES)
        d = np.asarray(task.evaluate(variable(0.0), ReparamTransforms(shading_shapes=on)).derivative)
        out[on] = (d.mean() - exact) / (d.std(ddof=1) / np.sqrt(BATCHES))
    return out


def test04_the_map_removes_the_bias_of_one_rotation(estimates):
    assert abs(estimates[True]) <= Q
    assert abs(estimates[False]) > Q


def test05_the_fan_s_cone_is_bounded_by_two_consecutive_hull_vertices():
    """:func:`_hull_cone` on random anchor sets on an integer grid (exact turns: repeats, as the
    anchors' padding makes, and collinear points abound): its two anchors are consecutive vertices of
    the hull :class:`scipy.spatial.ConvexHull` finds, counter-clockwise, and the chart point lies in
    the cone they span from the centre."""
    rng = np.random.default_rng(5)
    u = rng.integers(-4, 5, size=(200, 12, 2)).astype(np.float64)
    u[:, 8:] = u[:, :4]  # repeats
    centre = u.mean(axis=1)
    at = centre + rng.normal(size=(200, 2)) * 3.0
    ends, e_inv = _hull_cone(u, centre, at)
    for r in range(200):
        hull = ConvexHull(u[r]).vertices  # counter-clockwise
        pos = [np.flatnonzero(np.all(u[r, hull] == u[r, e], axis=1))[0] for e in ends[r]]
        assert (pos[0] + 1) % len(hull) == pos[1]
        weights = e_inv[r] @ (at[r] - centre[r])  # at - c in the basis [u_i - c, u_j - c]
        assert np.all(weights >= -1e-12)


SMALL_BALL = {
    "name": "sky_ball",
    "sky": 1.0,
    "camera": {"position": [0, -3, 1], "look_at": [0, 0, 0], "up": [0, 0, 1], "fov": 0.5,
               "width": 8, "height": 8},
    "shapes": [{"name": "ball", "type": "icosphere", "radius": 0.06, "subdivisions": 0, "smooth": True,
                "albedo": 0.0, "translate": [0.3, 0.15, 1.0], "rotate": [0.3, 0.2, 0.1]}],
}  # fmt: skip
"""A black icosahedron 0.12 rad across seen from the origin under the sky: its whole image in a kernel."""
MOTIONS = ["rotate.x", "rotate.y", "rotate.z", "translate.x", "translate.z", "scale"]


@pytest.mark.parametrize("subdivisions", [0, 1])
@pytest.mark.parametrize("motion", MOTIONS)
def test06_a_small_mesh_is_unbiased_under_every_motion(motion, subdivisions):
    """The icosahedron above (12 vertices: all anchors) and its first subdivision (42: anchors found
    per kernel, :mod:`sphere3d.reparam.outline_anchors`), every motion, 2^18 samples: reparam's dE/dθ
    at the origin is within the Student-t quantile (15 dof, family-wise α = 0.01 over the cases, Šidák)
    of Lambert's closed form over its facing faces (:func:`~sphere3d.closed_form.occluded_sky_irradiance`).
    Each cone of the fan carries one outline edge; one affine map fitted to all the anchors by least
    squares fails this under the turns about x and y (the vertices' charts move in no affine way)."""
    ball = {**SMALL_BALL, "shapes": [{**SMALL_BALL["shapes"][0], "subdivisions": subdivisions}]}
    scene = s3.load_scene(ball)
    _, exact = occluded_sky_irradiance(scene, ORIGIN, NORMAL, "ball." + motion)
    task = PointTask(scene, "ball." + motion, tuple(ORIGIN), tuple(NORMAL), N, 5, BATCHES)
    d = np.asarray(task.evaluate(variable(0.0), ReparamTransforms()).derivative)
    q = stats.t.ppf(1.0 - 0.5 * (1.0 - (1.0 - 0.01) ** (1.0 / (2 * len(MOTIONS)))), BATCHES - 1)
    assert abs(d.mean() - exact) <= q * d.std(ddof=1) / np.sqrt(BATCHES), (d.mean(), exact)
