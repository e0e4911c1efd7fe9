r"""Flatland scenes: shapes, materials, emitters, a pinhole camera and named parameters.

A scene is a plain dict (or a JSON file of the same shape), validated on load::

    {"name": "shadow",
     "camera": {"position": [x, y], "direction": [dx, dy], "fov": 0.9,
                "pixels": 64, "filter": "tent"},
     "sky": 0.0,
     "shapes": [{"name": "floor", "type": "segment", "points": [[-3, 0], [3, 0]],
                 "albedo": 0.8},
                {"name": "light", "type": "segment", "points": [[0.5, 2], [-0.5, 2]],
                 "emission": 6.0, "one_sided": true, "fade": 0.1},
                {"name": "ball", "type": "circle", "center": [0, 1], "radius": 0.3}],
     "parameters": ["light.translate.x", "ball.scale"]}

Shapes are made of line segments (``segment``: 2 points, ``polyline``: >= 2 points,
``polygon``: >= 3 points, closed) or are circles. Each has a diffuse ``albedo`` in
[0, 1] (BRDF albedo/2, theory/radiometry) and an ``emission`` radiance >= 0. A shape with a
``roughness`` α in (0, 1] is glossy instead: the GGX microfacet BSDF of :mod:`flatland.bsdf`, its
``albedo`` the constant Fresnel reflectance F scaling the lobe (α = 0, a perfect mirror, is
refused: a delta BSDF has no integral to reparameterize; theory/bsdf). Emission is
two-sided unless ``one_sided`` is true; a one-sided segment emits toward the right of
its direction a → b (outward for a counter-clockwise polygon), a circle outward. A
``segment`` emitter may ``fade`` linearly to zero over that fraction (<= 0.5) of its
length at both ends, so its own edge is not a moving discontinuity (theory/probes).
Rays that escape see the constant ``sky`` radiance. The camera is a pinhole with a 1D film: film coordinate t
looks along $\mathrm{normalize}(\mathrm{forward} + t · \mathrm{right})$ (theory/radiometry), right being
forward turned clockwise; the ``pixels`` cover t in $[-\tan(\mathrm{fov}/2), \tan(\mathrm{fov}/2)]$ left to
right, each integrated against its ``filter`` (``box`` one pixel wide, ``tent`` of radius one pixel,
``gaussian`` of standard deviation half a pixel).

Parameters bind a scalar θ to one scene quantity. θ is an offset applied to the
scene as loaded, and gradients are taken at θ = 0:

===============================  =================================================
``NAME.translate.x`` / ``.y``    add θ to every point (or the centre) of the shape
``NAME.rotate``                  rotate by θ radians about the shape's centre (the
                                 mean of its points; not for circles)
``NAME.scale``                   scale by 1 + θ about the shape's centre (a circle's
                                 radius)
``NAME.vertex.K.x`` / ``.y``     add θ to point K of a segment, polyline or polygon
``NAME.emission``                add θ to the shape's emitted radiance
``NAME.albedo``                  add θ to the shape's albedo
``NAME.roughness``               add θ to a glossy shape's roughness α
``camera.translate.x`` / ``.y``  move the camera
``camera.rotate``                turn the camera by θ radians (counter-clockwise)
``NAME.shape.K``                 a polygon's radial Fourier coefficient K: add
                                 $θ (p_i - c) B_K(φ_i)$ to each vertex $p_i$
===============================  =================================================

Shape coefficients deform a polygon smoothly along its radii: vertex i at angle $φ_i$ and
distance $r_i$ from the centre c (both of the polygon as loaded) moves to radius
$r_i (1 + Σ_K θ_K B_K(φ_i))$, with $B_0 = 1$, $B_{2m-1} = \cos mφ$, $B_{2m} = \sin mφ$ for
orders $m = 1 … M$, $M = \min(4, ⌊(n - 1)/2⌋)$ for n vertices (no order at or above the Nyquist
order n/2 of the vertices, at most 9 coefficients). The deformation is linear in θ, so offsets
add exactly, and with every coefficient 0 the polygon is unchanged bit for bit. A circle has no
shape coefficients (its ray intersection and tangent points are closed forms of a circle): a round
shape to deform is a polygon with many vertices.

A scene may carry ``offsets`` (``{"occluder.translate.x": 0.3}``): parameter offsets applied
on load, so the scene as rendered is the scene as written moved by them, and a gradient is
taken at those offsets (:func:`flatland.state.moved_scene` adds to them; every parameter of
the table composes additively with its own offset, a scale's factor being $1 + θ$ in total).

:func:`flatland.state.build_state` turns (scene, parameter, θ) into a
:class:`~flatland.state.SceneState`, the flat arrays the ray caster and renderer use.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from flatland.core.microfacet import check_alpha
from flatland.core.validate import (
    ValidationError,
    check_bool,
    check_choice,
    check_depth,
    check_finite,
    check_int,
    read_json,
)

__all__ = [
    "FILTERS",
    "SHAPE_TYPES",
    "Camera",
    "Scene",
    "Shape",
    "check_direction",
    "check_point",
    "list_scenes",
    "load_scene",
    "parameter_names",
]

SHAPE_TYPES = ("segment", "polyline", "polygon", "circle")
FILTERS = ("box", "tent", "gaussian")
_MIN_POINTS = {"segment": 2, "polyline": 2, "polygon": 3}
_TOP_KEYS = ("name", "description", "camera", "sky", "shapes", "parameters", "offsets")
MAX_SHAPE_ORDER = 4
"""Highest Fourier order of a polygon's shape coefficients (``NAME.shape.K``): at most 2 · 4 + 1 = 9."""
_CAMERA_KEYS = ("position", "direction", "fov", "pixels", "filter")
_COMMON_SHAPE_KEYS = ("name", "type", "albedo", "emission", "one_sided", "roughness")
_SHAPE_KEYS = {
    "segment": (*_COMMON_SHAPE_KEYS, "points", "fade"),
    "polyline": (*_COMMON_SHAPE_KEYS, "points"),
    "polygon": (*_COMMON_SHAPE_KEYS, "points"),
    "circle": (*_COMMON_SHAPE_KEYS, "center", "radius"),
}
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*$")


