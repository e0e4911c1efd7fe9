"""The ``boundary`` method: mesh edges, closed forms of its two terms, agreement with finite differences.

- Edges: adjacency of the built-in meshes, non-manifold and unwelded meshes.
- Pixel integrals (primary edges): a black triangle under a constant sky has a
  constant-radiance image except on the triangle, so the exact derivative of every
  pixel is ``-L ∮ k(x - p) (v·n) dl`` along the triangle's image, computed here by
  quadrature with a pinhole projection written in this file and velocities by central
  differences of projected vertices (no code shared with the method but the filter).
- Shading integrals (secondary edges): the irradiance under the same triangle, the
  derivative of Lambert's formula (tests/sphere3d/test_closed_forms.py), and a light
  without a fade moving (its border is a discontinuity; reparam loses 73 % there).
- Every built-in scene, for translate, rotate and scale parameters: per-pixel z-scores
  against a finite-difference image (slow).
- ``hard_shadow``: no crease term on its smooth occluder, and per-region sums against the
  stored Richardson reference; seen from the side of its terminator, turning, the smooth creases
  carry no term even where the occluder shadows itself.

Statistics: ``|estimate - exact| <= Z stderr`` with Z the two-sided normal quantile at the
Šidák level for the comparisons of a test (family-wise level ALPHA = 1e-3 per test, fixed
seeds); against finite differences both standard errors count and the quantile is
Student's t with the batches' degrees of freedom. A sum over several pixels (a region, the film)
takes its standard error from the spread of its per-batch values, with Student's t at batches - 1
degrees of freedom: the splatted film and the edge points correlate neighbouring pixels.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import sphere3d as s3
from benchmarks.hard_shadow_reference import load_reference
from flatland.core.dual import detach, tangent, variable
from flatland.core.image import summarize_batches
from flatland.core.stats import normal_quantile, sidak
from flatland.core.validate import ValidationError
from sphere3d import closed_form
from sphere3d.boundary import camera
from sphere3d.boundary.camera import camera_edge_term
from sphere3d.boundary.edges import mesh_edges
from sphere3d.methods import GRADIENT_METHODS
from sphere3d.sampling import filter_value
from sphere3d.state import build_state
from sphere3d.tasks import ImageTask
from sphere3d.tracing import face_normals
from tests.sphere3d.helpers import (
    ORIGIN,
    SKY,
    UP,
    footprint_rays,
    lambert,
    light_exact,
    light_scene,
    over_batches,
    regions,
    triangle_exact,
    triangle_scene,
)
from tests.tiers import SLOW, sweep

ALPHA = 1e-3
SIZE = 16
LOCAL = np.array([[0.0, 0.0, -0.5], [0.9, 0.0, 0.0], [0.0, 0.0, 0.5]])
CENTRE = np.array([-0.3, 0.0, 1.0])
TRIANGLE = LOCAL + CENTRE
CAMERA = {"position": [0, -3, 1], "look_at": [0, 0, 1], "fov": 0.8, "width": SIZE, "height": SIZE}


def _z(level_count: int) -> float:
    return normal_quantile(1.0 - sidak(ALPHA, level_count))


def _black_triangle(vertices=LOCAL, faces=((0, 1, 2),)) -> dict:
    shape = {"name": "tri", "type": "mesh", "vertices": np.asarray(vertices).tolist(), "albedo": 0.0}
    shape.update(faces=[list(f) for f in faces], translate=CENTRE.tolist())
    return {"name": "triangle", "camera": CAMERA, "sky": SKY, "shapes": [shape]}


def _film(points: np.ndarray, camera: dict) -> np.ndarray:
    """Pinhole projection to continuous pixel coordinates (x right, y down), written independently."""
    eye, target = np.array(camera["position"], float), np.array(camera["look_at"], float)
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    rel = points - eye
    depth = rel @ forward
    half = np.tan(0.5 * camera["fov"])
    x = (rel @ right / depth / half + 1.0) * 0.5 * camera["width"]
    y = (1.0 - rel @ up / depth / (half * camera["height"] / camera["width"])) * 0.5 * camera["height"]
    return np.stack([x, y], axis=-1)


def _moved(param: str, theta: float) -> tuple[np.ndarray, dict]:
    """The triangle's vertices and the camera with ``param`` offset by θ."""
    vertices, camera = TRIANGLE.copy(), {**CAMERA, "position": list(map(float, CAMERA["position"]))}
    owner, kind, *axis = param.split(".")
    if owner == "camera":
        camera["position"][("x", "y", "z").index(axis[0])] += theta
        camera["look_at"] = list(np.add(CAMERA["look_at"], np.eye(3)[("x", "y", "z").index(axis[0])] * theta))
    elif kind == "translate":
        vertices[:, ("x", "y", "z").index(axis[0])] += theta
    else:  # scale about the shape's centre, the origin of its local coordinates
        vertices = CENTRE + (1.0 + theta) * LOCAL
    return vertices, camera


