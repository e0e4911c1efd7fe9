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

A scene's own ``offsets`` (:mod:`flatland.scene`) are applied first, in their order; a parameter
passed to :func:`build_state` that the scene already offsets gets the sum of both in that slot, so
the state is that of the scene as written at the summed offsets, and a derivative taken at a moved
scene (:func:`moved_scene`) is the derivative at those offsets, for every kind of parameter.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from flatland.core.dual import Dual, detach, k_of
from flatland.core.microfacet import ALPHA_MAX
from flatland.core.validate import ValidationError, check_finite
from flatland.scene import Camera, Scene, Shape

__all__ = [
    "Parameter",
    "SceneState",
    "build_state",
    "check_offsets",
    "moved_scene",
    "parse_parameter",
    "parse_parameters",
    "shape_basis",
]


@dataclass(frozen=True)
class Parameter:
    """A parsed parameter name: what θ moves (see the parameter table of :mod:`flatland.scene`)."""

    name: str
    target: str  # shape name or "camera"
    kind: str  # translate, rotate, scale, vertex, shape, emission, albedo, roughness
    axis: int = -1  # 0 for x, 1 for y (translate, vertex)
    index: int = -1  # vertex index, or shape coefficient index


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
    if rest == ["roughness"]:
        if not shape.glossy:
            raise bad(f"shape {target!r} is diffuse: only a shape with a 'roughness' (glossy) has one")
        return Parameter(name, target, "roughness")
    if rest == ["rotate"]:
        if shape.type == "circle":
            raise bad("a circle does not change when rotated about its centre")
        return Parameter(name, target, "rotate")
    if len(rest) == 3 and rest[0] == "vertex" and rest[2] in axes and rest[1].isdigit():
        k = int(rest[1])
        if shape.type == "circle" or k >= len(shape.points):
            raise bad(f"shape {target!r} has {len(shape.points)} vertices")
        return Parameter(name, target, "vertex", axis=axes[rest[2]], index=k)
    if len(rest) == 2 and rest[0] == "shape" and rest[1].isdigit():
        k, terms = int(rest[1]), shape.shape_terms()
        if k >= terms:
            has = f"shape.0 to shape.{terms - 1}" if terms else "no shape coefficients (polygons have them)"
            raise bad(f"shape {target!r} ({shape.type}, {len(shape.points)} points) has {has}")
        return Parameter(name, target, "shape", index=k)
    raise bad("use translate.x|y, rotate, scale, vertex.K.x|y, shape.K, emission, albedo or roughness")


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
    roughness: Any  # (S + C,) GGX α of glossy primitives, 0.0 for diffuse ones
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

    # the state is frozen: what follows from its fields is computed once (asked for per ray batch)
    @functools.cached_property
    def differentiable(self) -> bool:
        """True when some array is a Dual (bound with a Dual θ)."""
        return any(isinstance(getattr(self, f.name), Dual) for f in fields(self))

    @functools.cached_property
    def k(self) -> int | None:
        """How many tangents its Duals carry (:func:`~flatland.core.dual.k_of`): None for one (or none)."""
        return k_of(*(getattr(self, f.name) for f in fields(self)))

    def detached(self) -> SceneState:
        """The same geometry with every derivative dropped (for tracing and jump values)."""
        return self._detached

    @functools.cached_property
    def _detached(self) -> SceneState:
        return replace(self, **{f.name: detach(getattr(self, f.name)) for f in fields(self)})

    @property
    def glossy(self) -> np.ndarray:
        """Which primitives are glossy (roughness > 0), shape (S + C,) bool."""
        return detach(self.roughness) > 0.0

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


def shape_basis(shape: Shape, k: int) -> np.ndarray:
    r"""The displacement of every vertex per unit of the shape coefficient k: $(p_i - c) B_k(φ_i)$.

    $p_i$ are the polygon's points as loaded, c their mean and $φ_i$ the angle of $p_i - c$;
    $B_0 = 1$, $B_{2m-1} = \cos mφ$, $B_{2m} = \sin mφ$ (the table of :mod:`flatland.scene`). Shape
    (n, 2).
    """
    d = np.array(shape.points, dtype=np.float64) - shape.centre()
    phi = np.arctan2(d[:, 1], d[:, 0])
    order = (k + 1) // 2
    basis = np.ones_like(phi) if k == 0 else np.cos(order * phi) if k % 2 else np.sin(order * phi)
    return d * basis[:, None]


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
    if p.kind == "shape":  # linear in θ: offsets add exactly; θ = 0 adds ±0.0, the points bit for bit
        return pts + theta * shape_basis(shape, p.index)
    return pts


