"""Closed forms and region masks shared by the sphere3d test modules.

From ``test_closed_forms``: the scenes of a black triangle under a sky and of a rectangular
light above the origin, with their irradiance by Lambert's polygon formula (a faded light by
quadrature). From ``test_hard_shadow``: the regions of the ``hard_shadow`` images
(silhouette, occluder, penumbra, umbra, lit; see that module's docstring), decided by closed
forms and a grid of camera rays over every pixel's filter footprint. For
``test_triangle_closed_form``: the loss of ``reparam``'s cosine-strategy rotations given each kernel
(:func:`rotation_loss`). For every test of a statistic over several pixels: its standard error from
the batches (:func:`over_batches`), as the splatted film correlates neighbouring pixels. For the
tests of one strategy of ``reparam``'s irradiance: the other's term set to 0 (:func:`strategy_alone`),
against finite differences of the same (:func:`strategy_z`).
"""

from __future__ import annotations

import itertools

import numpy as np

import sphere3d.integrator as integrator
from flatland.core.dual import Dual, detach, tangent, variable
from flatland.core.image import summarize_batches
from flatland.core.rng import Draws
from sphere3d import closed_form as cf
from sphere3d.film import FilmTransform
from sphere3d.integrator import Identity, Shading
from sphere3d.render import irradiance
from sphere3d.reparam.default import ReparamTransforms
from sphere3d.reparam.film_kernel import KAPPA_FILM
from sphere3d.rotation import Rotation
from sphere3d.sampling import GAUSSIAN_RADIUS, sample_cosine_hemisphere, sample_vmf
from sphere3d.scene import load_scene
from sphere3d.state import build_state, euler_matrix
from sphere3d.tasks import PointTask
from sphere3d.vector import norm

SKY = 1.5
TRIANGLE = np.array([[0.0, -0.5, 1.0], [0.9, 0.0, 1.0], [0.0, 0.5, 1.0]])
ORIGIN, UP = [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]
CAMERA = {"position": [0, -3, 1], "look_at": [0, 0, 0], "fov": 0.8, "width": 8, "height": 8}
REGIONS = ("silhouette", "occluder", "penumbra", "umbra", "lit")
MARGIN = 0.5
"""Pixels of margin around the filter footprint: the grid's spacing (0.25 px) and the
reference's steps (the edges move up to 0.3 px at θ = ±0.01) must not hide an edge."""


def over_batches(per_batch):
    """Mean and standard error of a statistic computed once per batch, shape (batches,).

    A statistic over several pixels (a region's sum, a paired difference of two methods' sums, a
    kept fraction against a fixed reference) cannot take its error from the pixels' standard errors
    as if they were independent: under the splatted film (:mod:`sphere3d.film`) every sample counts
    in each pixel its filter covers, so neighbouring pixels share samples (and ``boundary``'s edge
    points). The batches share none (:class:`sphere3d.tasks.ImageTask`; the control variate's pooled
    scale couples them weakly, a few % of the variance at most: ``ImageTask._control_variate``), so
    the statistic's value per batch is an i.i.d. sample and its mean has the standard error
    std(ddof=1) / sqrt(batches): compare with a Student-t quantile at batches - 1 degrees of freedom.
    """
    s = summarize_batches(per_batch)  # the package's rule, its rounding policy included
    return float(s.mean), float(s.stderr)


def lambert(vertices, normal=(0.0, 0.0, 1.0)):
    """Projected solid angle of a polygon seen from the origin: ½ |Σ γ_i n·u_i| (Dual-aware).

    Written with numpy's own cross product and norm, not the renderer's vector helpers,
    so the closed form shares no code with what it checks.
    """
    a = vertices / np.linalg.norm(vertices, axis=-1)[:, None]
    normal = np.asarray(normal)
    total = 0.0
    for i in range(len(vertices)):  # edges of the polygon
        c = np.cross(a[i], a[(i + 1) % len(vertices)])
        gamma = np.arccos(np.sum(a[i] * a[(i + 1) % len(vertices)]))  # the edge's angle γ_i
        total = total + gamma * np.sum(c * normal) / np.linalg.norm(c)
    return np.abs(0.5 * total)


def triangle_scene():
    shapes = [
        {"name": "tri", "type": "mesh", "vertices": TRIANGLE.tolist(), "faces": [[0, 1, 2]], "albedo": 0.0}
    ]
    return {"name": "triangle", "camera": CAMERA, "sky": SKY, "shapes": shapes}