def _triangle_pixel_derivatives(param: str, nodes: int = 4000) -> np.ndarray:
    """``dI_p/dθ = -L ∮ k(x - p) (v·n_out) dl`` along the triangle's image, by the midpoint rule."""
    s = (np.arange(nodes) + 0.5) / nodes
    out = np.zeros((SIZE, SIZE))
    h = 1e-6
    centres = np.stack(np.meshgrid(np.arange(SIZE) + 0.5, np.arange(SIZE) + 0.5), axis=-1).reshape(-1, 2)
    for i in range(3):
        ends = [_moved(param, t) for t in (0.0, h, -h)]
        # points of the 3D edge at fixed s, projected; on the film they are evenly spaced only in 3D
        pts = [_film(v[i] + s[:, None] * (v[(i + 1) % 3] - v[i]), cam) for v, cam in ends]
        x, velocity = pts[0], (pts[1] - pts[2]) / (2.0 * h)
        corner = _film(TRIANGLE, CAMERA)
        seg = corner[(i + 1) % 3] - corner[i]
        outward = np.array([seg[1], -seg[0]]) / np.linalg.norm(seg)
        if outward @ (corner[i] - corner.mean(axis=0)) < 0.0:
            outward = -outward
        dl = np.linalg.norm(np.gradient(x, axis=0), axis=1)  # film length per node (non-uniform)
        k = filter_value(x[None] - centres[:, None], "gaussian")  # (pixels, nodes)
        out -= SKY * (k @ (velocity @ outward * dl)).reshape(SIZE, SIZE)
    return out


def test01_edges_of_the_builtin_meshes():
    state = build_state(s3.load_scene("shadow"))
    edges = mesh_edges(state.triangles, state.shape_of)
    shape = state.shape_of[edges.face]
    floor, box, light = (shape == i for i in range(3))
    # a box: 12 crease edges and 6 coplanar face diagonals, every one between two faces
    assert box.sum() == 18 and edges.crease[box].sum() == 12 and np.all(edges.count[box] == 2)
    # a rectangle: 4 boundary edges (candidates from everywhere) and its diagonal
    for rect in (floor, light):
        assert rect.sum() == 5 and np.sum(edges.count[rect] == 1) == 4 and edges.always[rect].sum() == 4
        assert not edges.crease[rect].any()
    # seen from above, the box's silhouette is a closed loop of 4 to 6 edges plus every boundary edge
    sil = edges.silhouette(np.array([0.3, -0.2, 5.0]))
    assert 4 <= np.sum(sil & box) <= 6 and np.sum(sil & ~box) == 8


