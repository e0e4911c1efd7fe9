"""Scene sketches: one artist per shape, the camera and its frustum, the moving part and its motion.

The sketch draws geometry it is given, so the tests read it back from the artists
(found by their ``gid``): a segment's coordinates, the arrows' components against the
state's tangents, the dashed copy at θ + dθ, and which part carries the halo.
"""

from __future__ import annotations

import io
import math

import matplotlib
import matplotlib.image as mpimg
import numpy as np
import pytest
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Polygon
from matplotlib.quiver import Quiver

from flatland.core.dual import variable
from flatland.core.validate import ValidationError
from flatland.plotting.sketch import draw_scene, plot_scene
from flatland.plotting.style import METHOD_COLOURS, SKETCH_COLOURS
from flatland.scene import list_scenes, load_scene, parameter_names
from flatland.state import build_state, parse_parameter
from tests.tiers import sweep

KINDS = {"segment": LineCollection, "polyline": LineCollection, "polygon": Polygon, "circle": Circle}


def gids(ax):
    """Artists of ``ax`` by gid (every sketch element has one)."""
    return {a.get_gid(): a for a in ax.get_children() if a.get_gid()}


def test01_one_artist_per_shape_of_its_kind_and_the_camera_with_its_frustum():
    scene = load_scene("silhouette")
    ax = plot_scene(scene).axes[0]
    drawn = gids(ax)
    for shape in scene.shapes:
        kind = "emitter" if shape.emission > 0 else "shape"
        assert isinstance(drawn.pop(f"{kind}:{shape.name}"), KINDS[shape.type]), shape.name
    assert isinstance(drawn.pop("frustum"), Polygon) and isinstance(
        drawn.pop("frustum_edges"), LineCollection
    )
    camera, film = drawn.pop("camera"), drawn.pop("film")
    assert isinstance(camera, Line2D) and isinstance(film, Line2D)
    assert (camera.get_xdata()[0], camera.get_ydata()[0]) == scene.camera.position
    assert drawn == {}  # nothing moves without a parameter: no halo, no arrows, no copy
    # the film spans the field of view: its ends seen from the pinhole are fov apart
    ends = np.array(film.get_xydata()) - np.array(scene.camera.position)
    seen = math.acos(ends[0] @ ends[1] / np.prod(np.linalg.norm(ends, axis=1)))
    assert seen == pytest.approx(scene.camera.fov, rel=1e-12)
    assert ax.get_aspect() == 1.0 and ax.get_xlabel() == "x" and ax.get_ylabel() == "y"
    labels = [t.get_text() for t in ax.texts]
    assert all(s.name in labels for s in scene.shapes) and "pixel 0" in labels
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend[:3] == ["shape", "emitter", "camera, film, view"]


def test02_the_moving_part_is_marked_and_its_arrows_end_on_its_dashed_copy():
    scene = load_scene("shadow")
    ax = plot_scene(scene, "occluder.translate.x").axes[0]
    drawn = gids(ax)
    assert [g.split(":")[0] for g in drawn if g.endswith(":occluder")] == [
        "shape",
        "moving",
        "moved",
        "motion",
    ]
    assert not any(g.startswith(("moving:", "moved:", "motion:")) for g in drawn if "occluder" not in g)
    (a, b) = np.array(scene.shape("occluder").points)
    arrows = drawn["motion:occluder"]
    assert isinstance(arrows, Quiver)
    step = float(arrows.U[0])  # a translation along x: every arrow is (dθ, 0), dθ > 0
    assert step > 0.0 and np.all(step == arrows.U) and np.all(arrows.V == 0.0)
    moved = drawn["moved:occluder"].get_segments()[0]
    shift = np.array([step, 0.0])
    assert np.allclose(moved, [a + shift, b + shift], rtol=0.0, atol=1e-12)
    assert np.allclose(arrows.X, [a[0], b[0]]) and np.allclose(arrows.Y, [a[1], b[1]])
    assert drawn["moving:occluder"].get_colors()[0][:3] == pytest.approx(matplotlib.colors.to_rgb(
        SKETCH_COLOURS["moving"]))  # fmt: skip
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "occluder.translate.x" in legend and f"at θ + dθ, dθ = {step:.2g}" in legend
    assert ax.get_title() == "shadow: occluder.translate.x"