def triangle_exact(axis):
    return SKY * (np.pi - lambert(TRIANGLE + np.eye(3)[axis] * variable(0.0)))


def light_scene(fade):
    light = {
        "name": "light", "type": "rectangle", "size": [0.6, 0.4], "translate": [0.5, 0.2, 1.5],
        "rotate": [np.pi, 0.0, 0.0], "emission": 5.0, "albedo": 0.0, "fade": fade,
    }  # fmt: skip
    return {"name": "lit", "camera": CAMERA, "sky": 0.0, "shapes": [light]}


def light_exact(fade, nodes=48):
    """E for the rectangle light of :func:`light_scene` moving by θ in x, as a Dual."""
    theta = variable(0.0)
    if fade == 0.0:
        c = np.array([0.5, 0.2, 1.5]) + np.array([1.0, 0.0, 0.0]) * theta
        half = np.array([[-0.3, -0.2, 0.0], [0.3, -0.2, 0.0], [0.3, 0.2, 0.0], [-0.3, 0.2, 0.0]])
        corners = c + half
        return 5.0 * lambert(corners)
    # Gauss–Legendre on the pieces where the fade is smooth: E = ∫ L fade z² / d⁴ dA
    g, w = np.polynomial.legendre.leggauss(nodes)
    breaks = [-1.0, -1.0 + fade, 1.0 - fade, 1.0]
    u = np.concatenate([0.5 * (a + b) + 0.5 * (b - a) * g for a, b in itertools.pairwise(breaks)])
    wu = np.concatenate([0.5 * (b - a) * w for a, b in itertools.pairwise(breaks)])
    uu, vv = np.meshgrid(u, u, indexing="ij")

    def smooth(t):
        t = np.clip(t, 0.0, 1.0)
        return t * t * (3 - 2 * t)

    weight = smooth((1 - np.abs(uu)) / fade) * smooth((1 - np.abs(vv)) / fade)
    px, py, pz = 0.5 + theta + 0.3 * uu, 0.2 + 0.2 * vv, 1.5
    d2 = px * px + py * py + pz * pz
    return np.sum(5.0 * weight * pz * pz / (d2 * d2) * np.outer(wu, wu)) * 0.3 * 0.2


def blocked(scene, x, y, grow):
    """True where the segment x -> y meets the occluder grown by ``grow`` (closed forms)."""
    s = scene.shapes[scene.shape_index("occluder")]
    c = np.array(s.translate)
    d = y - x
    if s.type == "icosphere":
        # distance from the centre to the segment: clamp the projection parameter to [0, 1]
        t = np.clip(np.einsum("...i,...i", c - x, d) / np.einsum("...i,...i", d, d), 0.0, 1.0)
        return np.linalg.norm(x + t[..., None] * d - c, axis=-1) < dict(s.geometry)["radius"] + grow
    rotation = euler_matrix(np.array(s.rotate))
    half = np.array(dict(s.geometry)["size"]) / 2.0 + grow
    o, dl = (x - c) @ rotation, d @ rotation  # the box's frame: R^T (x - c)
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (-half - o) / dl, (half - o) / dl
    # slabs: the segment meets the box iff the intervals of the three axes overlap within [0, 1]
    near = np.nanmax(np.minimum(t1, t2), axis=-1)
    far = np.nanmin(np.maximum(t1, t2), axis=-1)
    return (near <= far) & (far >= 0.0) & (near <= 1.0)


def footprint_rays(state):
    """A 0.25 px grid over every pixel's filter footprint widened by MARGIN: the grid's offsets
    (ox, oy) from the pixel centre, and the camera directions (pixels, points, 3) through them."""
    cam = state.camera
    reach = GAUSSIAN_RADIUS + MARGIN
    g = np.arange(-reach, reach + 1e-9, 0.25)
    gx, gy = np.meshgrid(g, g)
    inside = gx**2 + gy**2 <= reach**2 + 1e-12
    rows, cols = np.divmod(np.arange(cam.height * cam.width), cam.width)
    d = cam.directions(cols[:, None] + 0.5 + gx[inside], rows[:, None] + 0.5 + gy[inside])
    return gx[inside], gy[inside], d