@SLOW
def test02_non_manifold_and_unwelded_meshes_and_degenerate_triangles():
    """Three triangles on one edge: one edge of count 3, a candidate from every viewpoint (the jump
    across it is traced, so any number of faces is handled). Duplicated vertices weld by position.
    A zero-length edge means a zero-area triangle, which the scene refuses; a sliver of nonzero area
    is accepted and gives finite results (its normal is a normalized nonzero cross product)."""
    fin = [[0, 0, 0], [0, 0, 1], [1, 0, 0.5], [-0.5, 0.8, 0.5], [-0.5, -0.8, 0.5]]
    faces = [[0, 1, 2], [1, 0, 3], [0, 1, 4]]
    state = build_state(s3.load_scene(_black_triangle(fin, faces)))
    edges = mesh_edges(state.triangles, state.shape_of)
    assert len(edges) == 7 and np.sum(edges.count == 3) == 1
    assert edges.always[edges.count == 3].all() and edges.other[edges.count == 3] == -1
    split = np.array([*LOCAL.tolist(), LOCAL[0].tolist(), [0.6, 0.0, 0.4]])
    two = build_state(s3.load_scene(_black_triangle(split, [(0, 1, 2), (3, 2, 4)])))
    welded = mesh_edges(two.triangles, two.shape_of)
    assert len(welded) == 5 and np.sum(welded.count == 2) == 1
    # the fin renders: finite, and its film-summed derivative agrees with finite differences. The film
    # sum is taken per batch (16 each): the splatted film and the edge points shared by neighbouring
    # pixels correlate the pixels, the batches are independent. Its mean's standard error from the
    # batches' spread, the two renders' (independent seeds) added in quadrature; two-sided Student's t
    # at 15 degrees of freedom, each render's (Welch's degrees of freedom are at least that), level ALPHA.
    # Finite differences at 4096 spp (film sum 9.97 +- 1.09; at 1024 spp +- 2.54, where the bound was
    # 10.3, as large as the sum): an error of half the sum fails
    fin_scene = _black_triangle(fin, faces)
    g = _batches(fin_scene, "tri.translate.x", "boundary", 64, 4, batches=16)
    ref = _batches(fin_scene, "tri.translate.x", "finite_difference", 4096, 5, batches=16, h=0.01)
    assert np.all(np.isfinite(g)) and abs(g.mean(axis=0).sum()) > 0.5
    (total, se), (ref_total, ref_se) = (over_batches(b.sum(axis=(1, 2))) for b in (g, ref))
    limit = stats.t.ppf(1.0 - 0.5 * ALPHA, 15)
    print(f"fin: film sum {total:.4f} +- {se:.4f} vs {ref_total:.4f} +- {ref_se:.4f}, ", end="")
    print(f"|t| {abs(total - ref_total) / np.hypot(se, ref_se):.2f} <= {limit:.2f}")
    assert abs(total - ref_total) <= limit * np.hypot(se, ref_se)
    with pytest.raises(ValidationError, match="degenerate"):
        s3.load_scene(_black_triangle([[0, 0, 0], [0, 0, 0], [1, 0, 0]]))
    # under a black sky and a light (arcs clipped to its image, but not the non-manifold edge's),
    # the fin and a sliver 1e-9 high (accepted: its area is not 0) give finite derivatives
    light = {"name": "light", "type": "rectangle", "size": [1.0, 1.0], "translate": [0.0, -0.5, 2.5]}
    light.update(rotate=[np.pi, 0.0, 0.0], emission=20.0, fade=0.0, albedo=0.0)
    ground = {"name": "ground", "type": "rectangle", "size": [5.0, 5.0], "translate": [0, 0, -0.2]}
    for vertices, tris in ((fin, faces), ([[0, 0, 0], [0.5, 0, 1e-9], [1, 0, 0]], [(0, 1, 2)])):
        lit = _black_triangle(vertices, tris)
        lit["shapes"][0]["albedo"] = 0.5
        lit.update(sky=0.0, shapes=[*lit["shapes"], light, ground])
        g = s3.render_gradient(lit, "tri.translate.x", method="boundary", spp=16, seed=1)
        assert np.all(np.isfinite(g.derivative)) and np.all(np.isfinite(g.derivative_stderr))


@pytest.mark.parametrize(
    "param",
    sweep(
        ["tri.translate.x", "tri.translate.z", "tri.scale", "camera.translate.x"],
        ["tri.translate.x", "tri.translate.z"],
    ),
)
def test03_black_triangle_pixels_match_the_closed_form(param):
    """Primary edges alone (the triangle reflects nothing, the sky is constant): every pixel
    within Z standard errors of the exact derivative, the film sum too, and pixels out of the
    filter's reach exactly 0. Measured at 64 spp, 32 batches, with the splatted film (the default):
    max |z| 3.46 for each parameter, over the 56-60 pixels with spread (the film's others exact), at
    the same pixel (10, 9), and the next two (2.62, 2.57) the same too. Not four events but one: the
    triangle faces the camera (the plane y = 0, seen along +y), and each of the four motions (its
    translations in x and z, its scaling about the centroid, the camera's translation in x) moves
    its image by a translation or a scaling, under which an edge's normal speed is constant along the
    edge (n · v for a translation by v, the rate times the distance from the centre to the edge's
    line for a scaling). A pixel near one edge then has estimate and exact derivative both that
    speed times one sum over the same edge samples: the same z for every parameter. One pixel at
    |t| = 3.46 of 31 degrees of freedom is p = 0.0016, 0.09 for the largest of 58."""
    exact = _triangle_pixel_derivatives(param)
    task = ImageTask(s3.load_scene(_black_triangle()), param, 64, 1, BATCHES)
    tally = GRADIENT_METHODS.run("boundary", task)
    g = summarize_batches(tally.derivative)
    assert np.all(np.isfinite(g.mean)) and np.abs(exact).max() > 0.5
    live = g.stderr > 0.0
    assert np.all(exact[~live] == 0.0) and np.all(g.mean[~live] == 0.0)
    z = (g.mean - exact)[live] / g.stderr[live]
    assert np.abs(z).max() <= stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, live.sum()), BATCHES - 1)
    # the film sum, per batch (the splatted film and shared edge points correlate the pixels, not the
    # batches): its mean against the exact sum, two-sided Student's t at 31 degrees of freedom, level ALPHA
    total, total_se = over_batches(tally.derivative.sum(axis=(1, 2)))
    limit = stats.t.ppf(1.0 - 0.5 * ALPHA, BATCHES - 1)
    print(f"{param}: film sum {total:.4f} +- {total_se:.4f} vs {exact.sum():.4f}, ", end="")
    print(f"|t| {abs(total - exact.sum()) / total_se:.2f} <= {limit:.2f}")
    assert abs(total - exact.sum()) <= limit * total_se
    naive = GRADIENT_METHODS.run("naive", task)
    assert np.array_equal(naive.value, tally.value) and np.all(naive.derivative == 0.0)


