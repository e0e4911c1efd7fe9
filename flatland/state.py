"""A flatland scene evaluated at one parameter value θ: flat arrays of segments, circles, materials, camera.

:func:`parse_parameter` reads a parameter name (the table of :mod:`flatland.scene`)
into a :class:`Parameter`, and :func:`build_state` is where θ enters: the parameter's
offset ``theta`` is applied to the quantity it names, as a
float (finite differences, plain renders) or a :class:`~flatland.core.dual.Dual`
(``variable(0.0)``, the gradient methods), and every θ-dependent array of the
:class:`SceneState` carries the tangent. Several parameters at once: a tuple of k
parameters with a tuple of k offsets, each applied to what it names in turn; with the
offsets :func:`~flatland.core.dual.variables` ``(k)`` (the seeds e_i) the arrays carry
k tangents, slot i the derivative with respect to parameter i. The ray caster
(:mod:`flatland.tracing`) traces the detached state and re-attaches hits to this one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from flatland.core.dual import Dual, detach, k_of
from flatland.core.validate import ValidationError
from flatland.scene import Camera, Scene, Shape

__all__ = ["Parameter", "SceneState", "build_state", "parse_parameter", "parse_parameters"]


@dataclass(frozen=True)
class Parameter:
    """A parsed parameter name: what θ moves (see the parameter table of :mod:`flatland.scene`)."""

    name: str
    target: str  # shape name or "camera"
    kind: str  # translate, rotate, scale, vertex, emission, albedo
    axis: int = -1  # 0 for x, 1 for y (translate, vertex)
    index: int = -1  # vertex index


def parse_parameter(scene: Scene, name: Any, field: str = "param") -> Parameter:
    """Check ``name`` against ``scene`` and parse it; one ValidationError naming ``field`` otherwise."""
    if not isinstance(name, str):
        raise ValidationError(field, f"must be a parameter name like 'occluder.translate.x', got {name!r}")
    parts = name.split(".")
    axes = {"x": 0, "y": 1}
    shapes = {s.name: s for s in scene.shapes}

    def bad(why: str) -> ValidationError:
        return ValidationError(field, f"unknown parameter {name!r}: {why}")

    target, rest = parts[0], parts[1:]
    if target == "camera":
        if len(rest) == 2 and rest[0] == "translate" and rest[1] in axes:
            return Parameter(name, "camera", "translate", axis=axes[rest[1]])
        if rest == ["rotate"]:
            return Parameter(name, "camera", "rotate")
        raise bad("the camera has translate.x, translate.y and rotate")
    if target not in shapes:
        raise bad(f"no shape {target!r} (shapes: {', '.join(shapes)}; or 'camera')")
    shape = shapes[target]
    if len(rest) == 2 and rest[0] == "translate" and rest[1] in axes:
        return Parameter(name, target, "translate", axis=axes[rest[1]])
    if rest in (["scale"], ["emission"], ["albedo"]):
        return Parameter(name, target, rest[0])
    if rest == ["rotate"]:
        if shape.type == "circle":
            raise bad("a circle does not change when rotated about its centre")
        return Parameter(name, target, "rotate")
    if len(rest) == 3 and rest[0] == "vertex" and rest[2] in axes and rest[1].isdigit():
        k = int(rest[1])
        if shape.type == "circle" or k >= len(shape.points):
            raise bad(f"shape {target!r} has {len(shape.points)} vertices")
        return Parameter(name, target, "vertex", axis=axes[rest[2]], index=k)
    raise bad("use translate.x|y, rotate, scale, vertex.K.x|y, emission or albedo")


def parse_parameters(scene: Scene, names: Any, field: str = "param") -> tuple[Parameter, ...]:
    """A list or tuple of k >= 1 distinct parameter names, each parsed by :func:`parse_parameter`; one
    ValidationError naming ``field`` and the value otherwise (empty, repeated names, not names)."""
    if not isinstance(names, list | tuple) or not names:
        raise ValidationError(field, f"must be a parameter name or a non-empty list of them, got {names!r}")
    repeated = sorted({n for n in names if isinstance(n, str) and names.count(n) > 1})
    if repeated:
        raise ValidationError(field, f"names each parameter once, got {names!r} (repeated: {repeated})")
    return tuple(parse_parameter(scene, name, field) for name in names)


@dataclass(frozen=True)
class SceneState:
    """A scene as flat arrays at one parameter value (Duals where θ enters).

    Primitives are numbered segments first (0..S-1), then circles (S..S+C-1).
    ``vertices`` are the shapes' points (segment endpoints, each once per shape),
    the candidate discontinuities of the boundary method together with circle
    tangent points.
    """

    seg_a: Any  # (S, 2)
    seg_b: Any  # (S, 2)
    circ_c: Any  # (C, 2)
    circ_r: Any  # (C,)
    prim_shape: np.ndarray  # (S + C,) int
    emission: Any  # (S + C,)
    albedo: Any  # (S + C,)
    one_sided: np.ndarray  # (S + C,) bool
    fade: np.ndarray  # (S + C,) float
    vertices: Any  # (V, 2)
    cam_o: Any  # (2,)
    cam_f: Any  # (2,)
    cam_r: Any  # (2,)
    sky: float
    camera: Camera

    @property
    def n_seg(self) -> int:
        return int(np.shape(detach(self.seg_a))[0])

    @property
    def n_circ(self) -> int:
        return int(np.shape(detach(self.circ_r))[0])

    @property
    def differentiable(self) -> bool:
        """True when some array is a Dual (bound with a Dual θ)."""
        return any(isinstance(getattr(self, f.name), Dual) for f in fields(self))

    @property
    def k(self) -> int | None:
        """How many tangents its Duals carry (:func:`~flatland.core.dual.k_of`): None for one (or none)."""
        return k_of(*(getattr(self, f.name) for f in fields(self)))

    def detached(self) -> SceneState:
        """The same geometry with every derivative dropped (for tracing and jump values)."""
        return replace(self, **{f.name: detach(getattr(self, f.name)) for f in fields(self)})

    def emitters(self) -> np.ndarray:
        """Indices of primitives with emission > 0 (at this parameter value)."""
        return np.flatnonzero(detach(self.emission) > 0.0)


def _unit(axis: int) -> np.ndarray:
    """The unit vector along x (0) or y (1)."""
    return np.eye(2)[axis]


def _rotation(points: Any, centre: np.ndarray, angle: Any) -> Any:
    c, s = np.cos(angle), np.sin(angle)
    dx, dy = points[:, 0] - centre[0], points[:, 1] - centre[1]
    return np.stack([centre[0] + c * dx - s * dy, centre[1] + s * dx + c * dy], axis=1)


def _moved_points(shape: Shape, moves: tuple[tuple[Parameter, Any], ...]) -> Any:
    """The shape's points (a circle's centre, as one point) with each parameter of ``moves`` at its
    offset, in turn."""
    pts = np.array([shape.center] if shape.type == "circle" else shape.points, dtype=np.float64)
    for p, theta in moves:
        if p.target == shape.name:
            pts = _move(shape, pts, p, theta)
    return pts


def _move(shape: Shape, pts: Any, p: Parameter, theta: Any) -> Any:
    """``pts`` with the shape's parameter ``p`` at offset ``theta``."""
    if p.kind == "translate":
        return pts + theta * _unit(p.axis)
    if p.kind == "rotate":
        return _rotation(pts, shape.centre(), theta)
    if p.kind == "scale":  # about the centre: a circle's centre stays put
        ctr = shape.centre()
        return ctr + (1.0 + theta) * (pts - ctr)
    if p.kind == "vertex":
        mask = np.zeros_like(pts)
        mask[p.index, p.axis] = 1.0
        return pts + theta * mask
    return pts