def regions(name):
    """Boolean masks (height, width) of the regions of ``test_hard_shadow``'s module docstring."""
    scene = load_scene(name)
    state = build_state(scene)
    cam = state.camera
    ox, oy, d = footprint_rays(state)
    origin = np.array(scene.camera.position)
    hit = state.tracer.intersect(origin, d).shape
    on_occ, on_ground = hit == scene.shape_index("occluder"), hit == scene.shape_index("ground")
    # shadows on the ground: every other footprint point (a 0.5 px grid), on the plane z = 0
    coarse = (np.abs(ox * 4) % 2 == 0) & (np.abs(oy * 4) % 2 == 0)
    x = origin + (-origin[2] / d[:, coarse, 2])[..., None] * d[:, coarse]
    ground = on_ground[:, coarse]
    light = scene.shapes[scene.shape_index("light")]
    u = np.linspace(-0.5, 0.5, 6)
    grid = np.array(light.translate) + np.stack([*np.meshgrid(u, u), np.zeros((6, 6))], -1).reshape(-1, 3)
    corners = np.array(light.translate) + np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]) / 2
    occ = scene.shapes[scene.shape_index("occluder")]
    # margins: the icosphere's faces lie up to 0.0054 inside its sphere; the reference moves it by 0.01
    facets = 0.006 if occ.type == "icosphere" else 0.0
    near = ground.any(1)  # pixels that see some ground: the only ones tested against the light
    hidden = np.zeros(ground.shape, dtype=bool)
    visible = np.ones(ground.shape, dtype=bool)
    hidden[near] = np.all([blocked(scene, x[near], y, -facets - 0.011) for y in corners], axis=0)
    visible[near] = ~np.any([blocked(scene, x[near], y, 0.011) for y in grid], axis=0)
    out = {
        "silhouette": on_occ.any(1) & ~on_occ.all(1),
        "occluder": on_occ.all(1),
        "umbra": on_ground.all(1) & hidden.all(1),
        "lit": ~on_occ.any(1) & np.where(ground, visible, True).all(1),
    }
    out["penumbra"] = ~(out["silhouette"] | out["occluder"] | out["umbra"] | out["lit"])
    return {k: out[k].reshape(cam.height, cam.width) for k in REGIONS}


def rotation_loss(vertices, param, n, seed, **options):
    r"""Share of dE/dθ that ``reparam``'s cosine-strategy rotations lose at the origin (normal +z) under a
    sky with the black triangle ``vertices``, without the noise of the samples μ: (mean, stderr).

    Per kernel centre ω (drawn as ``reparam`` draws it, keyed on the sample), the derivative expected
    over μ given ω and the rotation chosen is, by the divergence theorem on $∫ f(Rμ) k(Rμ, ω) dμ$
    (visibility fixed), $-q^{-1} ∫_{∂T} f k\, (Ω × μ)·n\, dl$, Ω the rotation's angular velocity, n the
    edges' outward normal; the exact one has the edges' own velocity $\dot μ$ in place of Ω × μ.
    q(ω) = A(κ) cos ω / π is ω's density ($A = \coth κ - 1/κ$, the mean cosine of the vMF; the
    triangle is far above the horizon). Gauss–Legendre nodes along each edge within 8 σ of ω's foot.
    """
    options = {"kappa": 1000.0, "probes": 7, "spread": 3.0, "refine": 3, **options}  # reparam's defaults
    kappa = options["kappa"]
    scene = load_scene(cf.sky_triangle_scene(vertices))
    state = build_state(scene, param, variable(0.0))
    v, vd = np.asarray(detach(state.triangles))[0], np.asarray(tangent(state.triangles))[0]
    _, exact = cf.occluded_sky_irradiance(scene, ORIGIN, UP, param)
    draws = Draws.of(seed, np.arange(n))
    up = np.tile(UP, (n, 1))
    mu = sample_cosine_hemisphere(draws.uniforms("samples", 5)[:, 3:5], up)
    omega = sample_vmf(draws.uniforms("kernel.bsdf", 2), mu, kappa)
    transforms = ReparamTransforms(kappa_film=KAPPA_FILM, paired=False, **options)
    shading = Shading.at(state, Dual(np.zeros((n, 3))), Dual(up), draws)
    rotation = transforms._probe_rotation(shading, omega)[0]
    a, a_dot = np.asarray(detach(rotation.target)), np.asarray(tangent(rotation.target))
    spin = 0.0 if rotation.spin is None else np.asarray(tangent(rotation.spin))[:, None] * a
    velocity = np.where(rotation.active[:, None], np.cross(a, a_dot) + spin, 0.0)  # Ω
    sigma = 1.0 / np.sqrt(kappa)
    g, w = np.polynomial.legendre.leggauss(48)
    bias = np.zeros(n)
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        e1 = v[i] / np.linalg.norm(v[i])
        m = np.cross(v[i], v[j])
        m /= np.linalg.norm(m)
        e2 = np.cross(m, e1)
        out = -np.sign(m @ v[k]) * m  # the outward normal of the edge's arc
        foot = np.arctan2(omega @ e2, omega @ e1)
        lo, hi = (np.clip(foot + s * 8.0 * sigma, 0.0, np.arctan2(v[j] @ e2, v[j] @ e1)) for s in (-1, 1))
        phi = 0.5 * (lo + hi)[:, None] + 0.5 * (hi - lo)[:, None] * g
        d = np.cos(phi)[..., None] * e1 + np.sin(phi)[..., None] * e2
        # d = α V_i + β V_j: the edge's point y = d / (α + β) at t = β / (α + β), velocity V̇_i + t (V̇_j - V̇_i)
        basis = np.array([[v[i] @ e1, v[j] @ e1], [v[i] @ e2, v[j] @ e2]])
        ab = np.stack([np.cos(phi), np.sin(phi)], axis=-1) @ np.linalg.inv(basis).T
        s = ab.sum(axis=-1)
        y_dot = vd[i] + (ab[..., 1] / s)[..., None] * (vd[j] - vd[i])
        normal_speed = (y_dot @ out) * s  # (ẏ·n) / |y|, |y| = 1 / s
        k_f = (
            kappa
            / (2 * np.pi * -np.expm1(-2 * kappa))
            * np.exp(kappa * (np.einsum("nqx,nx->nq", d, omega) - 1))
        )
        k_f *= d[..., 2]  # the cosine
        rotated = np.cross(velocity[:, None], d) @ out
        bias -= np.sum(k_f * (rotated - normal_speed) * w, axis=1) * 0.5 * (hi - lo)
    q = (1.0 / np.tanh(kappa) - 1.0 / kappa) * omega[:, 2] / np.pi
    share = -(bias / q) / exact
    return float(share.mean()), float(share.std(ddof=1) / np.sqrt(n))