@pytest.mark.parametrize("axis", sweep([0, 1, 2], [0]), ids=["translate.x", "translate.y", "translate.z"])
def test04_irradiance_under_a_black_triangle_matches_lambert(axis):
    """Secondary edges alone: E = L (π - Φ), Φ by Lambert's formula differentiated with Duals. naive
    gives exactly 0 here (test_closed_forms test03). Measured (2^17 samples): z 0.9, 1.6, 1.3."""
    exact = float(tangent(triangle_exact(axis)))
    param = f"tri.translate.{'xyz'[axis]}"
    e = s3.irradiance(triangle_scene(), ORIGIN, UP, param, method="boundary", n=1 << 17, seed=3)
    assert abs(e.derivative - exact) <= _z(3) * e.derivative_stderr
    assert (
        e.value == s3.irradiance(triangle_scene(), ORIGIN, UP, param, method="naive", n=1 << 17, seed=3).value
    )


def test05_a_light_without_fade_moving_has_its_border_as_the_only_moving_edge():
    """The unfaded light of test_closed_forms test07 (reparam 73 % low, naive 0): its own boundary
    edges are silhouettes seen from the point, the jump is its radiance. Exact -0.3007."""
    exact = float(tangent(light_exact(0.0)))
    e = s3.irradiance(light_scene(0.0), ORIGIN, UP, "light.translate.x", method="boundary", n=1 << 17, seed=6)
    assert abs(e.derivative - exact) <= _z(1) * e.derivative_stderr
    assert abs(detach(e.value)) > 0.0


SCENE_CASES = [
    ("shadow", "occluder.translate.x"),
    ("shadow", "occluder.rotate.z"),
    ("shadow", "occluder.scale"),
    ("shadow", "camera.translate.x"),
    ("silhouette", "occluder.rotate.z"),
    ("silhouette", "occluder.scale"),
    ("sky", "occluder.scale"),
    ("sky", "occluder.translate.z"),
    ("two_occluders", "left.translate.x"),
    ("two_occluders", "right.rotate.z"),
]
BATCHES = 32


def _batches(
    scene: dict,
    param: str,
    method: str,
    spp: int,
    seed: int,
    film: str = "splat",
    batches: int = BATCHES,
    **options,
) -> np.ndarray:
    """Per-batch derivative images (batches, SIZE, SIZE) of ``method`` with ``film``."""
    task = ImageTask(s3.load_scene(scene), param, spp, seed, batches, film=film)
    return GRADIENT_METHODS.run(method, task, **options).derivative