def _moves(scene: Scene, param: Any, theta: Any) -> tuple[tuple[Parameter, Any], ...]:
    """(parameter, offset) pairs to apply in order: the scene's own offsets (a parameter also in
    ``param`` gets the sum in its slot; a plain 0.0 is skipped, the identity), then ``param``'s others."""
    if isinstance(param, tuple | list):
        params = [parse_parameter(scene, q) if isinstance(q, str) else q for q in param]
        offsets = list(theta) if isinstance(theta, tuple | list) else [theta] * len(params)
        if len(offsets) != len(params):
            raise ValueError(
                f"theta: {len(params)} parameters need {len(params)} offsets, got {len(offsets)}"
            )
        given = list(zip(params, offsets, strict=True))
    else:
        p = parse_parameter(scene, param) if isinstance(param, str) else param
        given = [] if p is None else [(p, theta)]
    extra = {p.name: (p, t) for p, t in given}
    moves = []
    for name, base in scene.offsets:
        if name in extra:
            p, t = extra.pop(name)
            moves.append((p, base + t))
        elif base != 0.0:
            moves.append((parse_parameter(scene, name), base))
    return (*moves, *extra.values())


def check_offsets(scene: Scene, offsets: Any, field: str = "offsets") -> tuple[tuple[str, float], ...]:
    """A mapping (or pairs) from parameter names to finite offsets, checked against ``scene``: one
    ValidationError naming ``field`` when a name is unknown or the offsets leave an albedo outside
    [0, 1], an emission below 0, a roughness outside (0, 1] or a scale factor $1 + θ$ at or below 0."""
    pairs = list(offsets.items()) if isinstance(offsets, dict) else offsets
    if not isinstance(pairs, list | tuple):
        raise ValidationError(field, f"must map parameter names to offsets, got {offsets!r}")
    out = []
    for name, value in pairs:
        p = parse_parameter(scene, name, field)
        out.append((p.name, check_finite(f"{field}[{name!r}]", value)))
    for p, theta in ((parse_parameter(scene, n), t) for n, t in out):
        base = scene.shape(p.target) if p.target != "camera" else None
        if p.kind == "albedo" and not 0.0 <= base.albedo + theta <= 1.0:
            raise ValidationError(
                field, f"{p.name} = {theta!r} leaves the albedo {base.albedo + theta!r}, not in [0, 1]"
            )
        if p.kind == "emission" and base.emission + theta < 0.0:
            raise ValidationError(
                field, f"{p.name} = {theta!r} leaves the emission {base.emission + theta!r} < 0"
            )
        if p.kind == "roughness" and not 0.0 < base.roughness + theta <= ALPHA_MAX:
            raise ValidationError(
                field,
                f"{p.name} = {theta!r} leaves the roughness {base.roughness + theta!r}, "
                f"not in (0, {ALPHA_MAX:g}] (0 is a perfect mirror, a delta BSDF: "
                "no integral to reparameterize)",
            )
        if p.kind == "scale" and not 1.0 + theta > 0.0:
            raise ValidationError(field, f"{p.name} = {theta!r} makes the scale factor 1 + θ <= 0")
    return tuple(out)


def moved_scene(scene: Scene, params: Any, theta: Any) -> Scene:
    """``scene`` moved by the offsets ``theta`` of ``params`` (added to the scene's own offsets):
    rendering it renders the scene at those offsets, and differentiating it with respect to
    ``params`` differentiates there (the offsets of :mod:`flatland.scene`)."""
    names = [params] if isinstance(params, str) else list(params)
    values = np.broadcast_to(np.asarray(theta, dtype=np.float64), (len(names),))
    merged = dict(scene.offsets)
    for name, value in zip(names, values, strict=True):
        merged[parse_parameter(scene, name).name] = merged.get(name, 0.0) + float(value)
    return replace(scene, offsets=check_offsets(scene, merged))


def build_state(
    scene: Scene, param: str | Parameter | tuple | list | None = None, theta: Any = 0.0
) -> SceneState:
    """The scene's :class:`SceneState` with parameter ``param`` set to offset ``theta``.

    ``theta`` may be a float (finite differences) or a Dual (``variable(0.0)``, the
    gradient methods); with ``param=None`` every array is plain. A tuple or list of k
    parameters takes a sequence of k offsets, applied in order (e.g. ``variables(k)``:
    the state's Duals then carry k tangents), or one offset for all of them.
    """
    moves = _moves(scene, param, theta)
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
    roughness: Any = np.array([scene.shapes[k].roughness for k in prim_shape], dtype=np.float64)
    for p, theta in moves:
        if p.kind in ("emission", "albedo", "roughness"):
            mask = np.array([scene.shapes[k].name == p.target for k in prim_shape], dtype=np.float64)
            if p.kind == "emission":
                emission = emission + theta * mask
            elif p.kind == "albedo":
                albedo = albedo + theta * mask
            else:  # a diffuse primitive's 0.0 stays 0.0: θ times a mask of 0 (parse_parameter: glossy only)
                roughness = roughness + theta * mask
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
        roughness=roughness,
        one_sided=np.array(seg_one + circ_one, dtype=bool),
        fade=np.array(seg_fade + [0.0] * len(circ_shape), dtype=np.float64),
        vertices=np.concatenate(vertices) if vertices else empty2,
        cam_o=o,
        cam_f=f,
        cam_r=r_vec,
        sky=float(scene.sky),
        camera=cam,
    )
