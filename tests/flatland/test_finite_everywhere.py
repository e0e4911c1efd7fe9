"""No NaN or inf leaves a public function on input that validation accepts.

Tiny films (4 pixels, 64 samples per pixel) of every built-in scene and of degenerate
but valid variants, through ``render``, ``render_gradient`` (every method, and
``reparam`` with options at the edges of what validation accepts) and
``irradiance``; ``estimate`` on every textbook integral at both ends of its θ range
with the options at their edges. Warnings are errors under the test settings, so an
``invalid value`` or ``divide by zero`` on the way counts as a failure too, even when
the result happens to come out finite.

1. every built-in scene, every parameter, every method;
2. degenerate variants: coincident segments (the same segment twice, as two shapes,
   in both directions), a polygon whose edges retrace each other, touching and
   coincident circles, an occluder on a camera ray's line and one with an end at
   the camera, an emitter seen edge-on from the floor it lies in line with;
3. ``reparam`` options at their edges (tiny and huge κ, one probe, zero spread, no
   refinement, paired);
4. ``irradiance`` at points on a surface, at a segment's end and at a circle's rim;
5. ``estimate`` on every textbook integral at the ends of its θ range, every method,
   options at their edges.
"""

from __future__ import annotations

import numpy as np
import pytest

from flatland import estimate, irradiance, render, render_gradient
from flatland.integrals import INTEGRALS
from flatland.scene import list_scenes, load_scene

PIXELS, SPP = 4, 64
METHODS = ("naive", "finite_difference", "boundary", "reparam")


def _finite(*arrays) -> bool:
    return all(np.all(np.isfinite(np.asarray(a, dtype=np.float64))) for a in arrays)


def _check_image(scene, param, method, **options) -> None:
    g = render_gradient(scene, param, method=method, spp=SPP, seed=5, batches=2, **options)
    assert _finite(g.value, g.derivative, g.value_stderr, g.derivative_stderr), (param, method, options)


@pytest.mark.parametrize("name", list_scenes())
def test01_every_builtin_scene_parameter_and_method_is_finite(name):
    scene = load_scene(name).with_camera(pixels=PIXELS)
    image = render(scene, spp=SPP, seed=5, batches=2)
    assert _finite(image.value, image.stderr)
    for param in scene.parameters:
        for method in METHODS:
            _check_image(scene, param, method)


def _seg(name, a, b, **material):
    return {"name": name, "type": "segment", "points": [a, b], **material}


def _scene(shapes, position=(0.0, -2.0), direction=(0.0, 1.0), sky=0.3, fov=1.0):
    camera = {"position": list(position), "direction": list(direction), "fov": fov, "pixels": PIXELS}
    return {"name": "degenerate", "camera": camera, "sky": sky, "shapes": shapes}


FLOOR = _seg("floor", [-3.0, 0.0], [3.0, 0.0], albedo=0.8)
LIGHT = _seg("light", [-1.0, 2.0], [1.0, 2.0], emission=3.0)
OCC = [[-0.3, 0.8], [0.4, 0.9]]

DEGENERATE = {
    "coincident_occluders": (
        [FLOOR, LIGHT, _seg("occ", *OCC, albedo=0.5), _seg("twin", *OCC, albedo=0.5)],
        ["occ.translate.x", "twin.rotate", "occ.scale"],
    ),
    "coincident_reversed": (
        [FLOOR, LIGHT, _seg("occ", *OCC, albedo=0.5), _seg("twin", *OCC[::-1], albedo=0.3)],
        ["occ.translate.y", "twin.vertex.0.x"],
    ),
    "coincident_floors": (
        [FLOOR, _seg("floor2", [3.0, 0.0], [-3.0, 0.0], albedo=0.4), LIGHT, _seg("occ", *OCC)],
        ["floor.translate.y", "occ.translate.x", "floor2.albedo"],
    ),
    "emitter_on_the_floor": (  # an emitter coincident with part of a lit floor
        [FLOOR, _seg("strip", [-1.0, 0.0], [1.0, 0.0], emission=2.0, albedo=0.5), LIGHT, _seg("occ", *OCC)],
        ["strip.translate.x", "occ.translate.x", "strip.emission"],
    ),
    "retraced_polygon": (
        [FLOOR, LIGHT, {"name": "fold", "type": "polygon", "points": [*OCC, *OCC], "albedo": 0.5}],
        ["fold.translate.x", "fold.rotate", "fold.vertex.1.y"],
    ),
    "touching_circles": (
        [
            FLOOR,
            LIGHT,
            {"name": "c1", "type": "circle", "center": [-0.3, 0.8], "radius": 0.3, "albedo": 0.5},
            {"name": "c2", "type": "circle", "center": [0.3, 0.8], "radius": 0.3, "albedo": 0.5},
            {"name": "c3", "type": "circle", "center": [-0.3, 0.8], "radius": 0.3, "albedo": 0.2},
            {"name": "on_floor", "type": "circle", "center": [1.5, 0.2], "radius": 0.2, "emission": 1.0},
        ],
        ["c1.translate.x", "c2.scale", "c3.translate.y", "on_floor.scale"],
    ),
    "occluder_on_a_camera_ray": (  # its line passes through the camera; another ends at the camera
        [
            FLOOR,
            LIGHT,
            _seg("ray", [0.0, -1.0], [0.0, 1.0], albedo=0.5),
            _seg("stick", [0.0, -2.0], [0.5, -1.0]),
        ],
        ["ray.translate.x", "ray.rotate", "stick.vertex.1.x", "camera.translate.x", "camera.rotate"],
    ),
    "emitter_edge_on": (  # in line with the floor, and one pointing at the camera
        [
            FLOOR,
            _seg("edge", [3.5, 0.0], [5.0, 0.0], emission=2.0, one_sided=True, fade=0.5),
            _seg("facing", [0.0, 1.0], [0.0, 2.0], emission=1.0),
            _seg("occ", *OCC),
        ],
        ["edge.translate.y", "facing.translate.x", "occ.translate.x", "edge.rotate"],
    ),
    "glossy_extremes": (  # roughness at both ends, a glossy emitter, circle, polygon, a floor seen at grazing
        [
            _seg("floor", [-3.0, 0.0], [3.0, 0.0], albedo=1.0, roughness=1e-3),
            _seg("light", [-1.0, 2.0], [1.0, 2.0], emission=3.0, albedo=0.9, roughness=1.0),
            {
                "name": "ball",
                "type": "circle",
                "center": [-0.3, 0.8],
                "radius": 0.3,
                "albedo": 0.7,
                "roughness": 0.05,
            },
            {
                "name": "tri",
                "type": "polygon",
                "points": [[0.5, 0.5], [1.0, 0.5], [0.7, 1.0]],
                "albedo": 0.0,
                "roughness": 0.5,
            },
        ],
        ["ball.translate.x", "floor.roughness", "light.roughness", "tri.albedo", "camera.translate.y"],
    ),
}