@pytest.mark.slow  # 8192-spp finite differences per scene: the closed forms (test03, test07) in make test
@pytest.mark.parametrize("scene, param", SCENE_CASES, ids=[f"{s}-{p}" for s, p in SCENE_CASES])
def test06_every_builtin_scene_agrees_with_finite_differences_per_pixel(scene, param):
    """Per-pixel z-scores against a finite-difference image (h = 0.02, 8192 spp, seed 2) on a
    16 × 16 film, boundary at 1024 spp (seed 1), 32 batches each: ``|z| <= t₃₁`` at the Šidák level
    ALPHA over the pixels tested.

    A pixel is tested where at least half the reference's batches saw its value change: finite
    differences see a moving edge only through the few samples that cross it, and a pixel
    where most batches saw none (a filter's tail, a faint penumbra) has a batch standard
    error that says little (one crossing in 32 batches: mean ± mean). Measured max |z| over
    the ten cases 1.8-3.4 (limits 4.9-5.5), 31-208 pixels tested per case (1.9-3.8 with boundary
    on the per-pixel film).

    boundary renders with the default, splatted film; the reference with the per-pixel film
    (``film="pixel"``), whose pixels see a crossing only through their own samples, as the rule
    above assumes. A splatted reference sees crossings in the filter's far tails in every batch,
    where h's truncation error shows: on ``sky``/``occluder.translate.z`` four pixels of row 2 gave
    |z| 5.8-9.0, finite differences there -0.00031 / -0.00019 / -0.00016 at h = 0.02 / 0.01 / 0.005
    (standard error 0.00001-0.00002), boundary -0.00016 with either film.
    """
    d = s3.load_scene(scene).to_dict()
    d["camera"].update(width=SIZE, height=SIZE)
    ref = _batches(d, param, "finite_difference", 8192, 2, film="pixel", h=0.02)
    g = _batches(d, param, "boundary", 1024, 1)
    assert np.all(np.isfinite(g))
    seen = np.sum(np.abs(ref) > 1e-9 * np.abs(ref).max(), axis=0)
    tested = seen >= BATCHES // 2
    se = np.hypot(g.std(axis=0, ddof=1), ref.std(axis=0, ddof=1)) / np.sqrt(BATCHES)
    z = (g.mean(axis=0) - ref.mean(axis=0))[tested] / se[tested]
    limit = stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, int(tested.sum())), BATCHES - 1)
    print(f"{scene} {param}: {tested.sum()} pixels, max |z| {np.abs(z).max():.2f} <= {limit:.2f}")
    assert tested.sum() >= 30 and np.abs(z).max() <= limit


CLOSED_CASES = [
    (size, kind, param)
    for size in (0.5, 3.0, 10.0)
    for kind in ("gaussian", "tent")
    for param in ("tri.translate.x", "tri.translate.z", "tri.rotate.z")
]


@pytest.mark.parametrize(
    "size, kind, param",
    sweep(CLOSED_CASES, [c for c in CLOSED_CASES if c[0] == 3.0 and c[1] == "gaussian"]),
    ids=["-".join(map(str, c)) for c in CLOSED_CASES],
)
def test07_triangles_through_the_pinhole_match_sphere3d_closed_form(size, kind, param):
    """The same check as test03 against :func:`sphere3d.closed_form.triangle_image` (Green's theorem
    and Gauss-Legendre quadrature between the filter's kinks), for triangles 0.5 to 10 px across and
    both continuous filters. Measured max |z| 1.2-4.2 (limits about 4.6-5.2); pixels without
    variance are exact to 3e-11. (With the box filter a pixel clipping an edge by a sliver is a rare
    event at 64 spp, whose batch error can be 0: not tested per pixel.)"""
    scene = closed_form.pinhole_triangle_scene(size, filter=kind)
    exact = closed_form.triangle_image(scene, param).derivative
    g = s3.render_gradient(scene, param, method="boundary", spp=64, seed=1, batches=32)
    live = g.derivative_stderr > 0.0
    assert np.all(np.abs(g.derivative - exact)[~live] <= 1e-9)
    z = (g.derivative - exact)[live] / g.derivative_stderr[live]
    assert np.abs(z).max() <= stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, live.sum()), 31)


@SLOW  # the cube (test10) is the same check in make test
def test08_hard_shadow_smooth_creases_add_nothing_and_regions_match_the_reference():
    """``hard_shadow`` (smooth icosphere, unfaded light) against its stored Richardson reference.

    Pixels whose filter footprint lies on the occluder only (the ``occluder`` region of
    tests/sphere3d/test_hard_shadow.py) see no silhouette, so the camera term there comes
    from creases alone: exactly 0 for a smooth shape, whose shading is continuous across
    them (it was an O(EPS_FILM) difference of the two side rays: region sum 0.11 ± 0.03
    over 24 seeds of 32 and 64 spp). Then per region and for the whole film, the sum of the 16 batch means
    (batch-to-batch standard error: pixels sharing splatted edge points are correlated)
    against the reference's sum (its pixels are independent), ``|z| <= t₁₅`` at the Šidák
    level ALPHA over the four non-empty regions and the film. Per pixel z-scores are not
    used: the interior term has rare events on this scene (a sliver of light above the
    occluder's terminator: 0.0032 ± 0.0009 at 4096 spp where 1024 spp all give 0).
    """
    scene = s3.load_scene("hard_shadow")
    masks = regions("hard_shadow")
    plain = build_state(scene, "occluder.translate.x", 0.0)
    edges = mesh_edges(plain.triangles, plain.shape_of)
    state = build_state(scene, "occluder.translate.x", variable(0.0))
    crease_only = camera_edge_term(state, plain, edges, seed=3, batch=0, points_per_pixel=16.0)
    assert np.all(crease_only[masks["occluder"]] == 0.0)

    ref = load_reference("hard_shadow")
    g = GRADIENT_METHODS.run("boundary", ImageTask(scene, "occluder.translate.x", 64, 5, 16)).derivative
    tested = {k: m for k, m in masks.items() if m.any()} | {"film": np.ones((64, 64), dtype=bool)}
    limit = stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, len(tested)), 15)
    for key, mask in tested.items():
        sums = g[:, mask].sum(axis=1)
        se = np.hypot(
            sums.std(ddof=1) / 4.0,  # 4 = sqrt(16 batches)
            np.sqrt(np.sum(ref["stderr"][mask] ** 2)),
        )
        z = (sums.mean() - ref["derivative"][mask].sum()) / se
        print(f"{key}: {sums.mean():.2f} vs {ref['derivative'][mask].sum():.2f}, z {z:.2f} <= {limit:.2f}")
        assert abs(z) <= limit, key


