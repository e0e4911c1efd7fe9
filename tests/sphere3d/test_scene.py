"""Scenes: built-in meshes, loading (names, JSON, dicts, OBJ/PLY), validation errors, parameters.

Closed forms first (areas and normals of the built-in meshes, the fade profile), then
loading and round trips, then one error per kind of bad input, each naming its field.
"""

from __future__ import annotations

import copy
import json
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from flatland.core.dual import Dual, detach, tangent, variable
from flatland.core.validate import ValidationError
from sphere3d import shapes
from sphere3d.sampling import triangle_area
from sphere3d.scene import list_scenes, load_scene
from sphere3d.state import build_state, euler_matrix
from sphere3d.tables import per_state


def _area(mesh):
    t = mesh.vertices[mesh.faces]
    return triangle_area(t[:, 0], t[:, 1], t[:, 2])


def _outward(mesh):
    t = mesh.vertices[mesh.faces]
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    return np.einsum("ij,ij->i", n, t.mean(axis=1))


def test01_builtin_meshes_have_the_right_area_and_outward_normals():
    assert _area(shapes.rectangle(2.0, 3.0)).sum() == pytest.approx(6.0, rel=1e-14)
    assert _area(shapes.box(1.0, 2.0, 3.0)).sum() == pytest.approx(22.0, rel=1e-14)
    # a regular 64-gon: (n/2) r² sin(2π/n)
    assert _area(shapes.disk(1.5, 64)).sum() == pytest.approx(32 * 1.5**2 * np.sin(2 * np.pi / 64), rel=1e-13)
    ico = shapes.icosphere(2.0, 3)
    assert len(ico.faces) == 20 * 4**3
    np.testing.assert_allclose(np.linalg.norm(ico.vertices, axis=1), 2.0, rtol=1e-14)
    assert _area(ico).sum() == pytest.approx(4 * np.pi * 4.0, rel=2e-2)  # inscribed polyhedron: slightly less
    for mesh in (shapes.box(1.0, 2.0, 3.0), ico):
        assert np.all(_outward(mesh) > 0)
    for mesh in (shapes.rectangle(1.0, 1.0), shapes.disk(1.0, 8)):
        n = np.cross(*(mesh.vertices[mesh.faces][:, k] - mesh.vertices[mesh.faces][:, 0] for k in (1, 2)))
        assert np.all(n[:, 2] > 0)


def test02_fade_is_zero_on_the_border_one_inside_and_smooth():
    u = np.linspace(-1.0, 1.0, 2001)
    uv = np.stack([u, np.zeros_like(u)], axis=-1)
    kind = np.full(u.shape, shapes.FADE_RECTANGLE)
    w = shapes.fade_weight(uv, kind, np.full(u.shape, 0.2))
    assert w[0] == 0.0 and w[-1] == 0.0 and w[1000] == 1.0
    assert np.all(w[(np.abs(u) <= 0.8)] == 1.0)
    assert np.max(np.abs(np.diff(w))) < 0.02  # continuous: no jump anywhere on a 0.001 grid
    radial = shapes.fade_weight(
        np.array([[1.0, 0.0], [0.9, 0.0], [0.0, 0.0]]), np.full(3, shapes.FADE_RADIAL), np.full(3, 0.2)
    )
    np.testing.assert_allclose(radial, [0.0, 0.5, 1.0])  # smoothstep(0.5) = 0.5
    assert np.all(shapes.fade_weight(uv, kind, np.zeros(u.shape)) == 1.0)  # no fade
    dual = shapes.fade_weight(Dual(np.array([[0.9, 0.0]]), np.array([[1.0, 0.0]])), kind[:1], np.array([0.2]))
    # d/du of smoothstep((1 - u) / 0.2) at u = 0.9: -S'(0.5) / 0.2 = -1.5 / 0.2
    assert tangent(dual)[0] == pytest.approx(-7.5)


def test03_builtin_scenes_load_and_round_trip():
    assert list_scenes() == (
        "furnace",
        "glossy_reflection",
        "hard_shadow",
        "hard_shadow_cube",
        "interreflection",
        "shadow",
        "silhouette",
        "sky",
        "soft_shadow",
        "two_occluders",
    )
    for name in list_scenes():
        scene = load_scene(name)
        assert scene.name == name
        again = load_scene(scene.to_dict())
        assert again == scene
        assert json.loads(json.dumps(scene.to_dict())) == scene.to_dict()
        assert load_scene(scene) is scene