def build_state(
    scene: Scene, param: str | Parameter | tuple | list | None = None, theta: Any = 0.0
) -> SceneState:
    """The scene's :class:`SceneState` with parameter ``param`` set to offset ``theta``.

    ``theta`` may be a float (finite differences) or a Dual (``variable(0.0)``, the
    gradient methods); with ``param=None`` every array is plain. A tuple or list of k
    parameters takes a sequence of k offsets, applied in order (e.g. ``variables(k)``:
    the state's Duals then carry k tangents), or one offset for all of them.
    """
    if isinstance(param, tuple | list):
        params = [parse_parameter(scene, q) if isinstance(q, str) else q for q in param]
        offsets = list(theta) if isinstance(theta, tuple | list) else [theta] * len(params)
        if len(offsets) != len(params):
            raise ValueError(
                f"theta: {len(params)} parameters need {len(params)} offsets, got {len(offsets)}"
            )
        moves = tuple(zip(params, offsets, strict=True))
    else:
        p = parse_parameter(scene, param) if isinstance(param, str) else param
        moves = () if p is None else ((p, theta),)
    seg_a, seg_b, seg_shape, seg_fade, seg_one = [], [], [], [], []
    circ_c, circ_r, circ_shape, circ_one = [], [], [], []
    vertices = []
    for k, s in enumerate(scene.shapes):
        pts = _moved_points(s, moves)
        if s.type == "circle":
            radius: Any = s.radius
            for p, theta in moves:
                if p.target == s.name and p.kind == "scale":
                    radius = radius * (1.0 + theta)
            circ_c.append(pts[0])
            circ_r.append(np.stack([radius]))
            circ_shape.append(k)
            circ_one.append(s.one_sided)
            continue
        pairs = np.array(s.segments())
        seg_a.append(pts[pairs[:, 0]])
        seg_b.append(pts[pairs[:, 1]])
        seg_shape += [k] * len(pairs)
        seg_fade += [s.fade] * len(pairs)
        seg_one += [s.one_sided] * len(pairs)
        vertices.append(pts)
    empty2 = np.zeros((0, 2))
    seg_a_all = np.concatenate(seg_a) if seg_a else empty2
    seg_b_all = np.concatenate(seg_b) if seg_b else empty2
    circ_c_all = np.stack(circ_c) if circ_c else empty2
    circ_r_all = np.concatenate(circ_r) if circ_r else np.zeros(0)
    prim_shape = np.array(seg_shape + circ_shape, dtype=np.int64)
    emission: Any = np.array([scene.shapes[k].emission for k in prim_shape])
    albedo: Any = np.array([scene.shapes[k].albedo for k in prim_shape])
    for p, theta in moves:
        if p.kind in ("emission", "albedo"):
            mask = np.array([scene.shapes[k].name == p.target for k in prim_shape], dtype=np.float64)
            if p.kind == "emission":
                emission = emission + theta * mask
            else:
                albedo = albedo + theta * mask
    cam = scene.camera
    o: Any = np.array(cam.position, dtype=np.float64)
    f: Any = np.array(cam.direction, dtype=np.float64)
    for p, theta in moves:
        if p.target == "camera" and p.kind == "translate":
            o = o + theta * _unit(p.axis)
        if p.target == "camera" and p.kind == "rotate":
            angle = math.atan2(detach(f)[1], detach(f)[0]) + theta
            f = np.stack([np.cos(angle), np.sin(angle)])
    r_vec = np.stack([f[1], -f[0]])  # right = forward turned clockwise
    return SceneState(
        seg_a=seg_a_all,
        seg_b=seg_b_all,
        circ_c=circ_c_all,
        circ_r=circ_r_all,
        prim_shape=prim_shape,
        emission=emission,
        albedo=albedo,
        one_sided=np.array(seg_one + circ_one, dtype=bool),
        fade=np.array(seg_fade + [0.0] * len(circ_shape), dtype=np.float64),
        vertices=np.concatenate(vertices) if vertices else empty2,
        cam_o=o,
        cam_f=f,
        cam_r=r_vec,
        sky=float(scene.sky),
        camera=cam,
    )