# ------------------------------------------------------------------ scene description
@dataclass(frozen=True)
class Camera:
    """Pinhole camera with a 1D film (see the module docstring)."""

    position: tuple[float, float]
    direction: tuple[float, float]
    fov: float
    pixels: int
    filter: str

    @property
    def half_width(self) -> float:
        """Film half-width tan(fov / 2)."""
        return math.tan(0.5 * self.fov)

    @property
    def pixel_width(self) -> float:
        """Width Δt of one pixel in film coordinates."""
        return 2.0 * self.half_width / self.pixels

    def pixel_centers(self) -> np.ndarray:
        """Film coordinates of the pixel centres, left to right."""
        return -self.half_width + (np.arange(self.pixels) + 0.5) * self.pixel_width


@dataclass(frozen=True)
class Shape:
    """One shape: segments (``points``) or a circle (``center``, ``radius``), and its material."""

    name: str
    type: str
    points: tuple[tuple[float, float], ...] = ()
    center: tuple[float, float] | None = None
    radius: float | None = None
    albedo: float = 0.0
    emission: float = 0.0
    one_sided: bool = False
    fade: float = 0.0
    roughness: float = 0.0

    @property
    def glossy(self) -> bool:
        """True for a glossy shape (a ``roughness`` > 0, :mod:`flatland.bsdf`); False for a diffuse one."""
        return self.roughness > 0.0

    def segments(self) -> list[tuple[int, int]]:
        """Index pairs (i, j) of the points joined by segments (a polygon closes)."""
        n = len(self.points)
        pairs = [(i, i + 1) for i in range(n - 1)]
        return [*pairs, (n - 1, 0)] if self.type == "polygon" else pairs

    def shape_terms(self) -> int:
        r"""How many shape coefficients ``NAME.shape.K`` the shape has: $2M + 1$ for a polygon of n
        vertices, $M = \min(4, ⌊(n - 1)/2⌋)$ (see the module docstring); 0 for other shapes."""
        if self.type != "polygon":
            return 0
        return 2 * min(MAX_SHAPE_ORDER, (len(self.points) - 1) // 2) + 1

    def centre(self) -> np.ndarray:
        """The centre rotations and scalings act about: the mean of the points, or the circle's centre."""
        if self.type == "circle":
            return np.array(self.center, dtype=np.float64)
        return np.mean(np.array(self.points, dtype=np.float64), axis=0)


@dataclass(frozen=True)
class Scene:
    """A validated flatland scene; build one with :func:`load_scene`."""

    name: str
    camera: Camera
    sky: float
    shapes: tuple[Shape, ...]
    parameters: tuple[str, ...] = ()
    description: str = ""
    offsets: tuple[tuple[str, float], ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """The scene as a JSON-ready dict; ``load_scene(scene.to_dict()) == scene``."""
        cam = self.camera
        shapes = []
        for s in self.shapes:
            d: dict[str, Any] = {"name": s.name, "type": s.type}
            if s.type == "circle":
                d["center"] = list(s.center)
                d["radius"] = s.radius
            else:
                d["points"] = [list(p) for p in s.points]
            d.update(albedo=s.albedo, emission=s.emission, one_sided=s.one_sided)
            if s.type == "segment":
                d["fade"] = s.fade
            if s.glossy:
                d["roughness"] = s.roughness
            shapes.append(d)
        return {
            "name": self.name,
            "description": self.description,
            "camera": {
                "position": list(cam.position),
                "direction": list(cam.direction),
                "fov": cam.fov,
                "pixels": cam.pixels,
                "filter": cam.filter,
            },
            "sky": self.sky,
            "shapes": shapes,
            "parameters": list(self.parameters),
            **({"offsets": dict(self.offsets)} if self.offsets else {}),
        }

    def shape(self, name: str) -> Shape:
        """The shape called ``name``."""
        for s in self.shapes:
            if s.name == name:
                return s
        raise ValidationError("shape", f"no shape named {name!r} in scene {self.name!r}")

    def with_camera(self, **changes: Any) -> Scene:
        """A copy with camera fields changed (validated), e.g. ``scene.with_camera(pixels=32)``."""
        d = self.to_dict()
        d["camera"].update(changes)
        return load_scene(d)


# ------------------------------------------------------------------ validation
def _check_keys(path: str, d: Any, allowed: tuple[str, ...], required: tuple[str, ...]) -> None:
    if not isinstance(d, Mapping):
        raise ValidationError(path or "scene", f"must be a mapping (JSON object), got {d!r}")
    for key, value in d.items():
        if key not in allowed:
            where = f"{path}.{key}" if path else str(key)
            raise ValidationError(where, f"unknown key (value {value!r}); allowed keys: {', '.join(allowed)}")
    for key in required:
        if key not in d:
            raise ValidationError(f"{path}.{key}" if path else key, "is required")


def check_point(path: str, value: Any) -> tuple[float, float]:
    """``value`` as a pair of finite floats (a point or a vector); one error naming ``path`` otherwise."""
    if isinstance(value, str | bytes) or not hasattr(value, "__len__") or len(value) != 2:
        raise ValidationError(path, f"must be a pair [x, y], got {value!r}")
    return (check_finite(f"{path}[0]", value[0]), check_finite(f"{path}[1]", value[1]))


def check_direction(path: str, value: Any) -> tuple[float, float]:
    """``value`` as a unit vector: a non-zero pair of finite floats, normalized."""
    x, y = check_point(path, value)
    length = math.hypot(x, y)
    if not length > 1e-12:
        raise ValidationError(path, f"must be a non-zero vector, got {value!r}")
    return (x / length, y / length)


def _check_name(path: str, value: Any) -> str:
    if not isinstance(value, str) or not _NAME.match(value) or value == "camera":
        raise ValidationError(
            path, f"must be a name of letters, digits, '_' or '-' (not 'camera', no dots), got {value!r}"
        )
    return value


def _check_range(path: str, value: Any, lo: float, hi: float) -> float:
    out = check_finite(path, value)
    if not lo <= out <= hi:
        raise ValidationError(path, f"must lie in [{lo}, {hi}], got {value!r}")
    return out


def _check_camera(d: Any) -> Camera:
    _check_keys("camera", d, _CAMERA_KEYS, ("position", "direction", "fov", "pixels"))
    position = check_point("camera.position", d["position"])
    direction = check_direction("camera.direction", d["direction"])
    fov = check_finite("camera.fov", d["fov"])
    if not 0.0 < fov < math.pi:
        raise ValidationError("camera.fov", f"must lie in (0, π) radians, got {d['fov']!r}")
    pixels = check_int("camera.pixels", d["pixels"])
    filt = check_choice("camera.filter", d.get("filter", "tent"), FILTERS)
    return Camera(position, direction, fov, pixels, filt)


def _check_roughness(path: str, d: Mapping) -> float:
    """A glossy shape's GGX roughness α in (0, 1]; 0.0 (diffuse) when the key is absent.

    α = 0, a perfect mirror, is refused by :func:`~flatland.core.microfacet.check_alpha` with its
    reason: a delta BSDF has no integral to reparameterize.
    """
    if "roughness" not in d:
        return 0.0
    return float(check_alpha(check_finite(path, d["roughness"]), path))


def _check_shape(i: int, d: Any) -> Shape:
    path = f"shapes[{i}]"
    if not isinstance(d, Mapping):
        raise ValidationError(path, f"must be a mapping (JSON object), got {d!r}")
    kind = d.get("type")
    if kind not in SHAPE_TYPES:
        raise ValidationError(
            f"{path}.type", f"unknown shape type {kind!r}; choose from {', '.join(SHAPE_TYPES)}"
        )
    required = ("name", "type", "center", "radius") if kind == "circle" else ("name", "type", "points")
    _check_keys(path, d, _SHAPE_KEYS[kind], required)
    name = _check_name(f"{path}.name", d["name"])
    albedo = check_finite(f"{path}.albedo", d.get("albedo", 0.0))
    if not 0.0 <= albedo <= 1.0:
        raise ValidationError(f"{path}.albedo", f"must lie in [0, 1], got {d['albedo']!r}")
    emission = check_finite(f"{path}.emission", d.get("emission", 0.0))
    if emission < 0.0:
        raise ValidationError(f"{path}.emission", f"must be >= 0, got {d['emission']!r}")
    one_sided = check_bool(f"{path}.one_sided", d.get("one_sided", False))
    roughness = _check_roughness(f"{path}.roughness", d)
    if kind == "circle":
        center = check_point(f"{path}.center", d["center"])
        radius = check_finite(f"{path}.radius", d["radius"])
        if radius <= 0.0:
            raise ValidationError(f"{path}.radius", f"must be > 0, got {d['radius']!r}")
        return Shape(name, kind, (), center, radius, albedo, emission, one_sided, roughness=roughness)
    raw = d["points"]
    if isinstance(raw, str | bytes | Mapping) or not hasattr(raw, "__len__"):
        raise ValidationError(f"{path}.points", f"must be a list of points [x, y], got {raw!r}")
    if kind == "segment" and len(raw) != 2:
        raise ValidationError(f"{path}.points", f"a segment has exactly 2 points, got {len(raw)}")
    if len(raw) < _MIN_POINTS[kind]:
        raise ValidationError(
            f"{path}.points", f"a {kind} needs >= {_MIN_POINTS[kind]} points, got {len(raw)}"
        )
    points = tuple(check_point(f"{path}.points[{k}]", p) for k, p in enumerate(raw))
    fade = _check_range(f"{path}.fade", d.get("fade", 0.0), 0.0, 0.5)
    shape = Shape(name, kind, points, None, None, albedo, emission, one_sided, fade, roughness)
    scale = max(1.0, float(np.max(np.abs(np.array(points)))))
    for a, b in shape.segments():
        if math.dist(points[a], points[b]) <= 1e-9 * scale:
            raise ValidationError(
                f"{path}.points[{b}]",
                f"zero-length segment: point {b} {list(points[b])} equals point {a} {list(points[a])}",
            )
    return shape


def _from_dict(d: Any) -> Scene:
    _check_keys("", d, _TOP_KEYS, ("name", "camera", "shapes"))
    name = d["name"]
    if not isinstance(name, str) or not name:
        raise ValidationError("name", f"must be a non-empty string, got {name!r}")
    description = d.get("description", "")
    if not isinstance(description, str):
        raise ValidationError("description", f"must be a string, got {description!r}")
    camera = _check_camera(d["camera"])
    sky = check_finite("sky", d.get("sky", 0.0))
    if sky < 0.0:
        raise ValidationError("sky", f"must be >= 0, got {d['sky']!r}")
    raw_shapes = d["shapes"]
    if isinstance(raw_shapes, str | bytes | Mapping) or not hasattr(raw_shapes, "__len__") or not raw_shapes:
        raise ValidationError("shapes", f"must be a non-empty list of shapes, got {raw_shapes!r}")
    shapes = tuple(_check_shape(i, s) for i, s in enumerate(raw_shapes))
    seen: dict[str, int] = {}
    for i, s in enumerate(shapes):
        if s.name in seen:
            raise ValidationError(
                f"shapes[{i}].name", f"duplicate shape name {s.name!r} (also shapes[{seen[s.name]}])"
            )
        seen[s.name] = i
    scene = Scene(name, camera, sky, shapes, (), description)
    raw_params = d.get("parameters", [])
    if isinstance(raw_params, str | bytes | Mapping) or not hasattr(raw_params, "__len__"):
        raise ValidationError("parameters", f"must be a list of parameter names, got {raw_params!r}")
    from flatland.state import parse_parameter  # state.py builds on this module: imported on use

    params = tuple(parse_parameter(scene, p, field=f"parameters[{k}]").name for k, p in enumerate(raw_params))
    from flatland.state import check_offsets

    return replace(scene, parameters=params, offsets=check_offsets(scene, d.get("offsets", {})))


def _scene_dir() -> Any:
    return resources.files("flatland") / "scenes"


def list_scenes() -> tuple[str, ...]:
    """Names of the built-in scenes (``flatland/scenes/*.json``), sorted."""
    return tuple(sorted(p.name[:-5] for p in _scene_dir().iterdir() if p.name.endswith(".json")))


def load_scene(source: Any) -> Scene:
    """A validated :class:`Scene` from a built-in name, a ``.json`` path, a dict or a Scene.

    Raises
    ------
    ValidationError
        One error naming the bad field's path and value, e.g.
        ``shapes[2].radius: must be > 0, got -1.0``.
    """
    if isinstance(source, Scene):
        return source
    if isinstance(source, Mapping):
        return _from_dict(check_depth("scene", source))
    if isinstance(source, str) and source in list_scenes():
        return _from_dict(read_json(_scene_dir() / f"{source}.json", "built-in scene"))
    if isinstance(source, str | Path) and str(source).endswith(".json"):
        return _from_dict(read_json(source, "scene"))
    raise ValidationError(
        "scene",
        f"unknown scene {source!r}: not a built-in ({', '.join(list_scenes())}), a .json path or a dict",
    )


# ------------------------------------------------------------------ parameters
def parameter_names(scene: Scene) -> tuple[str, ...]:
    """Every parameter name :func:`~flatland.state.parse_parameter` accepts for ``scene``, in scene order.

    The camera's three, then per shape ``translate.x|y``, ``rotate`` (not circles),
    ``scale``, ``vertex.K.x|y`` for each point, ``shape.K`` (polygons: :meth:`Shape.shape_terms`),
    ``emission``, ``albedo`` and, for a glossy shape, ``roughness``.
    ``scene.parameters`` holds only the ones the scene file declares.
    """
    names = ["camera.translate.x", "camera.translate.y", "camera.rotate"]
    for shape in scene.shapes:
        names += [f"{shape.name}.translate.x", f"{shape.name}.translate.y"]
        names += [] if shape.type == "circle" else [f"{shape.name}.rotate"]
        names.append(f"{shape.name}.scale")
        names += [f"{shape.name}.vertex.{k}.{axis}" for k in range(len(shape.points)) for axis in "xy"]
        names += [f"{shape.name}.shape.{k}" for k in range(shape.shape_terms())]
        names += [f"{shape.name}.emission", f"{shape.name}.albedo"]
        names += [f"{shape.name}.roughness"] if shape.glossy else []
    return tuple(names)
