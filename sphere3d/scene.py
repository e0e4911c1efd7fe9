r"""Scenes on the sphere: shapes, materials, emitters, camera and parameters; loaded from dicts or JSON.

A scene is a dict (or a JSON file of the same shape)::

    {"name": "shadow",
     "camera": {"position": [x, y, z], "look_at": [x, y, z], "up": [x, y, z],
                "fov": 0.7, "width": 64, "height": 64, "filter": "gaussian"},
     "sky": 0.0,
     "shapes": [{"name": "floor", "type": "rectangle", "size": [4, 4], "albedo": 0.7},
                {"name": "light", "type": "rectangle", "size": [1, 1],
                 "translate": [0, 0, 2], "rotate": [3.14159, 0, 0],
                 "emission": 8.0, "fade": 0.25, "albedo": 0.0}, ...]}

Every shape has ``translate`` (position of its centre), ``rotate`` (radians about x,
then y, then z, acting about the centre), ``scale`` (uniform, about the centre), the
centre being the origin of the shape's own coordinates: the middle of every built-in
shape, and of a mesh whose ``center`` is true (its bounding box's centre; the default
for a mesh loaded from a file, whose own origin is arbitrary; inline ``vertices`` are
kept as written unless ``"center": true``, so with them the centre is their origin),
``albedo`` (diffuse reflectance in [0, 1]; a glossy shape's Fresnel reflectance F), ``roughness``
(absent: diffuse; α in (0, 1]: a rough GGX conductor, :mod:`sphere3d.materials`), ``emission``
(radiance of its front side, the side its normals face), ``fade`` (emitter border fade, rectangle and disk
only) and ``smooth`` (false, the default: shade with the face normals; true: with
the vertex normals of :mod:`sphere3d.shapes` interpolated over each triangle, e.g.
an OBJ file's ``vn``; rays still leave along the face normal); a mesh also takes
inline ``normals``, one per vertex. Type-specific keys are listed in
:data:`SHAPE_KEYS`. ``fov`` is the horizontal field of view in radians; ``sky`` the
constant environment radiance.

Parameters bind a scalar θ to one scene quantity, as in flatland: θ is an offset
applied to the scene as loaded, and gradients are taken at θ = 0:

========================================  ==============================================
``NAME.translate.x`` / ``.y`` / ``.z``    add θ to the shape's position
``NAME.rotate.x`` / ``.y`` / ``.z``       add θ radians to that rotation angle (about
                                          the shape's centre)
``NAME.scale``                            scale by 1 + θ about the shape's centre
``NAME.emission``                         add θ to the emitted radiance
``NAME.albedo``                           add θ to the albedo
``NAME.roughness``                        add θ to a glossy shape's GGX α (shapes with ``roughness``)
``camera.translate.x`` / ``.y`` / ``.z``  move the camera (position and look-at)
``sky.emission``                          add θ to the sky radiance
``NAME.shape.K``                          an icosphere's or mesh's shape coefficient K (0 to
                                          15): move each vertex v to $v (1 + θ Y_K(\hat v))$
========================================  ==============================================

Shape coefficients deform an icosphere or a mesh along the directions $\hat v$ from its centre
(the origin of its own coordinates) by the real spherical harmonics $Y_K$ of degree <= 3, scaled
to $Y_0 = 1$ and mean square 1 (:mod:`sphere3d.harmonics`, which also carries the vertex normals);
linear in θ, so offsets add exactly, and with every coefficient 0 the mesh is unchanged bit for bit.

A scene may carry ``offsets`` (``{"occluder.translate.x": 0.3}``): parameter offsets applied when
its state is built, so the scene as rendered is the scene as written moved by them, and a gradient
with respect to a parameter it offsets is taken there, the two offsets added in one slot
(:func:`sphere3d.state.moved_scene` adds to them; a scale's factor is $1 + θ$ in total).

Bad input raises one :class:`~flatland.core.validate.ValidationError` naming the
field path and the value, e.g. ``shapes[2].radius: must be > 0, got -1.0``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from dataclasses import field as dataclass_field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from flatland.core.validate import (
    ValidationError,
    check_choice,
    check_depth,
    check_finite,
    check_int,
    check_positive,
    read_json,
)
from sphere3d import shapes as shp
from sphere3d.harmonics import TERMS
from sphere3d.materials import materials
from sphere3d.offsets import check_offsets
from sphere3d.sampling import FILTERS

__all__ = [
    "SHAPE_KEYS",
    "SHAPE_TYPES",
    "Camera",
    "Scene",
    "Shape",
    "check_vector",
    "list_scenes",
    "load_reference",
    "load_scene",
    "parameter_names",
    "reference_path",
]

SHAPE_TYPES = ("rectangle", "box", "icosphere", "disk", "mesh")
MATERIAL_KEYS = ("albedo", "emission", "fade", "smooth", "roughness")
COMMON_KEYS = ("name", "type", "translate", "rotate", "scale", *MATERIAL_KEYS)
SHAPE_KEYS: Mapping[str, tuple[str, ...]] = {
    "rectangle": ("size",),
    "box": ("size",),
    "icosphere": ("radius", "subdivisions"),
    "disk": ("radius", "segments"),
    "mesh": ("path", "vertices", "faces", "normals", "center"),
}
"""Type-specific keys of each shape type (besides :data:`COMMON_KEYS`)."""
DEFAULTS: Mapping[str, Any] = {
    "translate": [0.0, 0.0, 0.0],
    "rotate": [0.0, 0.0, 0.0],
    "scale": 1.0,
    "albedo": 0.5,
    "emission": 0.0,
    "fade": 0.0,
    "smooth": False,
    "subdivisions": 2,
    "segments": 32,
}
CAMERA_KEYS = ("position", "look_at", "up", "fov", "width", "height", "filter")
CAMERA_DEFAULTS: Mapping[str, Any] = {"up": [0.0, 0.0, 1.0], "filter": "gaussian"}
AXES = ("x", "y", "z")
MAX_PIXELS = 4096


# ------------------------------------------------------------------ validation
def _check_keys(field: str, d: Any, allowed: tuple[str, ...], required: tuple[str, ...] = ()) -> None:
    if not isinstance(d, Mapping):
        raise ValidationError(field, f"must be an object (dict), got {type(d).__name__}")
    for key in d:
        if key not in allowed:
            raise ValidationError(
                f"{field}.{key}" if field else str(key), f"unknown key; allowed: {', '.join(allowed)}"
            )
    for key in required:
        if key not in d:
            raise ValidationError(f"{field}.{key}" if field else key, "is required")


def check_vector(field: str, value: Any, n: int = 3, positive: bool = False) -> tuple[float, ...]:
    """``value`` (a list, tuple or 1D array) as ``n`` finite floats, > 0 with ``positive``."""
    if (
        not isinstance(value, list | tuple | np.ndarray)
        or (isinstance(value, np.ndarray) and value.ndim != 1)
        or len(value) != n
    ):
        raise ValidationError(field, f"must be a list of {n} numbers, got {value!r}")
    check = check_positive if positive else check_finite
    return tuple(check(f"{field}[{i}]", x) for i, x in enumerate(value))


def _json_value(value: Any) -> Any:
    """A validated field as JSON writes it: tuples as lists."""
    return list(value) if isinstance(value, tuple) else value


@dataclass(frozen=True)
class Camera:
    """Pinhole camera: position, look-at point, up vector, horizontal fov (radians), film and filter."""

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    up: tuple[float, float, float]
    fov: float
    width: int
    height: int
    filter: str

    @staticmethod
    def from_dict(d: Any) -> Camera:
        _check_keys("camera", d, CAMERA_KEYS, ("position", "look_at", "fov", "width", "height"))
        d = {**CAMERA_DEFAULTS, **d}
        position = check_vector("camera.position", d["position"])
        look_at = check_vector("camera.look_at", d["look_at"])
        up = check_vector("camera.up", d["up"])
        fov = check_positive("camera.fov", d["fov"])
        if fov >= math.pi:
            raise ValidationError("camera.fov", f"must be < π (radians), got {d['fov']!r}")
        width = check_int("camera.width", d["width"])
        height = check_int("camera.height", d["height"])
        for key, n in (("width", width), ("height", height)):
            if n > MAX_PIXELS:
                raise ValidationError(f"camera.{key}", f"must be <= {MAX_PIXELS}, got {n}")
        forward = np.subtract(look_at, position)
        if np.linalg.norm(forward) == 0.0:
            raise ValidationError("camera.look_at", f"must differ from camera.position, got {list(look_at)}")
        if np.linalg.norm(np.cross(forward / np.linalg.norm(forward), up)) < 1e-6 * np.linalg.norm(up):
            raise ValidationError("camera.up", f"must not be parallel to the view direction, got {list(up)}")
        return Camera(
            position, look_at, up, fov, width, height, check_choice("camera.filter", d["filter"], FILTERS)
        )

    def to_dict(self) -> dict[str, Any]:
        return {f.name: _json_value(getattr(self, f.name)) for f in fields(self)}

    def frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit (forward, right, up) vectors of the camera."""
        f = np.subtract(self.look_at, self.position)
        f = f / np.linalg.norm(f)
        r = np.cross(f, self.up)
        r = r / np.linalg.norm(r)
        return f, r, np.cross(r, f)