def test04_json_files_and_mesh_files_load(tmp_path):
    (tmp_path / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0.5\nf 1 2 3\nf 2 4 3\n")
    ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
    ply += (
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 1\n1 0 1\n0 1 1\n3 0 1 2\n"
    )
    (tmp_path / "tri.ply").write_text(ply)
    d = load_scene("shadow").to_dict()
    d["shapes"] += [
        {"name": "objmesh", "type": "mesh", "path": "tri.obj"},
        {"name": "plymesh", "type": "mesh", "path": "tri.ply", "translate": [0.0, 0.0, 0.5]},
        {
            "name": "inline",
            "type": "mesh",
            "vertices": [[0, 0, 2], [1, 0, 2], [0, 1, 2]],
            "faces": [[0, 1, 2]],
        },
        {"name": "plyraw", "type": "mesh", "path": "tri.ply", "center": False},
    ]
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(d))
    scene = load_scene(str(path))
    assert [len(s.mesh.faces) for s in scene.shapes[-4:]] == [2, 1, 1, 1]
    assert scene.shapes[-4].to_dict()["path"] == str((tmp_path / "tri.obj").resolve())
    assert load_scene(scene.to_dict()) == scene
    state = build_state(scene)
    # a file's mesh is re-centred on its bounding box's centre (0.5, 0.5, 1), then translated
    np.testing.assert_allclose(state.triangles[state.shape_of == 4][0, 0], [-0.5, -0.5, 0.5])
    np.testing.assert_allclose(state.triangles[state.shape_of == 6][0, 0], [0.0, 0.0, 1.0])  # as stored
    np.testing.assert_allclose(
        state.triangles[state.shape_of == 5][0, 0], [0.0, 0.0, 2.0]
    )  # inline: as written


def test05_parameters_move_what_they_name():
    scene = load_scene("shadow")
    assert "occluder.rotate.z" in scene.parameters and "camera.translate.y" in scene.parameters
    base = build_state(scene)
    occ = base.shape_of == scene.shape_index("occluder")
    for param, check in [
        (
            "occluder.translate.y",
            lambda t, v: np.testing.assert_allclose(t, [0.0, 1.0, 0.0] * np.ones_like(v)),
        ),
        (
            "occluder.scale",
            lambda t, v: np.testing.assert_allclose(t, v - [-0.1, 0.0, 0.9]),
        ),  # d/dθ of c + (1+θ) r
    ]:
        s = build_state(scene, param, variable(0.0))
        check(tangent(s.triangles)[occ], detach(s.triangles)[occ])
        assert np.array_equal(detach(s.triangles), base.triangles)  # θ = 0: the scene as loaded
        assert not np.any(tangent(s.triangles)[~occ])
    rot = build_state(scene, "occluder.rotate.z", variable(0.0))
    r = euler_matrix(np.array(scene.shapes[1].rotate))
    local = (detach(rot.triangles)[occ] - [-0.1, 0.0, 0.9]) @ r  # back to object space
    # d/dγ Rz(γ) Ry Rx p = [e_z]× (R p): rotation about the shape's centre
    np.testing.assert_allclose(
        tangent(rot.triangles)[occ], np.cross([0.0, 0.0, 1.0], local @ r.T), atol=1e-12
    )
    cam = build_state(scene, "camera.translate.x", variable(0.0))
    np.testing.assert_allclose(tangent(cam.camera.origin), [1.0, 0.0, 0.0])
    assert tangent(build_state(scene, "light.emission", variable(0.0)).emission)[2] == 1.0
    assert tangent(build_state(scene, "sky.emission", variable(0.0)).sky) == 1.0
    assert tangent(build_state(scene, "floor.albedo", variable(0.0)).albedo)[0] == 1.0
    # an emission parameter makes a dark shape an emitter (its radiance has a derivative)
    assert build_state(scene, "occluder.emission", variable(0.0)).emitters.size == 2 + 12  # light + occluder