SHADE = np.array([[0.2, 0.05, 1.0], [0.6, -0.1, 1.0], [0.35, 0.3, 1.0]])
"""A black triangle between the origin and the light of ``light_scene(0.0)`` (x 0.2-0.8, y 0-0.4 at
z = 1.5), covering part of it as seen from the origin."""


def _shaded_light_exact(theta: float) -> float:
    """E at the origin: the light's projected solid angle minus that of its part behind the triangle
    moved by θ in x (Lambert's formula; the part by clipping the triangle's central projection on
    the light's plane z = 1.5 to the light's rectangle, Sutherland-Hodgman)."""
    poly = [p * 1.5 / p[2] for p in SHADE + np.array([theta, 0.0, 0.0])]
    for axis, bound, keep in ((0, 0.2, 1.0), (0, 0.8, -1.0), (1, 0.0, 1.0), (1, 0.4, -1.0)):
        inside = [keep * (p[axis] - bound) >= 0.0 for p in poly]
        clipped = []
        for i, p in enumerate(poly):
            q = poly[(i + 1) % len(poly)]
            if inside[i]:
                clipped.append(p)
            if inside[i] != inside[(i + 1) % len(poly)]:
                clipped.append(p + (bound - p[axis]) / (q[axis] - p[axis]) * (q - p))
        poly = clipped
    light = np.array([[0.2, 0.0, 1.5], [0.8, 0.0, 1.5], [0.8, 0.4, 1.5], [0.2, 0.4, 1.5]])
    return 5.0 * (lambert(light) - lambert(np.array(poly)))


@SLOW
def test09_a_black_triangle_shading_a_light_under_a_black_sky_matches_lambert():
    """Secondary edges clipped to the light's image: under a black sky the triangle's arcs count only
    where they cross the light's spherical image (:func:`sphere3d.boundary.shading.clip_arcs`),
    and the light's own border does not move (culled). Exact derivative: central differences
    (h = 1e-5) of the closed form above, whose truncation error (~1e-9) is far below the stderr.
    Measured (2^16 samples): z 1.55 here; the mean of 8 other seeds z 0.3, and with a 1e-9 sky
    (arcs not clipped) z 0.8 with 1.3 × the stderr. naive gives exactly 0 (the triangle is black)."""
    scene = light_scene(0.0)
    scene["shapes"].append({"name": "tri", "type": "mesh", "vertices": SHADE.tolist(), "faces": [[0, 1, 2]]})
    scene["shapes"][-1]["albedo"] = 0.0
    h = 1e-5
    exact = (_shaded_light_exact(h) - _shaded_light_exact(-h)) / (2.0 * h)
    e = s3.irradiance(scene, ORIGIN, UP, "tri.translate.x", method="boundary", n=1 << 16, seed=4)
    print(f"{e.derivative:.4f} ± {e.derivative_stderr:.4f} vs {exact:.4f}")
    assert abs(e.derivative - exact) <= _z(1) * e.derivative_stderr
    assert (
        s3.irradiance(scene, ORIGIN, UP, "tri.translate.x", method="naive", n=4096, seed=4).derivative == 0.0
    )


