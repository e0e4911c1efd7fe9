"""The irradiance at a point under the sky, or under a square light, with a black triangle (or a black
convex mesh) above it: Lambert's polygon formula for the projected solid angle, on Duals so that its
θ-derivative comes with it."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core.dual import detach, tangent, variable
from flatland.core.validate import ValidationError
from sphere3d.closed_form.convex import mesh_vertices
from sphere3d.closed_form.film import triangle_vertices
from sphere3d.closed_form.junction import clip_convex
from sphere3d.scene import check_vector, load_scene

__all__ = [
    "Flux",
    "boundary_flux",
    "occluded_light_irradiance",
    "occluded_sky_irradiance",
    "polygon_irradiance",
    "projected_solid_angle",
]


# ------------------------------------------------------------ Lambert's formula
def projected_solid_angle(point: Any, normal: Any, vertices: Any) -> Any:
    r"""$Φ = ∫_{Ω(T)} n·ω\, dω$, the projected solid angle of a polygon above the horizon (Lambert 1760).

    With $u_i$ the unit directions from the point to the vertices, the irradiance vector
    of the cone over the polygon is $½ Σ γ_i m_i$ (Lambert; Arvo 1995, "Applications of
    irradiance tensors"): each edge spans with the point a plane of unit normal $m_i$ and
    subtends the great arc $u_i → u_{i+1}$ of angle $γ_i$, and by Stokes' theorem on the
    sphere the cosine-weighted solid angle is the sum of those arcs' contributions:

        $Φ = ½ Σ_i γ_i n·m_i$,    $γ_i = \mathrm{atan2}(|u_i × u_{i+1}|, u_i·u_{i+1})$,
        $m_i = (u_i × u_{i+1}) / |u_i × u_{i+1}|$.

    The sum is positive when the vertices wind counter-clockwise about n (seen from
    the tip of n); the absolute value is returned. Dual-aware in all arguments.

    Parameters
    ----------
    point, normal : array_like or Dual, shape (3,)
        The shading point and its unit normal.
    vertices : array_like or Dual, shape (V, 3)

    Raises
    ------
    ValidationError
        If a vertex is not strictly above the horizon ($n·(v - x) ≤ 0$): the formula needs
        the polygon clipped there, which is not implemented.
    """
    d = vertices - point
    height = d @ normal
    if not np.all(np.asarray(detach(height)) > 0.0):
        raise ValidationError(
            "vertices",
            f"must lie strictly above the horizon of the point, got heights {np.asarray(detach(height))}",
        )
    u = d / np.linalg.norm(d, axis=-1)[:, None]
    v = u[np.roll(np.arange(len(u)), -1)]
    c = np.cross(u, v)
    sine = np.linalg.norm(c, axis=-1)
    gamma = np.arctan2(sine, np.sum(u * v, axis=-1))  # the arc's angle, accurate near 0 and π
    # a zero-length edge (two vertices in one direction) subtends no arc: γ = 0, no term (not 0/0)
    safe = np.where(np.asarray(detach(sine)) > 0.0, sine, 1.0)
    return np.abs(0.5 * np.sum(gamma * (c @ normal) / safe))


def polygon_irradiance(point: Any, normal: Any, vertices: Any, radiance: Any) -> Any:
    """Irradiance from a uniform one-sided polygonal emitter: $E = L Φ$ if its front faces the point, else 0.

    The front side is the one its normal $(v1 - v0) × (v2 - v0)$ points to (as
    :mod:`sphere3d.shapes` orients emitters); Φ from :func:`projected_solid_angle`. Dual-aware.
    """
    m = np.cross(vertices[1] - vertices[0], vertices[2] - vertices[0])
    facing = float(np.asarray(detach(np.sum(m * (point - vertices[0]))))) > 0.0
    return radiance * projected_solid_angle(point, normal, vertices) * facing


def occluded_sky_irradiance(
    scene: Any, point: Any, normal: Any, param: str | None = None, theta: float = 0.0
) -> tuple[float, float]:
    r"""$E = sky (π - Φ)$ at a point under a constant sky with the scene's black triangle above it,
    or one black convex mesh, and dE/dθ.

    The open sky gives $∫_H L \cos θ\, dω = π L$; the triangle (black, so nothing of it adds
    light) removes $L Φ(T)$; a convex mesh removes the sum over its faces turned towards the point,
    whose images from it tile the mesh's (:func:`_facing`). Returns (value, derivative) at the
    parameter offset ``theta``; the derivative flows through Lambert's formula with a Dual θ
    (derivative 0 without ``param``). The shape must lie wholly above the point's horizon.
    """
    scene = load_scene(scene)
    point = np.array(check_vector("point", point))
    normal = np.array(check_vector("normal", normal))
    length = float(np.linalg.norm(normal))
    if length == 0.0:
        raise ValidationError("normal", f"must not be zero, got {list(normal)}")
    theta = float(check_vector("theta", [theta], 1)[0])
    dual = variable(theta) if param is not None else theta
    if len(scene.shapes) == 1 and len(scene.shapes[0].mesh.faces) > 1:  # a convex mesh: its facing faces
        s = scene.shapes[0]
        if s.albedo != 0.0 or s.emission != 0.0:
            raise ValidationError(
                "scene.shapes[0]", f"must be black (albedo 0, emission 0), got {s.albedo!r}"
            )
        v = mesh_vertices(scene, param, dual)
        hidden = sum(
            projected_solid_angle(point, normal / length, v[face])
            for face in _facing(np.asarray(detach(v)), s.mesh.faces, point)
        )
    else:
        hidden = projected_solid_angle(point, normal / length, triangle_vertices(scene, param, dual))
    e = scene.sky * (np.pi - hidden)
    return float(np.asarray(detach(e))), float(np.asarray(tangent(e))) if param is not None else 0.0


def occluded_light_irradiance(
    scene: Any, param: str | None = None, eye: float = 0.0, theta: float = 0.0
) -> tuple[float, float]:
    r"""E and dE/dθ at the origin (normal +z) under the square light of
    :func:`~sphere3d.closed_form.light_triangle_scene` with its black triangle ``tri`` in between, or
    with one black convex mesh in its place (its faces turned towards the eye, whose shadows tile the
    mesh's: each clipped and subtracted alike).

    Seen from the origin the triangle hides the part of the light inside its shadow on the light's
    plane z = H: the triangle's vertices projected from the origin, $v H / v_z$, clipped by the
    light's square (Sutherland-Hodgman on Duals, :func:`~sphere3d.closed_form.clip_convex`; convex by
    convex), so $E = L (Φ(\mathrm{light}) - Φ(\mathrm{hidden}))$ by Lambert's formula
    (:func:`projected_solid_angle`). Every crossing of a triangle edge with the light's border moves
    with θ on the Duals: the derivative carries the shadow edge's motion across the light and along
    its border. Returns (value, derivative), the derivative 0 without ``param``.

    ``eye``: the height above the origin from which the visibility is seen, the cosine and the solid
    angle staying at the origin (the renderer's shadow rays start ``state.epsilon`` along the normal:
    pass it to compare at that order; the shadow is then projected from (0, 0, eye)). ``theta``: the
    parameter's offset (value and derivative there).
    """
    scene = load_scene(scene)
    names = sorted(s.name for s in scene.shapes)
    if len(names) != 2 or "light" not in names:
        raise ValidationError("scene.shapes", f"must be the shape 'light' and one occluder, got {names}")
    light = next(s for s in scene.shapes if s.name == "light")
    height = float(light.translate[2])
    half = 0.5 * float(dict(light.geometry)["size"][0]) * light.scale
    square = np.array([[-half, -half], [half, -half], [half, half], [-half, half]])
    whole = scene.to_dict()
    alone = load_scene({**whole, "shapes": [s for s in whole["shapes"] if s["name"] != "light"]})
    v = mesh_vertices(alone, param, variable(theta) if param is not None else 0.0)
    z = np.asarray(detach(v))[:, 2]
    if not np.all((z > eye) & (z < height)):
        raise ValidationError(
            f"scene.shapes[{alone.shapes[0].name}]",
            f"must lie between the origin and the light, got heights {z}",
        )
    scale = (height - eye) / (v[:, 2] - eye)  # each vertex's shadow on the light's plane, seen from the eye
    origin, up = np.zeros(3), np.array([0.0, 0.0, 1.0])
    e = light.emission * projected_solid_angle(origin, up, np.column_stack([square, np.full(4, height)]))
    for face in _facing(np.asarray(detach(v)), alone.shapes[0].mesh.faces, np.array([0.0, 0.0, eye])):
        hidden = clip_convex([(v[k, 0] * scale[k], v[k, 1] * scale[k]) for k in face], square)
        if hidden:
            lift = [np.stack([x, y, 0.0 * x + height]) for x, y in hidden]
            e = e - light.emission * projected_solid_angle(origin, up, np.stack(lift))
    value = float(np.asarray(detach(e)))
    return value, float(np.asarray(tangent(e))) if param is not None and hasattr(e, "tangent") else 0.0


@dataclass(frozen=True)
class Flux:
    r"""The boundary term of dE/dθ under the sky, $-L ∮ (n·ω) (\dot ω·m) dl$ (``net``, which is
    Lambert's derivative), and its gross flux $L ∮ |(n·ω) (\dot ω·m)| dl$ (``gross``): how much
    moving boundary a method must carry, the scale its error is measured against where the net
    derivative is a small difference of large parts (a sideways turn of a small triangle)."""

    net: float
    gross: float


def boundary_flux(
    scene: Any,
    point: Any,
    normal: Any,
    param: str,
    nodes: int = 48,
    radiance: float | None = None,
    window: Callable[[np.ndarray], np.ndarray] | None = None,
) -> Flux:
    r""":class:`Flux` of the scene's black triangle (or convex mesh: the edges of its outline, between the
    faces turned towards the point and the others) seen from ``point`` (normal ``normal``) under ``param``.

    Reynolds transport on the sphere of directions: the triangle's image Ω(T) is bounded by the
    great arcs of its edges; at the direction $ω(s) = P(s)/|P(s)|$ of the edge point
    $P(s) = A + s (B - A) - x$ (fixed s, Dual vertices) the boundary moves along the arc's outward
    normal m (pointing away from the third vertex) at $\dot ω·m$, and $dΦ/dθ = ∮ (n·ω) (\dot ω·m) dl$,
    $dl = |dω/ds| ds$, $dω/ds = (I - ω ω^T)(B - A)/|P|$. Each edge by ``nodes``-point Gauss–Legendre
    quadrature (the integrand is smooth in s; the sum agrees with Lambert's formula's derivative to
    rounding, tests/sphere3d/test_closed_forms.py).

    ``radiance``: behind the triangle instead of the scene's sky; ``window(ω)`` (bool per unit direction
    (nodes, 3)): where it is (a light's extent: the integrand then jumps inside an edge, and the
    quadrature is a scale, not a derivative to rounding).
    """
    scene = load_scene(scene)
    radiance = scene.sky if radiance is None else radiance
    x = np.array(check_vector("point", point))
    n = np.array(check_vector("normal", normal))
    n = n / np.linalg.norm(n)
    if len(scene.shapes) == 1 and len(scene.shapes[0].mesh.faces) > 1:  # a convex mesh: its outline
        v = mesh_vertices(scene, param, variable(0.0)) - x
        edges = _outline(_facing(np.asarray(detach(v)) + x, scene.shapes[0].mesh.faces, x))
    else:
        v, edges = triangle_vertices(scene, param, variable(0.0)) - x, [(0, 1, 2), (1, 2, 0), (2, 0, 1)]
    s, w = np.polynomial.legendre.leggauss(nodes)
    s, w = 0.5 * (s + 1.0), 0.5 * w
    net = gross = 0.0
    for i, j, k in edges:  # the outline's edges (a dozen, not a loop over samples)
        a, b, c = v[i], v[j], v[k]
        m = np.cross(np.asarray(detach(a)), np.asarray(detach(b)))
        m = m / np.linalg.norm(m)
        m = -m if m @ np.asarray(detach(c)) > 0.0 else m  # outward: away from the third vertex
        p = a[None, :] + s[:, None] * (b - a)[None, :]  # (nodes, 3) Dual
        omega = p / np.linalg.norm(p, axis=-1)[:, None]
        o = np.asarray(detach(omega))
        d = np.asarray(detach(b - a))
        dl = np.linalg.norm(d - o * (o @ d)[:, None], axis=1) / np.linalg.norm(np.asarray(detach(p)), axis=1)
        density = (o @ n) * (np.asarray(tangent(omega)) @ m) * dl
        if window is not None:
            density = np.where(window(o), density, 0.0)
        net += float(np.sum(w * density))
        gross += float(np.sum(w * np.abs(density)))
    return Flux(-radiance * net, radiance * gross)


def _outline(faces: np.ndarray) -> list[tuple[int, int, int]]:
    """The edges (a, b) of the region the ``faces`` (F, 3) cover that belong to one of them only (the
    outline of a convex mesh's faces turned towards a point), each with its face's third vertex."""
    ends = np.concatenate([faces[:, [0, 1, 2]], faces[:, [1, 2, 0]], faces[:, [2, 0, 1]]])  # (a, b, third)
    key = np.sort(ends[:, :2], axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return [tuple(int(i) for i in row) for row in ends[counts[inverse.ravel()] == 1]]


def _facing(v: np.ndarray, faces: np.ndarray, eye: np.ndarray) -> np.ndarray:
    """The faces (a triangle's only one) of a convex mesh turned towards ``eye``: outward normal (away
    from the vertices' mean) · (V - eye) < 0."""
    if len(faces) == 1:
        return faces
    tri = v[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    outward = np.sign(np.sum(normal * (tri.mean(axis=1) - v.mean(axis=0)), axis=1))
    return faces[np.sum(outward[:, None] * normal * (tri[:, 0] - eye), axis=1) < 0.0]