BAD = [
    (lambda d: d.pop("camera"), "camera: is required"),
    (lambda d: d.update(colour=1), "colour: unknown key"),
    (lambda d: d["shapes"][1].update(size=[0.5, -1.0, 0.5]), "shapes[1].size[1]: must be > 0, got -1.0"),
    (lambda d: d["shapes"][1].update(type="cone"), "shapes[1].type: must be one of"),
    (lambda d: d["shapes"][1].update(radius=1.0), "shapes[1].radius: unknown key"),
    (lambda d: d["shapes"][1].update(albedo=1.5), "shapes[1].albedo: must lie in [0, 1], got 1.5"),
    (lambda d: d["shapes"][1].update(fade=0.1), "shapes[1].fade: is only defined for rectangle and disk"),
    (lambda d: d["shapes"][2].update(emission=float("nan")), "shapes[2].emission: must be finite, got nan"),
    (lambda d: d["shapes"][2].update(name="floor"), "shapes[2].name: duplicate name 'floor'"),
    (lambda d: d["shapes"][2].update(name="a.b"), "shapes[2].name: must be a non-empty name without '.'"),
    (lambda d: d["camera"].update(fov=4.0), "camera.fov: must be < π"),
    (lambda d: d["camera"].update(width=0), "camera.width: must be an integer >= 1, got 0"),
    (lambda d: d["camera"].update(filter="lanczos"), "camera.filter: must be one of box, tent, gaussian"),
    (lambda d: d["camera"].update(look_at=d["camera"]["position"]), "camera.look_at: must differ"),
    (lambda d: d["camera"].update(up=[0.0, 4.0, -2.55]), "camera.up: must not be parallel"),
    (lambda d: d.update(sky=-1.0), "sky: must be >= 0, got -1.0"),
    (lambda d: d.update(shapes=[]), "shapes: must be a non-empty list"),
    (lambda d: d["shapes"].append({"name": "m", "type": "mesh"}), "shapes[3].path: a mesh needs a path"),
    (
        lambda d: d["shapes"].append(
            {"name": "m", "type": "mesh", "vertices": [[0, 0, 0], [1, 0, 0], [2, 0, 0]], "faces": [[0, 1, 2]]}
        ),
        "shapes[3].faces: triangle 0 is degenerate",
    ),
    (
        lambda d: d["shapes"].append({"name": "m", "type": "mesh", "path": "missing.obj"}),
        "shapes[3].path: no such file",
    ),
    (
        lambda d: d["shapes"].append({"name": "m", "type": "icosphere", "subdivisions": 9}),
        "shapes[3].subdivisions: must be <= 6",
    ),
    (lambda d: d["shapes"][1].update(smooth=1), "shapes[1].smooth: must be True or False, got 1"),
    (
        lambda d: d["shapes"].append(
            {
                "name": "m",
                "type": "mesh",
                "vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
                "faces": [[0, 1, 2]],
                "normals": [[0, 0, 1], [0, 0, 0], [0, 0, 1]],
            }
        ),
        "shapes[3].normals: normal 1 has zero length, got [0.0, 0.0, 0.0]",
    ),
    (
        lambda d: d["shapes"].append(
            {
                "name": "m",
                "type": "mesh",
                "vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
                "faces": [[0, 1, 2]],
                "normals": [[0, 0, 1]],
            }
        ),
        "shapes[3].normals: must be 3 finite [nx, ny, nz] rows (one per vertex), got shape (1, 3)",
    ),
]


@pytest.mark.parametrize("mutate, message", BAD, ids=[m for _, m in BAD])
def test06_bad_scenes_raise_one_error_naming_the_field(mutate, message):
    d = copy.deepcopy(load_scene("shadow").to_dict())
    mutate(d)
    with pytest.raises(ValidationError) as info:
        load_scene(d)
    assert message in str(info.value)


def test07_bad_sources_and_parameters():
    with pytest.raises(ValidationError, match="unknown scene 'nope'; built-in scenes: furnace, glossy_"):
        load_scene("nope")
    with pytest.raises(ValidationError, match=r"scene file 'missing\.json': no such file"):
        load_scene("missing.json")
    with pytest.raises(ValidationError, match=r"param: unknown parameter 'occluder\.spin'; choose from"):
        load_scene("shadow").check_param("occluder.spin")
    with pytest.raises(ValidationError, match="scene: must be a scene name"):
        load_scene(3)


def _smooth_sphere(radius=0.3, centre=(0.1, 0.0, 0.8), rotate=(0.2, -0.1, 0.4)):
    return {
        "name": "ball",
        "camera": {
            "position": [0.6, -3.6, 2.6],
            "look_at": list(centre),
            "fov": 0.5,
            "width": 8,
            "height": 8,
        },
        "shapes": [
            {
                "name": "ball",
                "type": "icosphere",
                "radius": radius,
                "subdivisions": 2,
                "smooth": True,
                "translate": list(centre),
                "rotate": list(rotate),
            }
        ],
    }


def _ball_hits(state, n=400):
    """Rays from the camera at random points of the ball: hit triangles and re-attached intersections."""
    rng = np.random.default_rng(8)
    origin = np.array([0.6, -3.6, 2.6])
    aim = np.array([0.1, 0.0, 0.8]) + rng.uniform(-0.28, 0.28, (n, 3))
    d = aim - origin
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    hits = state.tracer.intersect(origin, d)
    assert hits.hit.mean() > 0.5
    keep = np.flatnonzero(hits.hit)
    return origin, d[keep], hits.triangle[keep]