def test03_a_rotation_moves_every_vertex_perpendicular_to_its_radius():
    scene = load_scene("polygon")
    pts = np.array(scene.shape("polygon").points)
    centre = pts.mean(axis=0)
    arrows = gids(plot_scene(scene, "polygon.rotate", step=0.1).axes[0])["motion:polygon"]
    uv = np.stack([arrows.U, arrows.V], axis=1)
    radius = pts - centre
    assert np.allclose(uv, 0.1 * np.stack([-radius[:, 1], radius[:, 0]], axis=1), rtol=0.0, atol=1e-12)


@pytest.mark.parametrize("name", sweep(list_scenes(), ["polygon"]))
def test04_every_builtin_scene_and_every_parameter_marks_exactly_its_part(name):
    scene = load_scene(name)
    fig = Figure()
    ax = fig.add_subplot()
    for param in parameter_names(scene):
        ax.clear()
        draw_scene(ax, scene, param)
        drawn = gids(ax)
        p = parse_parameter(scene, param)
        marked = {g.split(":")[1] for g in drawn if g.startswith("moving:")}
        moved = {g.split(":")[1] for g in drawn if g.startswith(("moved:", "motion:"))}
        camera_edge = matplotlib.colors.to_hex(drawn["camera"].get_markeredgecolor())
        if p.target == "camera":
            assert marked == set() and moved == {"camera"}, param
            assert camera_edge == SKETCH_COLOURS["moving"], param
            continue
        assert marked == {p.target} and camera_edge == SKETCH_COLOURS["camera"], param
        geometric = p.kind not in ("emission", "albedo", "roughness")
        assert moved == ({p.target} if geometric else set()), param
        assert ax.get_title() == f"{name}: {param}"


def test05_a_state_with_its_duals_is_drawn_too_and_bad_input_is_one_error():
    scene = load_scene("silhouette")
    state = build_state(scene, "ball.scale", variable(0.0))
    drawn = gids(plot_scene(state).axes[0])
    assert "moving:shape 2" in drawn and "motion:shape 2" in drawn  # shapes numbered in scene order
    arrows = drawn["motion:shape 2"]  # a growing circle: four boundary points move outward at r' n = r n
    assert np.allclose(np.hypot(arrows.U, arrows.V) / arrows.scale, arrows.U[0], rtol=1e-12)
    cases = [
        ({"scene": state, "param": "ball.scale"}, "param"),
        ({"scene": scene, "param": "ball.rotate"}, "param"),
        ({"scene": scene, "param": "ball.scale", "step": 0.0}, "step"),
        ({"scene": scene, "param": "ball.scale", "theta": math.nan}, "theta"),
        ({"scene": "no_such_scene"}, "scene"),
    ]
    for kwargs, field in cases:
        with pytest.raises(ValidationError) as info:
            plot_scene(**kwargs)
        assert info.value.field == field, kwargs


def test06_sketch_colours_are_no_method_colour_and_the_png_shows_them():
    assert not set(SKETCH_COLOURS.values()) & set(METHOD_COLOURS.values())
    fig = plot_scene("shadow", "occluder.translate.x")
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=80)
    rgb = mpimg.imread(io.BytesIO(buffer.getvalue()))[..., :3]
    for key in ("emitter", "moving", "camera"):
        target = np.array(matplotlib.colors.to_rgb(SKETCH_COLOURS[key]))
        assert np.sum(np.all(np.abs(rgb - target) < 0.02, axis=-1)) > 20, key