@pytest.mark.parametrize("name", sorted(DEGENERATE))
def test02_degenerate_but_valid_scenes_are_finite(name):
    shapes, params = DEGENERATE[name]
    scene = load_scene(_scene(shapes))
    image = render(scene, spp=SPP, seed=5, batches=2)
    assert _finite(image.value, image.stderr)
    for param in params:
        for method in METHODS:
            _check_image(scene, param, method)
        _check_image(scene, param, "finite_difference", h=0.999 if param.endswith(".scale") else 1e-9)


REPARAM_EDGES = [
    {"kappa": 1e-6},
    {"kappa": 1e12},
    {"kappa_film": 1e-6},
    {"kappa_film": 1e15},
    {"probes": 1},
    {"probes": 2, "spread": 0.0},
    {"probes": 64, "refine": 0},
    {"refine": 40},
    {"paired": True, "kappa": 1e-6},
    {"paired": True, "kappa": 1e12, "kappa_film": 1e15},
]


@pytest.mark.parametrize("options", REPARAM_EDGES, ids=lambda o: ",".join(f"{k}={v}" for k, v in o.items()))
def test03_reparam_options_at_their_edges_are_finite(options):
    for name, param in [("shadow", "occluder.translate.x"), ("silhouette", "ball.scale")]:
        _check_image(load_scene(name).with_camera(pixels=PIXELS), param, "reparam", **options)
    shapes, _ = DEGENERATE["touching_circles"]
    _check_image(load_scene(_scene(shapes)), "c1.translate.x", "reparam", **options)


IRRADIANCE_POINTS = [
    ((0.0, 0.0), (0.0, 1.0)),  # on the floor
    ((-3.0, 0.0), (0.0, 1.0)),  # at the floor's end
    ((-0.3, 1.1), (0.0, 1.0)),  # on top of c1's rim, and of c3's (coincident)
    ((-0.3, 0.8), (1.0, 0.0)),  # at c1's centre, inside two coincident circles
    ((0.0, 0.8), (0.0, 1.0)),  # where c1 and c2 touch
]


@pytest.mark.parametrize(("point", "normal"), IRRADIANCE_POINTS)
def test04_irradiance_on_surfaces_and_at_contacts_is_finite(point, normal):
    shapes, params = DEGENERATE["touching_circles"]
    scene = load_scene(_scene(shapes))
    e = irradiance(scene, point, normal, n=16, seed=5, batches=2)
    assert _finite(e.value, e.value_stderr)
    for method in METHODS:
        for param in params:
            e = irradiance(scene, point, normal, param=param, method=method, n=16, seed=5, batches=2)
            assert _finite(e.value, e.derivative, e.value_stderr, e.derivative_stderr), (param, method)


ESTIMATE_OPTIONS = [
    ("naive", {}),
    ("boundary", {}),
    ("reparam", {}),
    ("reparam", {"kappa": 1e-6}),
    ("reparam", {"kappa": 1e12}),
    ("reparam", {"kappa": 1e-6, "paired": True}),
    ("reparam", {"kappa": 1e12, "paired": True}),
]


@pytest.mark.parametrize("integral", sorted(INTEGRALS))
def test05_textbook_estimates_at_the_edges_are_finite(integral):
    lo, hi = INTEGRALS[integral].theta_range
    for theta in (lo, hi):
        for method, options in ESTIMATE_OPTIONS:
            # the fewest samples accepted (one, or one pair): one draw has an infinite standard error by
            # definition (flatland.core.stats), so only its value and derivative are checked
            e = estimate(
                integral, theta, method=method, n=2 if options.get("paired") else 1, seed=5, **options
            )
            assert _finite(e.value, e.derivative), (theta, method, options)
            e = estimate(integral, theta, method=method, n=64, seed=5, **options)
            assert _finite(e.value, e.derivative, e.value_stderr, e.derivative_stderr), (
                theta,
                method,
                options,
            )
    # finite differences need θ ± h in range: the tiniest step next to each end, the widest in the middle
    h_tiny = 1e-12 * max(1.0, abs(lo), abs(hi))
    for theta, h in ((lo + h_tiny, h_tiny), (hi - h_tiny, h_tiny), (0.5 * (lo + hi), 0.5 * (hi - lo))):
        e = estimate(integral, theta, method="finite_difference", n=64, seed=5, h=h)
        assert _finite(e.value, e.derivative, e.value_stderr, e.derivative_stderr), (theta, h)