def test08_smooth_icosphere_normals_approach_the_sphere_and_move_with_it():
    from sphere3d.tracing import intersect_triangles

    scene = load_scene(_smooth_sphere())
    state = build_state(scene)
    origin, d, tri = _ball_hits(state)
    it = intersect_triangles(origin, d, state.triangles[tri])
    n = state.shading_normals(tri, it.b1, it.b2, it.normal)
    exact = (it.point - [0.1, 0.0, 0.8]) / np.linalg.norm(it.point - [0.1, 0.0, 0.8], axis=1, keepdims=True)
    # the vertex normals are exact and the interpolation error is second order in the edge
    # angle (0.32 rad at 2 subdivisions): sin(angle) <= 0.01 here, where the face normal is off
    # by up to half the edge angle (about 0.2 rad)
    smooth_err = np.linalg.norm(np.cross(n, exact), axis=1)
    face_err = np.linalg.norm(np.cross(it.normal, exact), axis=1)
    assert smooth_err.max() < 0.01 and face_err.max() > 0.1
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, rtol=1e-14)
    # a flat shape keeps its face normal, the very same object
    faceted = _smooth_sphere()
    faceted["shapes"][0]["smooth"] = False
    flat = build_state(load_scene(faceted))
    assert flat.shading_normals(tri, it.b1, it.b2, it.normal) is it.normal
    # derivative under translation and rotation: the Dual tangent against a central difference
    # with the same rays and triangles (h = 1e-6: truncation ~1e-12, rounding ~1e-10)
    h = 1e-6
    for param in ("ball.translate.x", "ball.rotate.z", "ball.rotate.x", "ball.scale"):
        dual = build_state(scene, param, variable(0.0))
        it_d = intersect_triangles(origin, d, dual.triangles[tri])
        nd = dual.shading_normals(tri, it_d.b1, it_d.b2, it_d.normal)
        np.testing.assert_array_equal(detach(nd), n)
        fd = []
        for theta in (h, -h):
            s = build_state(scene, param, theta)
            it_s = intersect_triangles(origin, d, s.triangles[tri])
            fd.append(s.shading_normals(tri, it_s.b1, it_s.b2, it_s.normal))
        np.testing.assert_allclose(tangent(nd), (fd[0] - fd[1]) / (2 * h), atol=1e-7)
        assert np.abs(tangent(nd)).max() > 0.1 or param == "ball.scale", param


def test09_mesh_vertex_normals_from_files_inline_and_faces(tmp_path):
    obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0.5\n"
    obj += "vn 0 0.6 0.8\nvn 0 0 2\nvn 0.6 0 0.8\nvn 0 0 1\nf 1//1 2//2 3//3\nf 2//2 4//4 3//3\n"
    (tmp_path / "normals.obj").write_text(obj)
    (tmp_path / "zero.obj").write_text(obj.replace("vn 0 0 1\n", "vn 0 0 0\n"))
    (tmp_path / "plain.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0.5\nf 1 2 3\nf 2 4 3\n")
    base = {"name": "m", "camera": load_scene("shadow").to_dict()["camera"]}
    scene = load_scene(
        base
        | {"shapes": [{"name": "m", "type": "mesh", "path": str(tmp_path / "normals.obj"), "smooth": True}]}
    )
    # the file's normals, normalized (vn 0 0 2 -> 0 0 1), not the ones trimesh would compute
    np.testing.assert_allclose(
        scene.shapes[0].mesh.normals, [[0, 0.6, 0.8], [0, 0, 1], [0.6, 0, 0.8], [0, 0, 1]]
    )
    state = build_state(scene)
    assert state.smooth.all()
    # at barycentrics (1/3, 1/3) of face 0: the normalized mean of its three vertex normals
    n = state.shading_normals(
        np.array([0]), np.array([1 / 3]), np.array([1 / 3]), np.array([[0.0, 0.0, 1.0]])
    )
    mean = np.array([0.6, 0.6, 2.6]) / np.linalg.norm([0.6, 0.6, 2.6])
    np.testing.assert_allclose(n[0], mean, rtol=1e-14)
    with pytest.raises(
        ValidationError, match=r"shapes\[0\]\.path \(vertex normals\): normal 3 has zero length"
    ):
        load_scene(base | {"shapes": [{"name": "m", "type": "mesh", "path": str(tmp_path / "zero.obj")}]})
    # no vn: the angle-weighted face normals; a lone face's vertices get its normal
    plain = load_scene(
        base | {"shapes": [{"name": "m", "type": "mesh", "path": str(tmp_path / "plain.obj")}]}
    )
    assert not build_state(plain).smooth.any()  # smooth is off unless asked for
    face = np.array([-0.5, -0.5, 1.0]) / np.sqrt(1.5)  # (v4 - v2) x (v3 - v2), the only face at v4
    np.testing.assert_allclose(plain.shapes[0].mesh.normals[3], face, rtol=1e-14)
    np.testing.assert_allclose(plain.shapes[0].mesh.normals[0], [0, 0, 1], atol=1e-15)
    # inline normals round-trip through to_dict
    inline = load_scene(
        base
        | {
            "shapes": [
                {
                    "name": "m",
                    "type": "mesh",
                    "vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
                    "faces": [[0, 1, 2]],
                    "normals": [[0, 0, 3], [0, 0.6, 0.8], [0, 0, 1]],
                    "smooth": True,
                }
            ]
        }
    )
    assert load_scene(inline.to_dict()) == inline
    np.testing.assert_allclose(inline.shapes[0].mesh.normals[0], [0, 0, 1])