@dataclass(frozen=True)
class Shape:
    """One shape: its type-specific geometry (``geometry``), transform and material."""

    name: str
    type: str
    translate: tuple[float, float, float]
    rotate: tuple[float, float, float]
    scale: float
    albedo: float
    emission: float
    fade: float
    smooth: bool
    geometry: tuple[tuple[str, Any], ...]
    mesh: shp.LocalMesh = dataclass_field(compare=False, repr=False)
    roughness: float | None = None  # GGX α of a glossy conductor (sphere3d.bsdf); None: diffuse

    @staticmethod
    def from_dict(field: str, d: Any, base_dir: Path | None) -> Shape:
        if not isinstance(d, Mapping):
            raise ValidationError(field, f"must be an object (dict), got {type(d).__name__}")
        kind = check_choice(f"{field}.type", d.get("type"), SHAPE_TYPES)
        _check_keys(field, d, COMMON_KEYS + SHAPE_KEYS[kind], ("name", "type"))
        name = d["name"]
        if not isinstance(name, str) or not name or "." in name or name in ("camera", "sky"):
            raise ValidationError(
                f"{field}.name", f"must be a non-empty name without '.', not camera/sky; got {name!r}"
            )
        d = {**DEFAULTS, **d}
        geometry, mesh = _geometry(field, kind, d, base_dir)
        return Shape(
            name=name,
            type=kind,
            translate=check_vector(f"{field}.translate", d["translate"]),
            rotate=check_vector(f"{field}.rotate", d["rotate"]),
            scale=check_positive(f"{field}.scale", d["scale"]),
            geometry=geometry,
            mesh=mesh,
            **materials(field, d, mesh),
        )

    def to_dict(self) -> dict[str, Any]:
        # name and type, the type-specific keys, then the common ones in field order
        out: dict[str, Any] = {"name": self.name, "type": self.type}
        out.update((k, _json_value(v)) for k, v in self.geometry)
        out.update(
            (f.name, _json_value(getattr(self, f.name)))
            for f in fields(self)
            if f.name not in ("name", "type", "geometry", "mesh")
            and (self.roughness or f.name != "roughness")
        )
        return out