def _crease_pixels(name: str) -> np.ndarray:
    """Pixels whose filter footprint (the grid of tests/sphere3d/helpers.py, footprint_rays) meets faces with
    different normals: on the cube, the images of its creases and of its silhouette."""
    scene = s3.load_scene(name)
    state = build_state(scene)
    cam = state.camera
    _, _, d = footprint_rays(state)
    hits = state.tracer.intersect(np.array(scene.camera.position), d)
    normals = face_normals(np.asarray(state.triangles)[hits.triangle])
    return (np.ptp(normals, axis=1).max(axis=-1) > 1e-6).reshape(cam.height, cam.width)


@pytest.mark.slow
def test10_hard_shadow_cube_creases_and_regions_match_the_reference():
    """``hard_shadow_cube`` (flat-shaded box: its creases are discontinuities of the shading) against its
    stored Richardson reference, boundary at 64 spp, 16 batches (seed 5).

    Regions of tests/sphere3d/test_hard_shadow.py, the ``occluder`` one split into ``crease``
    pixels (footprint on two faces or more) and ``face`` pixels. Two families, each at the Šidák
    level ALPHA, ``|z| <= t₁₅`` with both standard errors (batch-to-batch and the reference's):

    - per region and the film, the sum over its pixels as in test08; a region where both images
      are exactly 0 (no sample saw anything move: the umbra) must be 0 in both;
    - per pixel, the pixels of the ``crease``, ``silhouette`` and ``penumbra`` regions where the
      reference resolves a derivative, ``|ref| >= max(10 se_ref, 0.01)`` (chosen from the
      reference alone; the rest are filter tails: ~1e-5 values, O(ε) effects of the rays traced
      beside the edges, and ~1e-15 rounding in the reference).

    Measured (default, splatted film): region |z| <= 1.5 (crease -6.58 vs -5.45, z -0.59); per pixel
    rms z 1.02 over 1254 pixels, max |z| 3.97 (limit 8.05). With the per-pixel film: region |z| <=
    0.65 (crease -6.57 vs -5.45 ± 1.92), rms z 1.04, the 55 crease pixels alone max 2.9; at 256 spp
    (seed 6): crease -5.26 vs -5.45 ± 0.92, rms z 1.2, 1.1, 1.0.
    """
    name = "hard_shadow_cube"
    base = regions(name)
    crease = _crease_pixels(name)
    masks = {"crease": base["occluder"] & crease, "face": base["occluder"] & ~crease}
    masks.update({k: v for k, v in base.items() if k != "occluder"})
    assert masks["crease"].sum() >= 50 and masks["face"].sum() >= 50  # both are covered
    ref = load_reference(name)
    task = ImageTask(s3.load_scene(name), "occluder.translate.x", 64, 5, 16)
    g = GRADIENT_METHODS.run("boundary", task).derivative
    assert np.all(np.isfinite(g))
    tested = {k: m for k, m in masks.items() if m.any()} | {"film": np.ones((64, 64), dtype=bool)}
    sums = {k: g[:, m].sum(axis=1) for k, m in tested.items()}
    se = {
        k: np.hypot(s.std(ddof=1) / 4.0, np.sqrt(np.sum(ref["stderr"][tested[k]] ** 2)))
        for k, s in sums.items()
    }
    zero = [k for k in tested if se[k] == 0.0]
    for key in zero:  # nothing moved in any sample, nor in the reference
        assert np.all(g[:, tested[key]] == 0.0) and np.all(ref["derivative"][tested[key]] == 0.0), key
    limit = stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, len(tested) - len(zero)), 15)
    for key in [k for k in tested if k not in zero]:
        z = (sums[key].mean() - ref["derivative"][tested[key]].sum()) / se[key]
        print(f"{key}: {sums[key].mean():.2f} vs {ref['derivative'][tested[key]].sum():.2f}, z {z:.2f}")
        assert abs(z) <= limit, key
    resolved = np.abs(ref["derivative"]) >= np.maximum(10.0 * ref["stderr"], 0.01)
    pixels = resolved & (masks["crease"] | masks["silhouette"] | masks["penumbra"])
    assert (pixels & masks["crease"]).sum() >= 40
    pixel_se = np.hypot(g.std(axis=0, ddof=1) / 4.0, ref["stderr"])[pixels]
    z = (g.mean(axis=0) - ref["derivative"])[pixels] / pixel_se
    limit = stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, int(pixels.sum())), 15)
    rms = np.sqrt(np.mean(z**2))
    print(f"{pixels.sum()} pixels: max |z| {np.abs(z).max():.2f} <= {limit:.2f}, rms {rms:.2f}")
    assert np.abs(z).max() <= limit


