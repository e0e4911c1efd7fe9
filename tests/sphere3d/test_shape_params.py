"""A mesh's shape coefficients ``NAME.shape.K`` and a scene's ``offsets`` in sphere3d: the deformation,
the carried normals, and the derivative by every method.

1. The names: an icosphere and a mesh have shape.0 to shape.15, listed by ``parameter_names``; a box,
   a rectangle and a coefficient past the last are refused, as are bad offsets.
2. The harmonics are the documented ones: orthonormal to rounding in the mean over the sphere (a
   product Gauss rule exact for degree <= 7, the products being of degree <= 6), $Y_0 = 1$, and the
   spatial gradient of $Y_K(x/|x|)$ equals its central difference (truncation $O(h^2)$, bound 1e-6).
3. The deformation is the documented one: each vertex stays on its ray from the centre, at distance
   $|v| (1 + Σ_K θ_K Y_K(\\hat v))$ (to rounding); the carried normal is orthogonal to the deformed
   surface's tangents (central differences of F across the vertex, bound 1e-5 at h = 1e-4).
4. Bit for bit: coefficients at 0 (a Dual at 0) leave the triangles and normals unchanged; a scene with
   zero offsets renders the image of the scene without; an offset a and a θ = b of the same
   parameter give the state of the offset a + b, for a translation, a rotation, a scale and a
   shape coefficient (one slot); the gradient render of a list takes the scene's offset in its slot.
5. At the undeformed mesh shape.0 is a uniform scale about the centre ($Y_0 = 1$), so its derivative
   equals the scale's under the Dual methods (naive, boundary, reparam: the vertex tangents are the
   same numbers), to 1e-12 of the largest. (On a deformed mesh they differ: shape.0 adds θ v, the
   scale θ F(v).)
6. Against finite differences on a black icosphere before a constant sky (its derivative image is its
   silhouette's motion alone), at an offset shape: boundary's and reparam's film sums and first
   moments in x and y agree with central differences' (h = 0.01) within t standard errors, the
   standard errors from 8 independent runs of each (a pixel's batch standard error misjudges the
   rare samples that cross an edge), t the Student quantile (7 degrees of freedom) at two-sided
   sidak(1e-3, 6). Central differences
   of a faceted mesh's coverage cross kinks (the silhouette's edges change as faces turn), so their
   truncation error is not small at every coefficient: on this scene shape.10's film sum is -19.14
   (boundary, se 0.01) against -18.0 (se 0.6), -13.4 (1.2) and -8.4 (0.4) at h = 0.005, 0.01, 0.02;
   the test takes two coefficients whose differences at h = 0.01 have no such bias.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

pytest.importorskip("embreex")

import sphere3d as s3
from flatland.core.dual import variable, variables
from flatland.core.stats import sidak
from flatland.core.validate import ValidationError
from sphere3d.harmonics import TERMS, deform, harmonic, harmonic_gradient
from sphere3d.scene import load_scene, parameter_names
from sphere3d.state import build_state, moved_scene

N = 16


def blob(size: int = N, **offsets: float) -> s3.scene.Scene:
    """A black icosphere (radius 0.5) before a sky of radiance 1, seen from 3 units."""
    return load_scene(
        {
            "name": "blob",
            "sky": 1.0,
            "camera": {
                "position": [0.3, -3, 0.6],
                "look_at": [0, 0, 0],
                "fov": 0.45,
                "width": size,
                "height": size,
            },
            "shapes": [
                {"name": "blob", "type": "icosphere", "radius": 0.5, "subdivisions": 2, "albedo": 0.0}
            ],
            "offsets": {k.replace("_", "."): v for k, v in offsets.items()},
        }
    )


def test01_meshes_have_sixteen_coefficients_and_bad_names_and_offsets_are_refused():
    scene = load_scene("hard_shadow_cube")
    names = parameter_names(load_scene("hard_shadow"))
    assert [n for n in names if ".shape." in n] == [
        f"occluder.shape.{k}" for k in range(TERMS)
    ] and TERMS == 16
    assert not any(".shape." in n for n in parameter_names(scene))  # a box, rectangles: none
    for bad in ("occluder.shape.0", "ground.shape.1"):
        with pytest.raises(ValidationError, match=r"^param: unknown parameter"):
            s3.render_gradient(scene, bad, spp=1)
    with pytest.raises(ValidationError, match=r"^param: unknown parameter 'occluder\.shape\.16'"):
        s3.render_gradient("hard_shadow", "occluder.shape.16", spp=1)
    cases = {
        "nope.scale": "unknown parameter",
        "occluder.albedo": "leaves the albedo",
        "occluder.scale": "scale factor",
    }
    for name, message in cases.items():
        d = load_scene("hard_shadow").to_dict()
        d["offsets"] = {name: -1.0 if name != "occluder.albedo" else 0.7}
        with pytest.raises(ValidationError, match=f"^offsets: .*{message}"):
            load_scene(d)
    d["offsets"] = {"occluder.translate.x": float("nan")}
    with pytest.raises(ValidationError, match=r"^offsets\['occluder.translate.x'\]"):
        load_scene(d)


def test02_harmonics_are_orthonormal_with_y0_one_and_their_gradient_is_exact():
    nodes, weights = np.polynomial.legendre.leggauss(8)  # exact for degree <= 15 in cos(polar)
    phi = 2.0 * np.pi * np.arange(16) / 16  # exact for trigonometric degree <= 15
    c, p = np.meshgrid(nodes, phi, indexing="ij")
    s = np.sqrt(1.0 - c**2)
    u = np.stack([s * np.cos(p), s * np.sin(p), c], axis=-1).reshape(-1, 3)
    w = (np.repeat(weights, 16) / 2.0 / 16).ravel()  # mean over the sphere
    y = np.stack([harmonic(k, u) for k in range(TERMS)])
    np.testing.assert_allclose((y * w) @ y.T, np.eye(TERMS), atol=1e-13)
    assert np.all(y[0] == 1.0)
    rng = np.random.default_rng(1)
    x, h = rng.normal(size=(20, 3)), 1e-5
    for k in range(TERMS):
        numeric = np.stack(
            [(harmonic(k, _unit(x + h * e)) - harmonic(k, _unit(x - h * e))) / (2 * h) for e in np.eye(3)],
            axis=1,
        )
        np.testing.assert_allclose(harmonic_gradient(k, x), numeric, atol=1e-6)


def _unit(x):
    return x / np.linalg.norm(x, axis=1)[:, None]


def test03_vertices_stay_on_their_rays_and_carried_normals_are_orthogonal_to_the_surface():
    scene = load_scene("hard_shadow")
    mesh = scene.shapes[2].mesh
    coefficients = {1: 0.1, 4: -0.2, 6: 0.15, 12: 0.05}
    moved, normals = deform(mesh.vertices, mesh.normals, coefficients)
    u = _unit(mesh.vertices)
    g = sum(t * harmonic(k, u) for k, t in coefficients.items())
    np.testing.assert_allclose(_unit(moved), u, atol=1e-14)
    np.testing.assert_allclose(
        np.linalg.norm(moved, axis=1), np.linalg.norm(mesh.vertices, axis=1) * (1 + g), rtol=1e-14
    )
    h = 1e-4
    rng = np.random.default_rng(2)
    for _ in range(2):
        e = rng.normal(size=u.shape)  # a random direction in each vertex's tangent plane
        e = _unit(e - u * np.sum(e * u, axis=1)[:, None])
        ahead, _ = deform(mesh.vertices + h * e, mesh.normals, coefficients)
        behind, _ = deform(mesh.vertices - h * e, mesh.normals, coefficients)
        along = (ahead - behind) / (2 * h)
        cosine = (
            np.sum(along * normals, axis=1) / np.linalg.norm(along, axis=1) / np.linalg.norm(normals, axis=1)
        )
        assert np.max(np.abs(cosine)) < 1e-5


def test04_zero_coefficients_and_offsets_change_nothing_and_offsets_share_the_slot():
    scene = load_scene("hard_shadow")
    plain = build_state(scene)
    for k in (0, 5, 15):
        dual = build_state(scene, f"occluder.shape.{k}", variable(0.0))
        assert np.array_equal(dual.triangles.value, plain.triangles)
        assert np.array_equal(dual.normals.value, plain.normals)
    d = scene.to_dict()
    d["camera"].update(width=8, height=8)
    d["offsets"] = {"occluder.translate.x": 0.0, "occluder.shape.3": 0.0}
    small = load_scene(d)
    del d["offsets"]
    assert np.array_equal(s3.render(small, spp=2, seed=4).value, s3.render(d, spp=2, seed=4).value)
    for name, a, b in (
        ("occluder.translate.x", 0.1, 0.05),
        ("occluder.rotate.y", 0.3, -0.1),
        ("occluder.scale", 0.2, 0.1),
        ("occluder.shape.7", 0.1, 0.05),
    ):
        offset = build_state(moved_scene(scene, name, a), name, b)
        summed = build_state(moved_scene(scene, name, a + b))
        assert np.array_equal(offset.triangles, summed.triangles), name
        assert np.array_equal(offset.normals, summed.normals), name
        at = build_state(moved_scene(scene, name, a), [name, "occluder.albedo"], variables(2))
        assert np.array_equal(at.triangles.value, build_state(moved_scene(scene, name, a)).triangles), name
    moved = moved_scene(
        moved_scene(scene, "occluder.shape.2", 0.1), ["occluder.shape.2", "occluder.albedo"], [0.05, 0.1]
    )
    assert dict(moved.offsets) == {"occluder.shape.2": 0.1 + 0.05, "occluder.albedo": 0.1}
    assert load_scene(moved.to_dict()) == moved


@pytest.mark.parametrize("method", ["naive", "boundary", "reparam"])
def test05_shape_zero_is_the_scale(method):
    both = s3.render_gradient(blob(12), ["blob.shape.0", "blob.scale"], method=method, spp=4, seed=2)
    shape, scale = both.derivative
    assert np.max(np.abs(scale)) > 0.1 or method == "naive"  # naive: no silhouette term, 0 for both
    np.testing.assert_allclose(shape, scale, rtol=0, atol=1e-12 * np.max(np.abs(scale)))


def _moments(scene, params, seeds, **kwargs):
    """Per seed, per parameter: the derivative image's film sum and its first moments in x and y
    (weights 1, (column - c) / N, (row - c) / N): shape (seeds, k, 3)."""
    centred = (np.arange(N) + 0.5 - N / 2) / N
    weights = np.stack([np.ones((N, N)), np.tile(centred, (N, 1)), np.tile(centred[:, None], (1, N))])
    return np.array(
        [
            np.einsum(
                "kij,wij->kw", s3.render_gradient(scene, params, seed=seed, **kwargs).derivative, weights
            )
            for seed in seeds
        ]
    )


@pytest.mark.parametrize("method", ["boundary", "reparam"])
def test06_boundary_and_reparam_agree_with_finite_differences(method):
    scene = blob(N, blob_shape_6=0.1, blob_shape_3=-0.05)
    params = ["blob.shape.4", "blob.shape.6"]
    runs = 8
    fd = _moments(scene, params, range(runs), method="finite_difference", spp=256, h=0.01)
    g = _moments(scene, params, range(100, 100 + runs), method=method, spp=64)
    assert np.all(np.abs(fd[:, :, 0].mean(axis=0)) > 40.0)  # the silhouette moves
    se = np.hypot(fd.std(axis=0, ddof=1), g.std(axis=0, ddof=1)) / math.sqrt(runs)
    t = stats.t.ppf(1.0 - sidak(1e-3, se.size) / 2.0, runs - 1)
    assert np.all(np.abs(g.mean(axis=0) - fd.mean(axis=0)) <= t * se)