def _geometry(
    field: str, kind: str, d: Mapping[str, Any], base_dir: Path | None
) -> tuple[tuple, shp.LocalMesh]:
    """The type-specific keys (validated) and the local mesh they describe."""
    if kind == "rectangle":
        size = check_vector(f"{field}.size", d.get("size", [1.0, 1.0]), 2, positive=True)
        return (("size", size),), shp.rectangle(*size)
    if kind == "box":
        size = check_vector(f"{field}.size", d.get("size", [1.0, 1.0, 1.0]), 3, positive=True)
        return (("size", size),), shp.box(*size)
    if kind == "icosphere":
        radius = check_positive(f"{field}.radius", d.get("radius", 1.0))
        sub = check_int(f"{field}.subdivisions", d["subdivisions"], minimum=0)
        if sub > 6:
            raise ValidationError(f"{field}.subdivisions", f"must be <= 6, got {sub}")
        return (("radius", radius), ("subdivisions", sub)), shp.icosphere(radius, sub)
    if kind == "disk":
        radius = check_positive(f"{field}.radius", d.get("radius", 1.0))
        segments = check_int(f"{field}.segments", d["segments"], minimum=3)
        return (("radius", radius), ("segments", segments)), shp.disk(radius, segments)
    return shp.mesh_geometry(field, d, base_dir)


