"""Scenes: built-in meshes, loading (names, JSON, dicts, OBJ/PLY), validation errors, parameters.

Closed forms first (areas and normals of the built-in meshes, the fade profile), then
loading and round trips, then one error per kind of bad input, each naming its field.
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from flatland.core.dual import Dual, detach, tangent, variable
from flatland.core.validate import ValidationError
from sphere3d import shapes
from sphere3d.sampling import triangle_area
from sphere3d.scene import list_scenes, load_scene
from sphere3d.state import euler_matrix


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
    assert list_scenes() == ("shadow", "silhouette", "sky", "two_occluders")
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
    ]
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(d))
    scene = load_scene(str(path))
    assert [len(s.mesh.faces) for s in scene.shapes[-3:]] == [2, 1, 1]
    assert scene.shapes[-3].to_dict()["path"] == str((tmp_path / "tri.obj").resolve())
    assert load_scene(scene.to_dict()) == scene
    state = scene.state()
    np.testing.assert_allclose(state.triangles[state.shape_of == 4][0, 0], [0.0, 0.0, 1.5])


def test05_parameters_move_what_they_name():
    scene = load_scene("shadow")
    assert "occluder.rotate.z" in scene.parameters and "camera.translate.y" in scene.parameters
    base = scene.state()
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
        s = scene.state(param, variable(0.0))
        check(tangent(s.triangles)[occ], detach(s.triangles)[occ])
        assert np.array_equal(detach(s.triangles), base.triangles)  # θ = 0: the scene as loaded
        assert not np.any(tangent(s.triangles)[~occ])
    rot = scene.state("occluder.rotate.z", variable(0.0))
    r = euler_matrix(np.array(scene.shapes[1].rotate))
    local = (detach(rot.triangles)[occ] - [-0.1, 0.0, 0.9]) @ r  # back to object space
    # d/dγ Rz(γ) Ry Rx p = [e_z]× (R p): rotation about the shape's centre
    np.testing.assert_allclose(
        tangent(rot.triangles)[occ], np.cross([0.0, 0.0, 1.0], local @ r.T), atol=1e-12
    )
    cam = scene.state("camera.translate.x", variable(0.0))
    np.testing.assert_allclose(tangent(cam.camera.origin), [1.0, 0.0, 0.0])
    assert tangent(scene.state("light.emission", variable(0.0)).emission)[2] == 1.0
    assert tangent(scene.state("sky.emission", variable(0.0)).sky) == 1.0
    assert tangent(scene.state("floor.albedo", variable(0.0)).albedo)[0] == 1.0
    # an emission parameter makes a dark shape an emitter (its radiance has a derivative)
    assert scene.state("occluder.emission", variable(0.0)).emitters.size == 2 + 12  # light + occluder


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
]


@pytest.mark.parametrize("mutate, message", BAD, ids=[m for _, m in BAD])
def test06_bad_scenes_raise_one_error_naming_the_field(mutate, message):
    d = copy.deepcopy(load_scene("shadow").to_dict())
    mutate(d)
    with pytest.raises(ValidationError) as info:
        load_scene(d)
    assert message in str(info.value)


def test07_bad_sources_and_parameters():
    with pytest.raises(ValidationError, match="unknown scene 'nope'; built-in scenes: shadow"):
        load_scene("nope")
    with pytest.raises(ValidationError, match=r"scene file 'missing\.json': no such file"):
        load_scene("missing.json")
    with pytest.raises(ValidationError, match=r"param: unknown parameter 'occluder\.spin'; choose from"):
        load_scene("shadow").check_param("occluder.spin")
    with pytest.raises(ValidationError, match="scene: must be a scene name"):
        load_scene(3)