@pytest.mark.parametrize(("source", "center"), [("file", None), ("file", True), ("inline", True)])
def test10_a_recentred_mesh_turns_and_scales_about_its_centre(tmp_path, source, center):
    """A box far from its file's origin: re-centred, rotate and scale keep its bounding box's centre at
    ``translate`` (the scene docstring's promise); with ``"center": false`` it swings about the file's
    origin instead, as stored. The key round-trips when given."""
    corners = np.array([[x, y, z] for x in (4.0, 6.0) for y in (9.0, 10.0) for z in (-3.0, -2.0)])
    faces = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6]]
    (tmp_path / "box.obj").write_text(
        "".join(f"v {x} {y} {z}\n" for x, y, z in corners)
        + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces)
    )
    mesh = (
        {"path": str(tmp_path / "box.obj")}
        if source == "file"
        else {"vertices": corners.tolist(), "faces": faces}
    )
    base = {"name": "b", "camera": load_scene("shadow").to_dict()["camera"]}

    def centre(**transform):
        shape = {"name": "box", "type": "mesh", **mesh, **transform}
        if center is not None:
            shape["center"] = center
        scene = load_scene(base | {"shapes": [shape]})
        assert load_scene(scene.to_dict()) == scene and ("center" in scene.shapes[0].to_dict()) == (
            center is not None
        )
        v = np.asarray(detach(build_state(scene).triangles)).reshape(-1, 3)
        return 0.5 * (v.min(axis=0) + v.max(axis=0))

    move = [1.0, 2.0, 3.0]
    for transform in (
        {},
        {"rotate": [0.3, -1.1, 2.0]},
        {"scale": 2.5},
        {"rotate": [0.0, 0.0, 1.57], "scale": 0.5},
    ):
        # the box is symmetric about its centre: its bounding box's centre stays where the centre goes
        np.testing.assert_allclose(centre(translate=move, **transform), move, atol=1e-12)
    if source == "file" and center is None:  # kept as stored when asked: it swings about the file's origin
        raw = {"name": "box", "type": "mesh", **mesh, "center": False, "rotate": [0.0, 0.0, np.pi]}
        v = np.asarray(detach(build_state(load_scene(base | {"shapes": [raw]})).triangles)).reshape(-1, 3)
        np.testing.assert_allclose(0.5 * (v.min(axis=0) + v.max(axis=0)), [-5.0, -9.5, -2.5], atol=1e-12)


def test11_a_per_state_table_is_built_once_when_threads_ask_at_once():
    """Four threads ask for one state's table together: one builds it, the others wait and get the same
    object; a build that fails fails for every thread that asked, and none is left waiting."""
    calls = []

    def build(state):
        calls.append(1)
        time.sleep(0.05)
        return np.arange(3)

    table = per_state(build)
    state = build_state(load_scene("hard_shadow"))
    with ThreadPoolExecutor(4) as pool:
        results = list(pool.map(lambda _: table(state), range(4)))
    assert len(calls) == 1 and all(r is results[0] for r in results)

    def broken(state):
        calls.append(1)
        time.sleep(0.05)
        raise RuntimeError("no table")

    failing = per_state(broken)
    calls.clear()
    with ThreadPoolExecutor(4) as pool:
        futures = [pool.submit(failing, state) for _ in range(4)]
        errors = [f.exception(timeout=10) for f in futures]
    assert all(isinstance(e, RuntimeError) for e in errors) and 1 <= len(calls) <= 4