# ---------------------------------------------------------------------- scene
@dataclass(frozen=True)
class Scene:
    """A validated scene (immutable). Build with :func:`load_scene`."""

    name: str
    camera: Camera
    sky: float
    shapes: tuple[Shape, ...]
    offsets: tuple[tuple[str, float], ...] = ()

    @staticmethod
    def from_dict(d: Any, base_dir: Path | None = None) -> Scene:
        _check_keys("", d, ("name", "camera", "sky", "shapes", "offsets"), ("name", "camera", "shapes"))
        name = d["name"]
        if not isinstance(name, str) or not name:
            raise ValidationError("name", f"must be a non-empty string, got {name!r}")
        camera = Camera.from_dict(d["camera"])
        sky = check_positive("sky", d.get("sky", 0.0), allow_zero=True)
        if not isinstance(d["shapes"], list | tuple) or not d["shapes"]:
            raise ValidationError("shapes", f"must be a non-empty list of shapes, got {d['shapes']!r}")
        shapes = tuple(Shape.from_dict(f"shapes[{i}]", s, base_dir) for i, s in enumerate(d["shapes"]))
        seen: dict[str, int] = {}
        for i, s in enumerate(shapes):
            if s.name in seen:
                raise ValidationError(
                    f"shapes[{i}].name", f"duplicate name {s.name!r} (also shapes[{seen[s.name]}])"
                )
            seen[s.name] = i
        scene = Scene(name, camera, sky, shapes)
        return replace(scene, offsets=check_offsets(scene, d.get("offsets", {})))

    def to_dict(self) -> dict[str, Any]:
        """The scene as a JSON-ready dict; ``load_scene(scene.to_dict())`` gives an equal scene."""
        return {
            "name": self.name,
            "camera": self.camera.to_dict(),
            "sky": self.sky,
            "shapes": [s.to_dict() for s in self.shapes],
            **({"offsets": dict(self.offsets)} if self.offsets else {}),
        }

    # -------------------------------------------------------------- parameters
    @property
    def parameters(self) -> tuple[str, ...]:
        """Every parameter name of this scene."""
        names = [f"camera.translate.{a}" for a in AXES] + ["sky.emission"]
        for s in self.shapes:
            names += [f"{s.name}.translate.{a}" for a in AXES] + [f"{s.name}.rotate.{a}" for a in AXES]
            names += [f"{s.name}.scale", f"{s.name}.albedo", f"{s.name}.emission"]
            names += [] if s.roughness is None else [f"{s.name}.roughness"]
            if s.type in ("icosphere", "mesh"):
                names += [f"{s.name}.shape.{k}" for k in range(TERMS)]
        return tuple(names)

    def check_param(self, param: Any) -> str:
        """``param`` if it names a parameter of this scene; one error listing the choices otherwise."""
        if not isinstance(param, str) or param not in self.parameters:
            raise ValidationError(
                "param", f"unknown parameter {param!r}; choose from {', '.join(self.parameters)}"
            )
        return param

    def check_params(self, names: Any) -> tuple[str, ...]:
        """A list or tuple of k >= 1 distinct parameter names, each checked by :meth:`check_param`; one
        ValidationError naming ``param`` and the value otherwise (empty, a repeated name, not a name)."""
        if not isinstance(names, list | tuple) or not names:
            raise ValidationError(
                "param", f"must be a parameter name or a non-empty list of them, got {names!r}"
            )
        repeated = sorted({n for n in names if isinstance(n, str) and names.count(n) > 1})
        if repeated:
            raise ValidationError("param", f"names each parameter once, got {names!r} (repeated: {repeated})")
        return tuple(self.check_param(name) for name in names)

    def shape_index(self, name: str) -> int:
        """Index of the shape called ``name``."""
        return [s.name for s in self.shapes].index(name)


