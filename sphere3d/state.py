"""A scene evaluated at one parameter value θ: world-space triangles, materials, camera, tracer.

:func:`build_state` is where θ enters (theory/architecture, "scene + parameter → θ as a Dual"):
the parameter's offset ``theta`` is applied to its field — a float (finite
differences, plain renders) or a :class:`~flatland.core.dual.Dual` (``variable(0.0)``
for the gradient, taken at θ = 0 as in flatland) —
and every quantity computed from it (vertex positions, the camera origin, albedos,
emissions, the total emitter area) carries the tangent. The tracer is built from
the detached triangles: rays are traced at θ0 and re-attached to these Duals.

A scene's own ``offsets`` (:mod:`sphere3d.offsets`) are applied here too: a parameter the scene
offsets and :func:`build_state` differentiates gets the sum of both in one slot (a translation,
a rotation angle, a scale's factor $1 + θ$, a shape coefficient), so the state is that of the
scene as written at the summed offsets, and a derivative taken at a moved scene
(:func:`moved_scene`) is the derivative at those offsets. Offsets of 0 change nothing, bit for bit.
"""

from __future__ import annotations

import threading
import weakref
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from flatland.core.budget import Term
from flatland.core.dual import Dual, detach
from sphere3d import shapes as shp
from sphere3d.harmonics import deform
from sphere3d.offsets import check_offsets
from sphere3d.sampling import triangle_area
from sphere3d.scene import AXES, Scene
from sphere3d.tracing import make_tracer
from sphere3d.vector import dot, norm
from sphere3d.world import check_world

__all__ = [
    "SCENE_BYTES_PER_TRIANGLE",
    "CameraState",
    "SceneState",
    "build_state",
    "moved_scene",
    "plain_state",
    "scene_term",
]


def _axis_rotation(axis: int, angle: Any) -> Any:
    """Rotation matrix about coordinate axis ``axis`` by ``angle`` (float or Dual)."""
    c, s = np.cos(angle), np.sin(angle)
    one, zero = 1.0 + 0.0 * c, 0.0 * c
    rows = {
        0: [[one, zero, zero], [zero, c, -s], [zero, s, c]],
        1: [[c, zero, s], [zero, one, zero], [-s, zero, c]],
        2: [[c, -s, zero], [s, c, zero], [zero, zero, one]],
    }[axis]
    return np.stack([np.stack(r) for r in rows])


def euler_matrix(angles: Any) -> Any:
    """R = Rz(γ) Ry(β) Rx(α): rotate about x first, then y, then z (radians)."""
    return _axis_rotation(2, angles[2]) @ _axis_rotation(1, angles[1]) @ _axis_rotation(0, angles[0])