def test11_edge_points_in_chunks_and_edge_samples_in_slices_give_the_numbers_of_one_pass(monkeypatch):
    # memory bounds (sphere3d.boundary.camera.point_bytes, sphere3d.boundary.transforms.draw_bytes): each
    # chunk of film edge points reads its own part of the batch's stream, each slice of shading points
    # its points' keyed uniforms; only the order of the film's sums changes (rounding)
    import sphere3d.boundary.transforms as transforms

    scene = s3.load_scene("shadow")
    plain = build_state(scene, "occluder.translate.x")
    state = build_state(scene, "occluder.translate.x", variable(0.0))
    edges = mesh_edges(plain.triangles, plain.shape_of)
    whole = camera_edge_term(state, plain, edges, 5, 2, 1.0)
    assert camera.point_count(1.0, camera.film_edges(state, plain, edges).length).sum() > 150
    monkeypatch.setattr(camera, "POINT_CHUNK", 50)
    np.testing.assert_allclose(camera_edge_term(state, plain, edges, 5, 2, 1.0), whole, rtol=0, atol=1e-12)
    point = dict(param="occluder.translate.x", method="boundary", n=32, secondary=8, progress=False)
    one = s3.irradiance("shadow", [0.136, -0.214, 0.0], [0, 0, 1], **point)
    monkeypatch.setattr(transforms, "DRAW_CHUNK", 64)  # slices of 8 shading points
    sliced = s3.irradiance("shadow", [0.136, -0.214, 0.0], [0, 0, 1], **point)
    assert one.derivative != 0.0 and sliced.derivative == pytest.approx(one.derivative, rel=1e-12, abs=0)
    assert sliced.value == one.value


def test12_smooth_creases_carry_no_term_even_across_the_terminator(monkeypatch):
    """Why :func:`~sphere3d.boundary.camera.camera_candidates` may skip a smooth shape's creases: a
    shadow ray leaves each face above its own plane, so a light straddling the faces' planes (the
    occluder's terminator) could differ in visibility across a crease. Seen from the side where the
    terminator faces the camera, ``hard_shadow``'s icosphere turning about its vertical axis (its creases
    sweep the terminator), the term of its creases that are not silhouettes (the estimate with them as
    the only film edges less the one with none, the same seed: exactly their term) is within noise:
    the film's sum (Student's t, ALPHA) and the chi-square of the pixels' z where the term is above
    1e-6. Measured at 256 spp: film sum -0.043 ± 0.023 (z -1.9), at 1024 spp -0.002 ± 0.007."""
    d = s3.load_scene("hard_shadow").to_dict()
    d["camera"].update(width=32, height=32, position=[3.0, -0.6, 0.9], look_at=[0.1, 0.0, 0.8], fov=0.25)
    scene = s3.load_scene(d)
    origin = np.array(d["camera"]["position"])

    def creases(state, edges):  # the smooth shape's creases that are not silhouettes
        return edges.crease & np.asarray(state.smooth)[edges.face] & ~edges.silhouette(origin)

    task = ImageTask(scene, "occluder.rotate.y", 256, 1, 16)
    monkeypatch.setattr(camera, "camera_candidates", creases)
    with_creases = GRADIENT_METHODS.run("boundary", task).derivative
    monkeypatch.setattr(camera, "camera_candidates", lambda state, edges: np.zeros(len(edges), bool))
    term = with_creases - GRADIENT_METHODS.run("boundary", task).derivative
    assert np.any(term != 0.0)  # the creases were sampled
    film = term.sum(axis=(1, 2))
    z_film = film.mean() / (film.std(ddof=1) / 4.0)
    mean, se = term.mean(axis=0), term.std(axis=0, ddof=1) / 4.0
    # pixels whose term is not negligible: above 1e-6 (1e-4 of the gradient image's RMS here); below it
    # lie side-ray differences of order EPS_FILM², the same in every batch (z up to hundreds, at 1e-8)
    shown = np.abs(mean) > 1e-6
    chi2 = float(np.sum((mean[shown] / se[shown]) ** 2))
    print(f"film {film.mean():+.4f}, z {z_film:+.2f}; {shown.sum()} pixels, chi2 {chi2:.0f}")
    assert abs(z_film) <= stats.t.ppf(1.0 - 0.5 * sidak(ALPHA, 2), 15)
    # z of 15-dof means: each z² has mean 15/13; the chi-square's quantile scaled by it (conservative)
    assert shown.sum() >= 20 and chi2 <= 15.0 / 13.0 * stats.chi2.ppf(1.0 - sidak(ALPHA, 2), shown.sum())