def parameter_names(scene: Scene) -> tuple[str, ...]:
    """Every parameter name of ``scene``: ``scene.parameters`` (the name flatland shares)."""
    return scene.parameters


# ------------------------------------------------------------------- loading
def _builtin_dir():
    return resources.files("sphere3d") / "scenes"


def list_scenes() -> tuple[str, ...]:
    """Names of the built-in scenes (``sphere3d/scenes/*.json``)."""
    return tuple(sorted(p.name[:-5] for p in _builtin_dir().iterdir() if p.name.endswith(".json")))


def reference_path(name: str) -> Path:
    """Where the stored reference derivative image of the built-in scene ``name`` is (package data,
    ``sphere3d/scenes/references/<name>.npz``, written by ``python -m benchmarks.hard_shadow_reference``)."""
    return Path(str(_builtin_dir() / "references" / f"{name}.npz"))


def load_reference(name: str) -> dict[str, Any]:
    """The stored reference derivative image of a built-in scene, as a dict of arrays.

    Central differences with common random numbers, Richardson-extrapolated over two steps
    (truncation $O(h^4)$), with a standard error per pixel: ``derivative``, ``stderr``, the two
    differences ``d_h`` and ``d_h2``, and the settings (``scene``, ``param``, ``h``, ``spp``).
    Shipped with the package, so a tutorial reads it from an installed copy too.

    Raises
    ------
    ValidationError
        If the scene has no stored reference (naming the scenes that have one).
    """
    path = reference_path(str(name))
    if not path.is_file():
        stored = sorted(
            p.name[:-4] for p in (_builtin_dir() / "references").iterdir() if p.name.endswith(".npz")
        )
        raise ValidationError("name", f"no stored reference for {name!r}; stored: {', '.join(stored)}")
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def load_scene(source: Any) -> Scene:
    """A validated :class:`Scene` from a built-in name, a path to a .json file, or a dict.

    Raises
    ------
    ValidationError
        Naming the field and value of the first problem found.
    """
    if isinstance(source, Scene):
        return source
    if isinstance(source, Mapping):
        return Scene.from_dict(check_depth("scene", source))
    if isinstance(source, str | Path):
        text = str(source)
        if isinstance(source, str) and text in list_scenes():
            return Scene.from_dict(read_json(_builtin_dir() / f"{text}.json", "built-in scene"))
        path = Path(source)
        if path.suffix.lower() == ".json":
            return Scene.from_dict(read_json(path, "scene"), base_dir=path.parent.resolve())
        raise ValidationError(
            "scene",
            f"unknown scene {text!r}; built-in scenes: {', '.join(list_scenes())}, or a path to a .json file",
        )
    raise ValidationError(
        "scene", f"must be a scene name, a .json path or a dict, got {type(source).__name__}"
    )