class FollowPlane(Identity):
    """One rotation per camera sample following the point of the plane z = 0 under its film point.

    The point moves with the triangle (``tri.translate.x``: velocity (1, 0, 0)), so the
    rotation ``R(detach ω_p → ω_p)`` (Loubet et al. 2019, Sec. 4.1) carries its film motion.
    """

    def camera(self, state, x, y, draws):
        cam = state.camera
        o = np.asarray(detach(cam.origin))
        d = np.asarray(detach(cam.directions(x, y)))
        p = o + (-o[2] / d[:, 2])[:, None] * d  # on the plane z = 0 of the triangle
        moving = Dual(p, np.broadcast_to([1.0, 0.0, 0.0], p.shape)) - o
        return FilmTransform((Rotation.following(moving / norm(moving)[:, None]),))


def strategy_alone(monkeypatch, keep: str) -> None:
    """Only the ``keep`` strategy's estimate ("emitter" or "bsdf"): the other's term set to 0."""

    def zero(shading, *args, **kwargs):
        m = len(shading)
        return Dual(np.zeros(m), None, shading.state.k) if shading.state.dual else np.zeros(m)

    monkeypatch.setattr(integrator, "_bsdf_term" if keep == "emitter" else "_emitter_term", zero)


def cosine_only(monkeypatch) -> None:
    """The cosine strategy alone and unweighted: the emitter strategy's term 0 and the light's density 0 in
    the balance heuristic, so the cosine-sampled estimate is one of the whole E (its closed form's)."""
    strategy_alone(monkeypatch, "bsdf")
    monkeypatch.setattr(integrator, "solid_angle_pdf", lambda inv_area, t, cos_y: 0.0 * cos_y)


def strategy_z(scene, param, **switches):
    """reparam's derivative (:class:`~sphere3d.reparam.default.ReparamTransforms` with ``switches``) against
    finite differences (16x the samples), both of the patched estimator: their difference over its
    standard error."""
    task = PointTask(load_scene(scene), param, ORIGIN, UP, 1 << 16, 3, 16)
    r = summarize_batches(np.asarray(task.evaluate(variable(0.0), ReparamTransforms(**switches)).derivative))
    f = irradiance(scene, ORIGIN, UP, param=param, method="finite_difference", n=1 << 20, seed=3, batches=16)
    return (r.mean - f.derivative) / np.hypot(r.stderr, f.derivative_stderr)