@dataclass(frozen=True)
class CameraState:
    """The pinhole camera at θ: origin (maybe a Dual), fixed frame, film mapping.

    Continuous pixel coordinates: x in [0, width) left to right, y in [0, height)
    top to bottom; pixel (row i, column j) has its centre at (j + ½, i + ½). The film
    plane lies at distance 1 along ``forward``; pixels are square.
    """

    origin: Any
    forward: np.ndarray
    right: np.ndarray
    up: np.ndarray
    tan_half: float
    width: int
    height: int
    filter: str

    def directions(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Unit directions through continuous pixel coordinates (x, y) (plain)."""
        sx = (2.0 * x / self.width - 1.0) * self.tan_half
        sy = (1.0 - 2.0 * y / self.height) * self.tan_half * self.height / self.width
        # forward + sx right + sy up, then divided by its length: component by component (the same
        # operations as broadcasting over the last axis, about twice as fast for 3-vectors)
        f, r, u = (np.asarray(v, dtype=np.float64) for v in (self.forward, self.right, self.up))
        d = np.empty((*np.shape(sx), 3))
        for k in range(3):
            np.add(f[k] + sx * r[k], sy * u[k], out=d[..., k])
        length = np.sqrt(np.einsum("...i,...i->...", d, d))
        for k in range(3):
            np.divide(d[..., k], length, out=d[..., k])
        return d

    def film(self, omega: Any) -> tuple[Any, Any]:
        """Continuous pixel coordinates (x, y) where direction ``omega`` meets the film; Dual-aware."""
        cz = dot(omega, self.forward)
        px = dot(omega, self.right) / cz
        py = dot(omega, self.up) / cz
        x = (px / self.tan_half + 1.0) * (0.5 * self.width)
        y = (1.0 - py / (self.tan_half * self.height / self.width)) * (0.5 * self.height)
        return x, y

    def log_jacobian(self, omega: Any) -> Any:
        r"""log of film area per solid angle, $-3 \log \cos θ$ (up to a constant); Dual-aware."""
        return -3.0 * np.log(dot(omega, self.forward))


@dataclass(frozen=True)
class SceneState:
    """Everything the integrator reads, at one θ.

    Attributes
    ----------
    scene : Scene
    param : str, tuple of str or None
        The parameter θ stands for (None: a plain render), or the k parameters of k tangents.
    triangles : Dual or ndarray, shape (T, 3, 3)
        World-space vertices of all triangles, grouped by shape.
    shape_of : ndarray of int, shape (T,)
    uv : ndarray, shape (T, 3, 2)
        Per-vertex fade coordinates; ``fade_kind``, ``fade``: per triangle.
    normals : Dual or ndarray, shape (T, 3, 3)
        World-space unit vertex normals of every triangle's corners (rotating with the shape).
    smooth : ndarray of bool, shape (T,)
        Triangles of smooth shapes, shaded with the interpolated ``normals``.
    albedo, emission : Dual or ndarray, shape (S,)
        Per shape. ``sky``: the environment radiance.
    roughness : Dual or ndarray, shape (S,)
        GGX α of the glossy shapes (:mod:`sphere3d.glossy`), 0 for diffuse ones; ``glossy`` (bool,
        shape (S,)) marks the glossy ones.
    albedo_varies : ndarray of bool, shape (S,)
        The shapes whose albedo is the parameter: a method must not skip them where their
        albedo is 0 at θ0 (its derivative need not be).
    sky_varies : bool
        The sky's radiance is the parameter (likewise where it is 0 at θ0).
    emitters : ndarray of int
        Triangles that emit (emission > 0, or the emission is the parameter).
    emitter_area : Dual or float
        Their total area (the emitter sampling density is 1 / emitter_area).
    camera : CameraState
    tracer : EmbreeTracer or BruteForceTracer
        Built on the detached triangles.
    epsilon : float
        Ray offset against self-intersection (scene-size relative).
    corners : ndarray of int, shape (T, 3), optional
        Each triangle corner's vertex, numbered across the shapes: corners with one number are
        copies of one world-space vertex, so their positions are bit-equal (the weld of
        :func:`sphere3d.boundary.edges.mesh_edges` then sorts vertices, not corners).
    """

    scene: Scene
    param: str | tuple[str, ...] | None
    triangles: Any
    shape_of: np.ndarray
    uv: np.ndarray
    fade_kind: np.ndarray
    fade: np.ndarray
    normals: Any
    smooth: np.ndarray
    albedo: Any
    emission: Any
    sky: Any
    albedo_varies: np.ndarray
    sky_varies: bool
    emitters: np.ndarray
    emitter_area: Any
    camera: CameraState
    tracer: Any
    epsilon: float
    roughness: Any = None
    glossy: np.ndarray | None = None
    corners: np.ndarray | None = None

    @property
    def dual(self) -> bool:
        """True if the state carries θ-tangents."""
        return isinstance(self.triangles, Dual)

    @property
    def k(self) -> int | None:
        """How many tangents its Duals carry, one per parameter (None: one, or none)."""
        return self.triangles.k if isinstance(self.triangles, Dual) else None

    def detached(self) -> SceneState:
        """The same state without tangents (values unchanged), for rows whose tangents are known to be 0."""
        plain = {
            f: detach(getattr(self, f))
            for f in ("triangles", "normals", "albedo", "emission", "sky", "roughness")
        }
        camera = replace(self.camera, origin=detach(self.camera.origin))
        return replace(self, **plain, emitter_area=detach(self.emitter_area), camera=camera)

    def emitted(self, triangle: np.ndarray, b1: Any, b2: Any) -> Any:
        """Front-side radiance at barycentrics (b1, b2) of ``triangle``: emission × border fade."""
        emission = self.emission[self.shape_of[triangle]]
        if np.shape(b1) == np.shape(triangle) and not np.any(
            (self.fade[triangle] > 0.0) & (self.fade_kind[triangle] != shp.FADE_NONE)
        ):
            return emission  # no border fade on these triangles: the factor is exactly 1
        uv = self.uv[triangle]
        b1, b2 = b1[..., None], b2[..., None]
        point_uv = (1.0 - b1 - b2) * uv[..., 0, :] + b1 * uv[..., 1, :] + b2 * uv[..., 2, :]
        fade = shp.fade_weight(point_uv, self.fade_kind[triangle], self.fade[triangle])
        return emission * fade

    def shading_normals(self, triangle: np.ndarray, b1: Any, b2: Any, geometric: Any) -> Any:
        """Unit shading normals at barycentrics (b1, b2) of ``triangle``; Dual-aware.

        On smooth shapes the vertex normals interpolated with the hit's barycentrics and
        normalized (Phong 1975): they carry θ-tangents from the sliding barycentrics and
        the rotating vertex normals, as positions do. Elsewhere, and where the
        interpolated vector vanishes, the ``geometric`` (face) normal itself is returned.
        """
        smooth = self.smooth[triangle]
        if not smooth.any():
            return geometric
        s = np.flatnonzero(smooth)
        n = self.normals[triangle[s]]
        w1, w2 = b1[s][..., None], b2[s][..., None]
        mixed = (1.0 - w1 - w2) * n[..., 0, :] + w1 * n[..., 1, :] + w2 * n[..., 2, :]
        length = norm(mixed)
        ok = detach(length) > 1e-9
        unit = mixed / np.where(ok, length, 1.0)[..., None]
        out = geometric * 1.0  # a copy, Dual or plain like the geometric normals
        out[s] = np.where(ok[:, None], unit, geometric[s])
        return out


SCENE_BYTES_PER_TRIANGLE = 2048
"""Memory model of a render's scene states and their per-state tables, bytes per triangle: the plain
and the differentiated state (world triangles, normals, Dual tangents), the mesh edges, the edge trees
and the film corners peak at 1.37 kB per triangle (numpy allocations, tracemalloc, hard_shadow's
occluder at 81 924 and at 327 684 triangles alike), Embree's hierarchy besides; all O(T)."""


def scene_term(scene: Scene) -> Term:
    """The scene's share of a request (:class:`~flatland.core.budget.Term`): its states' tables,
    :data:`SCENE_BYTES_PER_TRIANGLE` per triangle, held for the whole call; named ``shapes``, with the
    scene's triangle count, when it alone is too large."""
    triangles = sum(len(shape.mesh.faces) for shape in scene.shapes)
    what = "triangles in the scene"
    return Term(
        "shapes", triangles, what, "its states' per-triangle tables", SCENE_BYTES_PER_TRIANGLE * triangles
    )


_PLAIN: dict[tuple, tuple[weakref.ref, SceneState]] = {}
_PLAIN_LOCK = threading.Lock()


def _last_plain(scene: Scene, param: str | None, tracer: str) -> SceneState | None:
    with _PLAIN_LOCK:
        hit = _PLAIN.get((id(scene), param, tracer))
    return hit[1] if hit is not None and hit[0]() is scene else None


def plain_state(scene: Scene, param: str | None = None, tracer: str = "embree") -> SceneState:
    """``build_state(scene, param, 0.0, tracer)``, the last one built kept while its scene lives.

    A gradient method asks for the state at θ0 more than once (the boundary method's memory model,
    its edges, its film term), and the gradient's Dual state has the same detached triangles:
    :func:`build_state` takes this state's tracer for it instead of building the same one again.
    One state is kept (the last asked for), so memory holds at most one scene's extra state.
    """
    state = _last_plain(scene, param, tracer)
    if state is None:
        state = build_state(scene, param, 0.0, tracer)
        key = (id(scene), param, tracer)
        with _PLAIN_LOCK:
            _PLAIN.clear()
            _PLAIN[key] = (weakref.ref(scene, lambda _, cache=_PLAIN: cache.pop(key, None)), state)
    return state


def _offset(values: tuple[float, ...], offsets: dict[int | None, Any]) -> Any:
    """``values`` as a vector with ``offsets[i]`` added to component i (none: the plain vector)."""
    if not offsets:
        return np.array(values)
    return np.stack([float(v) + offsets[i] if i in offsets else float(v) for i, v in enumerate(values)])


def _bind(scene: Scene, param: Any, theta: Any) -> dict[tuple[str, str], dict[int | None, Any]]:
    """Each parameter's offset by what it moves: (owner, kind) -> {axis or coefficient (None: neither):
    offset}. ``param`` is one name (offset ``theta``), None, or a tuple or list of k names with a
    sequence of k offsets (or one offset for all of them). The scene's own offsets come first: a
    parameter it offsets gets the sum in its slot; a plain offset of 0.0 is skipped (the identity)."""
    names = tuple(param) if isinstance(param, tuple | list) else (() if param is None else (param,))
    offsets = list(theta) if isinstance(theta, tuple | list) else [theta] * len(names)
    if len(offsets) != len(names):
        raise ValueError(f"theta: {len(names)} parameters need {len(names)} offsets, got {len(offsets)}")
    given = dict(zip((scene.check_param(name) for name in names), offsets, strict=True))
    moves = [(name, base + given.pop(name) if name in given else base) for name, base in scene.offsets]
    bound: dict[tuple[str, str], dict[int | None, Any]] = {}
    for name, offset in [*moves, *given.items()]:
        if isinstance(offset, float) and offset == 0.0 and name not in names:
            continue
        owner, _, rest = name.partition(".")
        kind, _, axis_name = rest.partition(".")
        slot = int(axis_name) if kind == "shape" else AXES.index(axis_name) if axis_name else None
        bound.setdefault((owner, kind), {})[slot] = offset
    return bound


def moved_scene(scene: Scene, params: str | list[str] | tuple[str, ...], theta: Any) -> Scene:
    """``scene`` moved by the offsets ``theta`` of ``params`` (added to the scene's own offsets): rendering
    it renders the scene at those offsets, and differentiating it with respect to ``params``
    differentiates there. One ValidationError for an unknown name or an offset leaving the scene invalid."""
    names = [params] if isinstance(params, str) else list(params)
    values = np.broadcast_to(np.asarray(theta, dtype=np.float64), (len(names),))
    merged = dict(scene.offsets)
    for name, value in zip(names, values, strict=True):
        merged[name] = merged.get(name, 0.0) + float(value)
    return replace(scene, offsets=check_offsets(scene, merged))


def build_state(
    scene: Scene, param: str | tuple | list | None = None, theta: Any = 0.0, tracer: str = "embree"
) -> SceneState:
    """The :class:`SceneState` of ``scene`` with ``param`` offset by ``theta`` (see module docstring).

    ``param`` may be a tuple or list of k names with a sequence of k offsets, each applied to what it
    names (``variables(k)``: the state's Duals carry k tangents, slot i parameter i's).
    """
    bound = _bind(scene, param, theta)
    varies = _bind(replace(scene, offsets=()), param, theta)  # what the parameters themselves move
    param = tuple(param) if isinstance(param, list) else param
    offsets = list(theta) if isinstance(theta, tuple | list) else [theta]
    k = next((t.k for t in offsets if isinstance(t, Dual)), None)  # None: one tangent (or plain)

    triangles, shape_of, uv, fade_kind, fade, albedo, emission = [], [], [], [], [], [], []
    normals, smooth, roughness, corners, first_vertex = [], [], [], [], 0
    for index, s in enumerate(scene.shapes):
        mine = {kind: offs for (owner, kind), offs in bound.items() if owner == s.name}
        translate = _offset(s.translate, mine.get("translate", {}))
        rotate = _offset(s.rotate, mine.get("rotate", {}))
        scale = s.scale * (1.0 + mine["scale"][None]) if "scale" in mine else s.scale
        # world = translate + R (scale · local): rotation and scale act about the centre
        rotation_t = np.swapaxes(euler_matrix(rotate), -1, -2)
        local, local_normals = deform(s.mesh.vertices, s.mesh.normals, mine.get("shape", {}))
        world = translate + (scale * local) @ rotation_t
        triangles.append(world[s.mesh.faces])
        corners.append(s.mesh.faces + first_vertex)  # every corner of one vertex: world[that vertex]
        first_vertex += len(s.mesh.vertices)
        normals.append((local_normals @ rotation_t)[s.mesh.faces])  # a uniform scale: still unit
        smooth.append(np.full(len(s.mesh.faces), s.smooth))
        n = len(s.mesh.faces)
        shape_of.append(np.full(n, index))
        uv.append(s.mesh.uv[s.mesh.faces])
        fade_kind.append(np.full(n, s.mesh.fade_kind))
        fade.append(np.full(n, s.fade))
        albedo.append(s.albedo + mine["albedo"][None] if "albedo" in mine else s.albedo)
        emission.append(s.emission + mine["emission"][None] if "emission" in mine else s.emission)
        rough = s.roughness or 0.0  # 0: a diffuse shape
        roughness.append(rough + mine["roughness"][None] if "roughness" in mine else rough)

    triangles = np.concatenate(triangles)
    normals = np.concatenate(normals)
    shape_of = np.concatenate(shape_of)
    albedo = np.stack(albedo)
    emission = np.stack(emission)
    roughness = np.stack(roughness)
    sky = (
        scene.sky + bound[("sky", "emission")][None]
        if ("sky", "emission") in bound
        else np.float64(scene.sky)
    )
    dual = any(isinstance(t, Dual) for t in offsets)
    if dual:
        # one code path: with a Dual θ every scene quantity is a Dual (most with zero tangent)
        triangles, normals, albedo, emission, sky, roughness = (
            x if isinstance(x, Dual) else Dual(x, None, k)
            for x in (triangles, normals, albedo, emission, sky, roughness)
        )

    emitting = [i for i, s in enumerate(scene.shapes) if s.emission > 0.0 or (s.name, "emission") in bound]
    emitters = np.flatnonzero(np.isin(shape_of, emitting))
    et = triangles[emitters]
    emitter_area = np.sum(triangle_area(et[:, 0], et[:, 1], et[:, 2])) if len(emitters) else 0.0

    cam = scene.camera
    forward, right, up = cam.frame()
    origin = _offset(cam.position, bound.get(("camera", "translate"), {}))
    if dual and not isinstance(origin, Dual):
        origin = Dual(origin, None, k)
    camera = CameraState(
        origin, forward, right, up, float(np.tan(0.5 * cam.fov)), cam.width, cam.height, cam.filter
    )

    plain = np.asarray(detach(triangles))
    origin0 = np.asarray(detach(origin), dtype=np.float64)
    kept = _last_plain(scene, param, tracer)
    if kept is not None and _same_geometry(kept, plain, origin0):
        # a Dual state at θ0: the kept state's geometry, checked when it was built, and its tracer
        epsilon, traced = kept.epsilon, kept.tracer
    else:
        traced = _tracer(scene, param, plain, shape_of, tracer)
        check_world(scene, param, theta, plain, shape_of, origin0)
        # per coordinate over its own strided row: numpy reduces axis 0 of an (n, 3) array element by element
        extent = float(max(np.ptp(column) for column in plain.reshape(-1, 3).T))
        extent = max(extent, float(np.max(np.abs(origin0 - plain.reshape(-1, 3).mean(axis=0)))))
        epsilon = 1e-4 * max(extent, 1e-3)
    return SceneState(
        scene=scene,
        param=param,
        triangles=triangles,
        shape_of=shape_of,
        uv=np.concatenate(uv),
        fade_kind=np.concatenate(fade_kind),
        fade=np.concatenate(fade),
        normals=normals,
        smooth=np.concatenate(smooth),
        albedo=albedo,
        emission=emission,
        sky=sky,
        albedo_varies=np.array([(s.name, "albedo") in varies for s in scene.shapes]),
        sky_varies=("sky", "emission") in varies,
        emitters=emitters,
        emitter_area=emitter_area,
        camera=camera,
        tracer=traced,
        epsilon=epsilon,
        roughness=roughness,
        glossy=np.array([s.roughness is not None for s in scene.shapes]),
        corners=np.concatenate(corners).astype(np.int64, copy=False),
    )


def _same_geometry(kept: SceneState, plain: np.ndarray, origin: np.ndarray) -> bool:
    """Whether ``kept`` (a plain state) has these detached triangles and camera position, bit for bit."""
    return np.array_equal(
        np.asarray(detach(kept.camera.origin), dtype=np.float64), origin
    ) and np.array_equal(np.asarray(detach(kept.triangles)), plain)


def _tracer(scene: Scene, param: str | None, plain: np.ndarray, shape_of: np.ndarray, backend: str) -> Any:
    """The tracer of :func:`plain_state`'s kept state where its triangles are these (a Dual state at θ0,
    a finite difference at 0), else a new one."""
    kept = _last_plain(scene, param, backend)
    if kept is not None and np.array_equal(np.asarray(detach(kept.triangles)), plain):
        return kept.tracer
    return make_tracer(plain, shape_of, backend)
