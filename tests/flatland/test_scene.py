"""Flatland scenes: loading, round trips, validation errors, and what each parameter moves."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from flatland.core.dual import Dual, detach, tangent, variable
from flatland.core.validate import ValidationError
from flatland.scene import Scene, list_scenes, load_scene
from flatland.state import build_state, parse_parameter

BUILTINS = (
    "furnace",
    "glossy_reflection",
    "interreflection",
    "penumbra",
    "polygon",
    "shadow",
    "silhouette",
    "two_occluders",
)


def _base() -> dict:
    return {
        "name": "t",
        "camera": {
            "position": [0.0, 0.0],
            "direction": [0.0, 2.0],
            "fov": 1.0,
            "pixels": 8,
            "filter": "tent",
        },
        "sky": 0.5,
        "shapes": [
            {
                "name": "seg",
                "type": "segment",
                "points": [[-1.0, 1.0], [1.0, 1.0]],
                "emission": 2.0,
                "fade": 0.2,
            },
            {
                "name": "poly",
                "type": "polygon",
                "points": [[0.0, 2.0], [1.0, 2.0], [1.0, 3.0]],
                "albedo": 0.5,
            },
            {"name": "line", "type": "polyline", "points": [[-2.0, 0.0], [-2.0, 1.0], [-1.5, 1.5]]},
            {"name": "ball", "type": "circle", "center": [2.0, 2.0], "radius": 0.5, "albedo": 0.3},
        ],
        "parameters": ["seg.translate.x", "ball.scale"],
    }


def test01_builtin_scenes_are_listed_load_and_round_trip(tmp_path):
    assert set(BUILTINS) <= set(list_scenes())
    for name in BUILTINS:
        scene = load_scene(name)
        assert isinstance(scene, Scene) and scene.name == name and scene.parameters
        again = load_scene(scene.to_dict())
        assert again == scene
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps(scene.to_dict()))
        assert load_scene(path) == scene and load_scene(str(path)) == scene
        assert load_scene(scene) is scene


def test02_defaults_are_filled_and_direction_normalized():
    scene = load_scene(_base())
    assert scene.camera.direction == (0.0, 1.0)
    seg, poly, line, ball = scene.shapes
    assert (seg.albedo, seg.one_sided, seg.fade) == (0.0, False, 0.2)
    assert (poly.emission, poly.fade) == (0.0, 0.0)
    assert len(poly.segments()) == 3 and len(line.segments()) == 2
    assert ball.center == (2.0, 2.0) and ball.radius == 0.5
    assert scene.with_camera(pixels=3).camera.pixels == 3
    assert scene.camera.pixel_centers().size == 8
    assert math.isclose(scene.camera.pixel_width * 8, 2.0 * math.tan(0.5))


def _bad(path: list, value: object) -> dict:
    d = _base()
    target = d
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    return d


@pytest.mark.parametrize(
    ("data", "field", "fragment"),
    [
        (_bad(["colour"], "red"), "colour", "'red'"),
        (_bad(["shapes", 0, "type"], "blob"), "shapes[0].type", "'blob'"),
        (_bad(["shapes", 1, "points", 1, 0], float("nan")), "shapes[1].points[1][0]", "nan"),
        (_bad(["shapes", 3, "radius"], -1.0), "shapes[3].radius", "-1.0"),
        (_bad(["shapes", 1, "albedo"], -0.2), "shapes[1].albedo", "-0.2"),
        (_bad(["shapes", 1, "albedo"], 1.5), "shapes[1].albedo", "1.5"),
        (_bad(["shapes", 0, "emission"], -3.0), "shapes[0].emission", "-3.0"),
        (_bad(["shapes", 0, "points"], [[1.0, 1.0], [1.0, 1.0]]), "shapes[0].points[1]", "[1.0, 1.0]"),
        (
            _bad(["shapes", 1, "points"], [[0.0, 0.0], [1.0, 0.0], [0.0, 0.0]]),
            "shapes[1].points[0]",
            "[0.0, 0.0]",
        ),
        (_bad(["camera", "fov"], math.pi), "camera.fov", "3.14159"),
        (_bad(["camera", "fov"], 0.0), "camera.fov", "0.0"),
        (_bad(["camera", "filter"], "lanczos"), "camera.filter", "'lanczos'"),
        (_bad(["camera", "pixels"], 0), "camera.pixels", "0"),
        (_bad(["camera", "direction"], [0.0, 0.0]), "camera.direction", "[0.0, 0.0]"),
        (_bad(["parameters"], ["seg.spin"]), "parameters[0]", "'seg.spin'"),
        (_bad(["shapes", 2, "name"], "seg"), "shapes[2].name", "'seg'"),
        (_bad(["shapes", 1, "fade"], 0.1), "shapes[1].fade", "0.1"),
        (_bad(["shapes", 0, "fade"], 0.7), "shapes[0].fade", "0.7"),
        (_bad(["sky"], -1.0), "sky", "-1.0"),
        (_bad(["shapes"], []), "shapes", "[]"),
    ],
)
def test03_bad_fields_raise_one_error_naming_path_and_value(data, field, fragment):
    with pytest.raises(ValidationError) as info:
        load_scene(data)
    assert info.value.field == field
    assert str(info.value).startswith(f"{field}: ") and fragment in str(info.value)


def test04_bad_sources_raise_one_error(tmp_path):
    with pytest.raises(ValidationError, match="unknown scene 'nowhere'"):
        load_scene("nowhere")
    with pytest.raises(ValidationError, match=r"scene file .*missing\.json': no such file"):
        load_scene(tmp_path / "missing.json")
    broken = tmp_path / "broken.json"
    broken.write_text("{")
    with pytest.raises(ValidationError, match=r"broken\.json': invalid JSON"):
        load_scene(broken)


@pytest.mark.parametrize(
    "name",
    [
        "ball.rotate",
        "ball.vertex.0.x",
        "poly.vertex.3.x",
        "poly.translate.z",
        "camera.scale",
        "nobody.scale",
        3,
    ],
)
def test05_unknown_parameters_are_rejected(name):
    with pytest.raises(ValidationError) as info:
        parse_parameter(load_scene(_base()), name)
    assert info.value.field == "param" and repr(name) in str(info.value)


def _moved(scene: Scene, param: str, theta: float):
    g = build_state(scene, param, theta)
    return {
        k: np.asarray(detach(getattr(g, k)))
        for k in ("seg_a", "seg_b", "circ_c", "circ_r", "emission", "albedo", "cam_o", "cam_f")
    }


def test06_each_parameter_kind_moves_what_it_names():
    scene = load_scene(_base())
    base = _moved(scene, None, 0.0)
    t = 0.25
    m = _moved(scene, "seg.translate.x", t)
    assert np.allclose(m["seg_a"][0] - base["seg_a"][0], [t, 0.0]) and np.allclose(
        m["seg_a"][1:], base["seg_a"][1:]
    )
    m = _moved(scene, "ball.translate.y", t)
    assert np.allclose(m["circ_c"] - base["circ_c"], [[0.0, t]])
    m = _moved(scene, "ball.scale", t)
    assert np.allclose(m["circ_r"], base["circ_r"] * (1 + t)) and np.allclose(m["circ_c"], base["circ_c"])
    # rotation about the centre (mean of the points): distances to it kept, the centre fixed
    m = _moved(scene, "poly.rotate", t)
    centre = np.mean(np.array(scene.shape("poly").points), axis=0)
    before, after = base["seg_a"][1:4] - centre, m["seg_a"][1:4] - centre
    assert np.allclose(np.linalg.norm(before, axis=1), np.linalg.norm(after, axis=1))
    assert np.allclose(np.arctan2(after[:, 1], after[:, 0]) - np.arctan2(before[:, 1], before[:, 0]), t)
    m = _moved(scene, "poly.scale", t)
    assert np.allclose(m["seg_a"][1:4] - centre, (1 + t) * before)
    # vertex 1 of the polyline is the end of its segment 0 and the start of its segment 1
    m = _moved(scene, "line.vertex.1.y", t)
    assert np.allclose(m["seg_b"][4] - base["seg_b"][4], [0.0, t]) and np.allclose(
        m["seg_a"][5] - base["seg_a"][5], [0.0, t]
    )
    assert np.allclose(m["seg_a"][4], base["seg_a"][4])
    m = _moved(scene, "seg.emission", t)
    assert np.allclose(m["emission"] - base["emission"], [t, 0, 0, 0, 0, 0, 0])
    m = _moved(scene, "poly.albedo", t)
    assert np.allclose(m["albedo"] - base["albedo"], [0, t, t, t, 0, 0, 0])
    m = _moved(scene, "camera.translate.x", t)
    assert np.allclose(m["cam_o"] - base["cam_o"], [t, 0.0])
    m = _moved(scene, "camera.rotate", t)
    assert np.allclose(m["cam_f"], [-math.sin(t), math.cos(t)])


@pytest.mark.parametrize(
    "param",
    [
        "seg.translate.x",
        "poly.rotate",
        "poly.scale",
        "line.vertex.2.x",
        "ball.scale",
        "camera.rotate",
        "seg.emission",
    ],
)
def test07_dual_binding_tangents_equal_central_differences(param):
    scene = load_scene(_base())
    g = build_state(scene, param, variable(0.0))
    h = 1e-6
    plus, minus = _moved(scene, param, h), _moved(scene, param, -h)
    for key in plus:
        arr = getattr(g, key)
        fd = (plus[key] - minus[key]) / (2 * h)
        assert np.allclose(tangent(arr), fd, atol=1e-8), key
    assert g.differentiable and not build_state(scene).differentiable
    assert isinstance(g.detached().seg_a, np.ndarray) and not isinstance(g.detached().seg_a, Dual)
