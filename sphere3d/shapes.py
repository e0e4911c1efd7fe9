"""Triangle meshes of the built-in shapes in object space, OBJ/PLY loading, and the emitter fade.

Every shape is a :class:`LocalMesh`: vertices centred on the origin (the point that
rotation and scale act about), outward (or +z) facing triangles, and per-vertex
coordinates ``uv`` used by the radiance fade of area emitters (theory/probes):

============  ========================================  ==================================
type          geometry                                  fade coordinate
============  ========================================  ==================================
rectangle     ``size`` = [sx, sy] in the z = 0 plane,   $uv = (2x / sx, 2y / sy)$
              normal +z                                 in $[-1, 1]^2$
disk          ``radius``, ``segments`` fan, normal +z   u = 0 at the centre, 1 on
                                                        the rim (exact on the polygon)
box           ``size`` = [sx, sy, sz]                   none
icosphere     ``radius``, ``subdivisions``              none
mesh          OBJ / PLY file or inline arrays           none
============  ========================================  ==================================

A mesh is re-centred (its bounding box's centre moved to the origin, :func:`mesh_geometry`)
when its ``center`` key is true, the default for a file: a model's own origin is arbitrary,
and the scene's ``rotate`` and ``scale`` act about the origin. Inline vertices are kept as
written unless ``center`` is true (they are usually written where the shape belongs).

Every mesh also has unit vertex normals, used for shading when the shape is
``smooth`` (:mod:`sphere3d.scene`): the exact sphere normal at an icosphere's
vertices, +z on rectangles and disks, the file's normals (OBJ ``vn``, PLY
``nx ny nz``) or inline ``normals`` for a mesh, and otherwise the angle-weighted
mean of the adjacent face normals (:func:`vertex_normals`).

The fade multiplies the radiance by a smoothstep $S(t) = t^2(3 - 2t)$ of the distance to
the border divided by ``fade``, so the emitter's own edge is not a discontinuity of
the integrand (it becomes continuous, zero at the edge).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flatland.core.validate import ValidationError, check_bool

__all__ = [
    "FADE_NONE",
    "FADE_RADIAL",
    "FADE_RECTANGLE",
    "LocalMesh",
    "box",
    "check_normals",
    "disk",
    "fade_weight",
    "icosphere",
    "load_mesh_file",
    "mesh_geometry",
    "recentred",
    "rectangle",
    "vertex_normals",
]

FADE_NONE, FADE_RECTANGLE, FADE_RADIAL = 0, 1, 2


@dataclass(frozen=True)
class LocalMesh:
    """A triangle mesh in object space.

    Attributes
    ----------
    vertices : ndarray, shape (V, 3)
    faces : ndarray of int, shape (F, 3)
        Counter-clockwise seen from outside (the face normal points outwards / +z).
    uv : ndarray, shape (V, 2)
        Fade coordinates (see the module table).
    fade_kind : int
        ``FADE_NONE``, ``FADE_RECTANGLE`` or ``FADE_RADIAL``.
    normals : ndarray, shape (V, 3)
        Unit vertex normals for smooth shading (see the module docstring).
    """

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    fade_kind: int
    normals: np.ndarray


def _plus_z(n: int) -> np.ndarray:
    return np.tile([0.0, 0.0, 1.0], (n, 1))


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit vertex normals: the mean of the adjacent faces' unit normals weighted by the corner angles.

    The angle weights (Thürmer and Wüthrich 1998) make the result independent of how a
    face is split into triangles. A vertex whose weighted sum vanishes (no face, or
    faces that cancel) gets the normal of its first adjacent face, else +z.
    """
    tri = vertices[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    out = np.zeros_like(vertices, dtype=np.float64)
    fallback = np.tile([0.0, 0.0, 1.0], (len(vertices), 1))
    for k in range(3):  # the three corners of every face (not a loop over faces)
        a = tri[:, (k + 1) % 3] - tri[:, k]
        b = tri[:, (k + 2) % 3] - tri[:, k]
        cos = np.sum(a * b, axis=1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
        np.add.at(out, faces[:, k], np.arccos(np.clip(cos, -1.0, 1.0))[:, None] * n)
    fallback[faces[::-1].ravel()] = np.repeat(n[::-1], 3, axis=0)  # first adjacent face wins
    length = np.linalg.norm(out, axis=1, keepdims=True)
    ok = length > 1e-12
    return np.where(ok, out / np.where(ok, length, 1.0), fallback)


def rectangle(sx: float, sy: float) -> LocalMesh:
    """Two triangles spanning $[-sx/2, sx/2] × [-sy/2, sy/2]$ at z = 0, normal +z."""
    x, y = 0.5 * sx, 0.5 * sy
    vertices = np.array([[-x, -y, 0.0], [x, -y, 0.0], [x, y, 0.0], [-x, y, 0.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    return LocalMesh(vertices, faces, uv, FADE_RECTANGLE, _plus_z(len(vertices)))


def disk(radius: float, segments: int) -> LocalMesh:
    """A fan of ``segments`` triangles around the centre at z = 0, normal +z."""
    phi = 2.0 * np.pi * np.arange(segments) / segments
    rim = np.stack([radius * np.cos(phi), radius * np.sin(phi), np.zeros(segments)], axis=-1)
    vertices = np.vstack([[0.0, 0.0, 0.0], rim])
    i = np.arange(segments)
    faces = np.stack([np.zeros(segments, dtype=int), 1 + i, 1 + (i + 1) % segments], axis=-1)
    uv = np.zeros((segments + 1, 2))
    uv[1:, 0] = 1.0
    return LocalMesh(vertices, faces, uv, FADE_RADIAL, _plus_z(len(vertices)))


def box(sx: float, sy: float, sz: float) -> LocalMesh:
    """An axis-aligned box centred on the origin, 12 outward-facing triangles."""
    corners = np.array([[x, y, z] for z in (-0.5, 0.5) for y in (-0.5, 0.5) for x in (-0.5, 0.5)])
    vertices = corners * np.array([sx, sy, sz])
    # corner index = 4 z + 2 y + x; two triangles per face, counter-clockwise from outside
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    faces = np.array([tri for a, b, c, d in quads for tri in ((a, b, c), (a, c, d))])
    return LocalMesh(vertices, faces, np.zeros((8, 2)), FADE_NONE, vertex_normals(vertices, faces))


def icosphere(radius: float, subdivisions: int) -> LocalMesh:
    """A subdivided icosahedron with vertices on the sphere of ``radius`` ($20·4^s$ triangles)."""
    g = (1.0 + np.sqrt(5.0)) / 2.0
    v = np.array(
        [[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0], [0, -1, g], [0, 1, g],
         [0, -1, -g], [0, 1, -g], [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]],
        dtype=np.float64,
    )  # fmt: skip
    faces = np.array(
        [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
         [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
         [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    )  # fmt: skip
    v = v / np.linalg.norm(v, axis=1, keepdims=True)
    for _ in range(subdivisions):
        # split every edge at its (projected) midpoint; shared edges share the new vertex
        edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
        unique, inverse = np.unique(edges, axis=0, return_inverse=True)
        mid = v[unique[:, 0]] + v[unique[:, 1]]
        mid /= np.linalg.norm(mid, axis=1, keepdims=True)
        m = len(v) + inverse.reshape(3, -1)  # midpoint index of edges (01, 12, 20) per face
        a, b, c = faces[:, 0], faces[:, 1], faces[:, 2]
        faces = np.concatenate(
            [
                np.stack([a, m[0], m[2]], 1),
                np.stack([b, m[1], m[0]], 1),
                np.stack([c, m[2], m[1]], 1),
                np.stack([m[0], m[1], m[2]], 1),
            ]
        )
        v = np.vstack([v, mid])
    # v is on the unit sphere: the exact sphere normal at each vertex
    return LocalMesh(radius * v, faces, np.zeros((len(v), 2)), FADE_NONE, v.copy())


def inline_mesh(field: str, vertices: Any, faces: Any, normals: Any = None) -> LocalMesh:
    """A mesh from inline vertex, face and (optional) vertex normal lists, validated (errors name ``field``).

    ``normals`` (one nonzero [nx, ny, nz] row per vertex) are normalized; without them the
    vertex normals are :func:`vertex_normals`.
    """
    try:
        v = np.asarray(vertices, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValidationError(f"{field}.vertices", "must be a list of [x, y, z] numbers") from None
    if v.ndim != 2 or v.shape[1] != 3 or len(v) < 3 or not np.all(np.isfinite(v)):
        raise ValidationError(
            f"{field}.vertices", f"must be at least 3 finite [x, y, z] rows, got shape {v.shape}"
        )
    try:
        f = np.asarray(faces)
    except (TypeError, ValueError):
        raise ValidationError(f"{field}.faces", "must be a list of [i, j, k] vertex indices") from None
    if f.ndim != 2 or f.shape[1] != 3 or len(f) < 1 or not np.issubdtype(f.dtype, np.integer):
        raise ValidationError(
            f"{field}.faces", f"must be at least one [i, j, k] row of integers, got shape {f.shape}"
        )
    if f.min() < 0 or f.max() >= len(v):
        raise ValidationError(
            f"{field}.faces", f"indices must lie in [0, {len(v) - 1}], got {f.min()}..{f.max()}"
        )
    tri = v[f]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    if np.any(area2 <= 0.0):
        raise ValidationError(f"{field}.faces", f"triangle {int(np.argmin(area2))} is degenerate (zero area)")
    f = f.astype(np.int64)
    n = vertex_normals(v, f) if normals is None else check_normals(f"{field}.normals", normals, len(v))
    return LocalMesh(v, f, np.zeros((len(v), 2)), FADE_NONE, n)


def check_normals(field: str, normals: Any, count: int) -> np.ndarray:
    """``normals`` as ``count`` unit rows; one ValidationError naming ``field`` if one is bad or zero."""
    try:
        n = np.asarray(normals, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValidationError(field, "must be a list of [nx, ny, nz] numbers") from None
    if n.shape != (count, 3) or not np.all(np.isfinite(n)):
        raise ValidationError(
            field, f"must be {count} finite [nx, ny, nz] rows (one per vertex), got shape {n.shape}"
        )
    length = np.linalg.norm(n, axis=1)
    if np.any(length < 1e-12):
        i = int(np.argmin(length))
        raise ValidationError(field, f"normal {i} has zero length, got {n[i].tolist()}")
    return n / length[:, None]


def load_mesh_file(field: str, path: Path) -> LocalMesh:
    """A triangle mesh from an OBJ or PLY file (parsed by ``trimesh``), as stored (:func:`mesh_geometry`
    re-centres it).

    The file's vertex normals (OBJ ``vn``, PLY ``nx ny nz``) become the mesh's normals
    when it has them for every vertex; a zero one is refused (naming ``field``).
    """
    if path.suffix.lower() not in (".obj", ".ply"):
        raise ValidationError(field, f"must be an .obj or .ply file, got {str(path)!r}")
    if not path.is_file():
        raise ValidationError(field, f"no such file: {str(path)!r}")
    import trimesh

    try:
        mesh = trimesh.load(str(path), process=False)
        if not isinstance(mesh, trimesh.Trimesh):  # several objects: merged, as force="mesh" does
            mesh = trimesh.load(str(path), force="mesh", process=False)
    except Exception as exc:  # trimesh raises many kinds of errors on malformed files
        raise ValidationError(field, f"cannot read {str(path)!r}: {exc}") from None
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))))
    if faces.size == 0:
        raise ValidationError(field, f"{str(path)!r} contains no triangles")
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    # trimesh keeps a file's normals in its cache and computes its own when asked for them otherwise
    stored = mesh._cache.cache.get("vertex_normals") if hasattr(mesh, "_cache") else None
    normals = None if stored is None or np.shape(stored) != vertices.shape else np.array(stored)
    if normals is not None:
        normals = check_normals(f"{field} (vertex normals)", normals, len(vertices))
    return inline_mesh(field, vertices, faces.astype(np.int64), normals)


def _smoothstep(t: Any) -> Any:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def fade_weight(uv: Any, kind: np.ndarray, width: np.ndarray) -> Any:
    """Radiance factor in [0, 1] at fade coordinates ``uv`` (Dual-aware): 0 on the border, 1 inside.

    Parameters
    ----------
    uv : array_like or Dual, shape (..., 2)
        Interpolated fade coordinates of the points.
    kind, width : ndarray, shape (...)
        Fade kind and width per point; width 0 means no fade (factor 1).
    """
    active = width > 0.0
    w = np.where(active, width, 1.0)
    # distance to the border in fade units, per coordinate (theory/probes: no moving emitter edge)
    tu = (1.0 - np.abs(uv[..., 0])) / w
    tv = (1.0 - np.abs(uv[..., 1])) / w
    rect = _smoothstep(tu) * _smoothstep(tv)
    radial = _smoothstep(tu)
    faded = np.where(kind == FADE_RECTANGLE, rect, radial)
    return np.where(active & (kind != FADE_NONE), faded, 1.0 + 0.0 * tu)


def mesh_geometry(field: str, d: Mapping[str, Any], base_dir: Path | None) -> tuple[tuple, LocalMesh]:
    """A ``mesh`` shape's keys (validated, file paths made absolute) and its local mesh.

    The mesh comes from a file (``path``, relative to ``base_dir``) or inline ``vertices``,
    ``faces`` and optional per-vertex ``normals``; bad input raises one ValidationError
    naming ``field``'s key. With ``center`` (default: true for a file, false for inline
    vertices) the mesh is moved so its bounding box's centre is the origin (:func:`recentred`);
    the key is kept in the geometry only when given.
    """
    geometry, mesh = _mesh_source(field, d, base_dir)
    if "center" not in d:
        return geometry, recentred(mesh) if "path" in d else mesh
    center = check_bool(f"{field}.center", d["center"])
    return (*geometry, ("center", center)), recentred(mesh) if center else mesh


def recentred(mesh: LocalMesh) -> LocalMesh:
    """``mesh`` moved so the centre of its bounding box (per axis, the mean of the least and the
    largest coordinate) is the origin."""
    centre = 0.5 * (mesh.vertices.min(axis=0) + mesh.vertices.max(axis=0))
    return LocalMesh(mesh.vertices - centre, mesh.faces, mesh.uv, mesh.fade_kind, mesh.normals)


def _mesh_source(field: str, d: Mapping[str, Any], base_dir: Path | None) -> tuple[tuple, LocalMesh]:
    """The file's or the inline arrays' keys and mesh, as given."""
    if "path" in d:
        if "vertices" in d or "faces" in d:
            raise ValidationError(f"{field}.path", "give either path or vertices/faces, not both")
        if not isinstance(d["path"], str):
            raise ValidationError(f"{field}.path", f"must be a file path string, got {d['path']!r}")
        path = Path(d["path"])
        if not path.is_absolute() and base_dir is not None:
            path = base_dir / path
        path = path.resolve()
        return (("path", str(path)),), load_mesh_file(f"{field}.path", path)
    if "vertices" not in d or "faces" not in d:
        raise ValidationError(f"{field}.path", "a mesh needs a path or both vertices and faces")
    mesh = inline_mesh(field, d["vertices"], d["faces"], d.get("normals"))
    vertices = tuple(tuple(float(x) for x in row) for row in mesh.vertices)
    faces = tuple(tuple(int(i) for i in row) for row in mesh.faces)
    geometry = (("vertices", [list(r) for r in vertices]), ("faces", [list(r) for r in faces]))
    if d.get("normals") is not None:
        geometry += (("normals", [[float(x) for x in row] for row in mesh.normals]),)
    return geometry, mesh
