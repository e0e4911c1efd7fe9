"""The camera image of a black triangle under the sky: the pixel filter integrated over the
projected triangle (Green's theorem) and its derivative (Reynolds transport of the boundary)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import special

from flatland.core.dual import detach, tangent, variable
from flatland.core.validate import ValidationError, check_choice
from sphere3d.sampling import FILTERS, GAUSSIAN_RADIUS, GAUSSIAN_SIGMA
from sphere3d.scene import AXES, Camera, Scene, check_vector, load_scene

__all__ = [
    "QUADRATURE_NODES",
    "TriangleImage",
    "filter_cdf_1d",
    "filter_kinks",
    "filter_profile_1d",
    "polygon_filter_derivative",
    "polygon_filter_integral",
    "project",
    "triangle_image",
    "triangle_vertices",
]

QUADRATURE_NODES = {"box": 2, "tent": 4, "gaussian": 16}
"""Gauss–Legendre nodes per smooth piece of an edge. Between the kinks of the filter the
edge integrands are polynomials in the edge parameter s (box: degree 1, tent: degree 3,
for the value and the derivative alike), which n nodes integrate exactly up to degree
$2n - 1$; the gaussian's pieces are entire functions of s, for which 24 nodes on pieces at
most 1.5 px = 3σ long leave a relative error below 1e-14 (test_closed_form.py test03)."""

# the truncated gaussian profile k₁(x) = (g(x) - g(R)) / Z on |x| <= R, g(x) = exp(-x²/2σ²):
# Z = ∫_{-R}^{R} (g - g(R)) dx = σ√(2π) (2Φ(R/σ) - 1) - 2 R g(R)       (Φ the normal CDF)
_SIGMA, _RADIUS = GAUSSIAN_SIGMA, GAUSSIAN_RADIUS
_G_R = math.exp(-0.5 * (_RADIUS / _SIGMA) ** 2)
_PHI_LOW = float(special.ndtr(-_RADIUS / _SIGMA))
_Z = _SIGMA * math.sqrt(2.0 * math.pi) * (1.0 - 2.0 * _PHI_LOW) - 2.0 * _RADIUS * _G_R


# ------------------------------------------------------------------- 1D filter
def filter_kinks(kind: str) -> tuple[float, ...]:
    """Offsets (pixels) where the 1D profile $k_1$ or its CDF K is not smooth, plus the gaussian's centre.

    box: the support's ends ±½ ($k_1$ jumps); tent: -1, 0, 1 ($k_1'$ jumps); gaussian: ±R ($k_1'$
    jumps where the shifted profile reaches 0) and 0, which is smooth but halves the pieces.
    """
    kind = check_choice("filter", kind, FILTERS)
    return {"box": (-0.5, 0.5), "tent": (-1.0, 0.0, 1.0), "gaussian": (-_RADIUS, 0.0, _RADIUS)}[kind]


def filter_profile_1d(x: Any, kind: str) -> Any:
    r"""The 1D profile $k_1$ of the separable pixel filter $k(x, y) = k_1(x) k_1(y)$, integral 1.

    box: 1 on [-½, ½]; tent: $\max(1 - |x|, 0)$; gaussian: $(e^{-x^2/2σ^2} - e^{-R^2/2σ^2}) / Z$ on
    [-R, R] (σ = ½, R = 3σ as :mod:`sphere3d.sampling`), 0 outside. Dual-aware.
    """
    kind = check_choice("filter", kind, FILTERS)
    if kind == "box":
        return np.where(np.abs(x) <= 0.5, 1.0, 0.0) + 0.0 * x
    if kind == "tent":
        return np.maximum(1.0 - np.abs(x), 0.0)
    return np.maximum(np.exp(-0.5 * (x / _SIGMA) ** 2) - _G_R, 0.0) / _Z


def filter_cdf_1d(x: np.ndarray, kind: str) -> np.ndarray:
    r"""$K(x) = ∫_{-∞}^x k_1(t) dt$, from 0 below the support to 1 above it (plain arrays).

    box: $\mathrm{clip}(x + ½, 0, 1)$. tent: $½ (1 + x)^2$ on [-1, 0], $1 - ½ (1 - x)^2$ on [0, 1].
    gaussian: $[σ\sqrt{2π} (Φ(x/σ) - Φ(-R/σ)) - g(R) (x + R)] / Z$ on [-R, R].
    """
    kind = check_choice("filter", kind, FILTERS)
    x = np.asarray(x, dtype=np.float64)
    if kind == "box":
        return np.clip(x + 0.5, 0.0, 1.0)
    if kind == "tent":
        t = np.clip(x, -1.0, 1.0)
        return np.where(t <= 0.0, 0.5 * (1.0 + t) ** 2, 1.0 - 0.5 * (1.0 - t) ** 2)
    t = np.clip(x, -_RADIUS, _RADIUS)
    inner = (
        _SIGMA * math.sqrt(2.0 * math.pi) * (special.ndtr(t / _SIGMA) - _PHI_LOW) - _G_R * (t + _RADIUS)
    ) / _Z
    return np.clip(inner, 0.0, 1.0)


# --------------------------------------------------------------- film polygon
def _edges(polygon: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and end points (E, 2) of the edges of a polygon, counter-clockwise in (x, y).

    Green's theorem needs the boundary positively oriented in the coordinates used; the
    film's y axis points down, so the order is taken from the sign of the shoelace area
    $½ Σ (x_i y_{i+1} - x_{i+1} y_i)$, not from how the polygon looks on screen.
    """
    a = polygon
    b = np.roll(polygon, -1, axis=0)
    area2 = np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1])
    return (a, b) if area2 >= 0.0 else (b[::-1], a[::-1])


def _check_polygon(field: str, polygon: Any) -> np.ndarray:
    p = np.asarray(polygon, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) < 3 or not np.all(np.isfinite(p)):
        raise ValidationError(field, f"must be at least 3 finite [x, y] vertices, got shape {p.shape}")
    return p


def _pieces(a: np.ndarray, b: np.ndarray, centres: np.ndarray, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre nodes s (P, E, N) and weights on the edges a→b, split at the filter's kinks.

    For pixel centre c, the edge point $p(s) = a + s (b - a)$ crosses a kink κ of the
    profile in x where $a_x + s (b_x - a_x) = c_x + κ$, i.e. $s = (c_x + κ - a_x) / (b_x - a_x)$;
    same in y. Those s in (0, 1), with 0 and 1, cut [0, 1] into pieces on which the
    integrand is smooth; each piece [s0, s1] gets the nodes $s0 + (s1 - s0)(g + 1)/2$ and
    weights $(s1 - s0) w / 2$ (zero-length pieces weigh 0).
    """
    kinks = np.asarray(filter_kinks(kind))
    d = b - a  # (E, 2)
    cuts = [np.zeros((len(centres), len(a), 1)), np.ones((len(centres), len(a), 1))]
    for axis in (0, 1):
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (centres[:, None, axis, None] + kinks - a[None, :, axis, None]) / d[None, :, axis, None]
        cuts.append(np.where(np.isfinite(s), np.clip(s, 0.0, 1.0), 0.0))  # parallel edges: no cut
    s = np.sort(np.concatenate(cuts, axis=-1), axis=-1)  # (P, E, C)
    g, w = np.polynomial.legendre.leggauss(QUADRATURE_NODES[kind])
    lo, hi = s[..., :-1, None], s[..., 1:, None]  # (P, E, C-1, 1)
    nodes = lo + 0.5 * (hi - lo) * (g + 1.0)
    weights = 0.5 * (hi - lo) * w
    shape = (*nodes.shape[:2], -1)
    return nodes.reshape(shape), weights.reshape(shape)


def polygon_filter_integral(polygon: Any, centres: Any, kind: str) -> np.ndarray:
    r"""$∫_T k(x - c) dx$ for every centre c: the share of each pixel's filter the polygon T covers.

    Green's theorem with $Q = K(x - c_x) k_1(y - c_y)$, $P = 0$ ($∂Q/∂x = k_1(x - c_x) k_1(y - c_y) = k$):
    $∫_T k\, dA = ∮_{∂T} K(x - c_x) k_1(y - c_y) dy$, and on the edge a→b, $p(s) = a + s (b - a)$,
    $dy = (b_y - a_y) ds$:

        $∫_T k = Σ_{edges} (b_y - a_y) ∫_0^1 K(p_x(s) - c_x) k_1(p_y(s) - c_y) ds$,

    each 1D integral by Gauss–Legendre between the kinks (:data:`QUADRATURE_NODES`).

    Parameters
    ----------
    polygon : array_like, shape (V, 2)
        A simple polygon in pixel coordinates, either orientation.
    centres : array_like, shape (P, 2)
        Filter centres (pixel centres).
    kind : {"box", "tent", "gaussian"}

    Returns
    -------
    ndarray, shape (P,)
    """
    kind = check_choice("filter", kind, FILTERS)
    a, b = _edges(_check_polygon("polygon", polygon))
    c = np.asarray(centres, dtype=np.float64).reshape(-1, 2)
    s, w = _pieces(a, b, c, kind)  # (P, E, N)
    px = a[None, :, 0, None] + s * (b - a)[None, :, 0, None]
    py = a[None, :, 1, None] + s * (b - a)[None, :, 1, None]
    f = filter_cdf_1d(px - c[:, None, 0, None], kind) * filter_profile_1d(py - c[:, None, 1, None], kind)
    return np.sum(np.sum(f * w, axis=-1) * (b - a)[None, :, 1], axis=-1)


def polygon_filter_derivative(polygon: Any, polygon_dot: Any, centres: Any, kind: str) -> np.ndarray:
    r"""$d/dθ ∫_{T(θ)} k(x - c) dx$ when the polygon's vertices move with velocities ``polygon_dot``.

    Reynolds transport: k does not depend on θ, so only the boundary moves,
    $d/dθ ∫_T k = ∮_{∂T} k(p) (v·n) dl$, n the outward unit normal. The polygon at θ is
    the one through the moved vertices, so its edge a→b at $θ + dθ$ is the segment between
    $a + \dot a\, dθ$ and $b + \dot b\, dθ$, and the point $p(s) = a + s (b - a)$ moves with
    $v(s) = (1 - s) \dot a + s \dot b$. For a counter-clockwise edge, $n\, dl = (dy, -dx) = (b - a)^⊥ ds$:

        $d/dθ ∫_T k = Σ_{edges} ∫_0^1 k(p(s) - c) [v_x(s) (b_y - a_y) - v_y(s) (b_x - a_x)] ds$.

    Parameters
    ----------
    polygon, polygon_dot : array_like, shape (V, 2)
        Vertices and their θ-derivatives, in the same order.
    centres : array_like, shape (P, 2)
    kind : {"box", "tent", "gaussian"}

    Returns
    -------
    ndarray, shape (P,)
    """
    kind = check_choice("filter", kind, FILTERS)
    p = _check_polygon("polygon", polygon)
    v = _check_polygon("polygon_dot", polygon_dot)
    if v.shape != p.shape:
        raise ValidationError("polygon_dot", f"must have the shape of polygon {p.shape}, got {v.shape}")
    # orient (vertex, velocity) pairs together: a reversed polygon reverses its velocities
    a, b = _edges(p)
    reverse = not np.array_equal(a, p)
    va, vb = (np.roll(v, -1, axis=0)[::-1], v[::-1]) if reverse else (v, np.roll(v, -1, axis=0))
    c = np.asarray(centres, dtype=np.float64).reshape(-1, 2)
    s, w = _pieces(a, b, c, kind)
    d = b - a
    px = a[None, :, 0, None] + s * d[None, :, 0, None]
    py = a[None, :, 1, None] + s * d[None, :, 1, None]
    vx = (1.0 - s) * va[None, :, 0, None] + s * vb[None, :, 0, None]
    vy = (1.0 - s) * va[None, :, 1, None] + s * vb[None, :, 1, None]
    normal_speed = vx * d[None, :, 1, None] - vy * d[None, :, 0, None]  # (v·n) dl/ds
    k = filter_profile_1d(px - c[:, None, 0, None], kind) * filter_profile_1d(py - c[:, None, 1, None], kind)
    return np.sum(k * normal_speed * w, axis=(-2, -1))


# ---------------------------------------------------------------- projection
def project(camera: Camera, points: Any) -> tuple[Any, Any]:
    r"""Continuous pixel coordinates (x right, y down) of 3D points through the pinhole; Dual-aware.

    With (f, r, u) the camera frame built here from the scene format's convention
    (f toward ``look_at``, $r = f × up$ normalized, $u = r × f$; not with the renderer's
    :meth:`~sphere3d.scene.Camera.frame`, so a mistake there cannot be shared) and
    $q = P - position$, the ray through P meets the film plane (distance 1 along f) at
    $(q·r, q·u) / (q·f)$; the camera maps the film square [-t, t] ($t = \tan(fov/2)$) to
    [0, width) and [-t h/w, t h/w] to [0, height) top to bottom (square pixels):

        $x = (q·r / q·f / t + 1) w / 2$,    $y = (1 - q·u / q·f / (t h / w)) h / 2$.

    Raises
    ------
    ValidationError
        If a point is not strictly in front of the camera ($q·f ≤ 0$): behind the pinhole
        a straight edge does not project to a straight segment.
    """
    f = np.subtract(camera.look_at, camera.position)
    f = f / math.sqrt(float(f @ f))
    r = np.cross(f, camera.up)  # numpy's cross product, not the renderer's frame code
    r = r / math.sqrt(float(r @ r))
    u = np.cross(r, f)
    q = points - np.asarray(camera.position)
    depth = q @ f
    if not np.all(np.asarray(detach(depth)) > 0.0):
        raise ValidationError(
            "vertices", f"must lie in front of the camera (depth > 0), got depths {np.asarray(detach(depth))}"
        )
    t = math.tan(0.5 * camera.fov)
    w, h = camera.width, camera.height
    x = ((q @ r) / depth / t + 1.0) * (0.5 * w)
    y = (1.0 - (q @ u) / depth / (t * h / w)) * (0.5 * h)
    return x, y


def _triangle_shape(scene: Scene, field: str = "scene") -> int:
    """Index of the scene's single black triangle; one ValidationError if the scene is not that."""
    if len(scene.shapes) != 1:
        raise ValidationError(
            f"{field}.shapes", f"must hold exactly one triangle, got {len(scene.shapes)} shapes"
        )
    s = scene.shapes[0]
    if len(s.mesh.faces) != 1:
        raise ValidationError(
            f"{field}.shapes[0]", f"must be a single triangle, got {len(s.mesh.faces)} faces"
        )
    if s.albedo != 0.0 or s.emission != 0.0:
        raise ValidationError(
            f"{field}.shapes[0]", f"must be black (albedo 0, emission 0), got {s.albedo!r}, {s.emission!r}"
        )
    return 0


def _moved_transform(scene: Scene, s: Any, param: str | None, theta: Any, what: str) -> tuple[Any, Any, Any]:
    """The shape ``s``'s (translate, rotate, scale) with ``param`` (its translate, rotate or scale;
    ``what`` names the shape in the error) offset by ``theta`` (float or Dual)."""
    translate, rotate, scale = np.array(s.translate), np.array(s.rotate), s.scale
    if param is None:
        return translate, rotate, scale
    owner, _, rest = scene.check_param(param).partition(".")
    kind, _, axis = rest.partition(".")
    if owner != s.name or kind not in ("translate", "rotate", "scale"):
        raise ValidationError("param", f"must move {what} ({s.name}.translate/rotate/scale), got {param!r}")
    basis = np.eye(3)[AXES.index(axis)] if axis else None
    if kind == "translate":
        return translate + basis * theta, rotate, scale
    if kind == "rotate":
        return translate, rotate + basis * theta, scale
    return translate, rotate, scale * (1.0 + theta)


def triangle_vertices(scene: Scene, param: str | None = None, theta: Any = 0.0) -> Any:
    """World vertices (3, 3) of the scene's triangle with ``param`` offset by ``theta`` (float or Dual).

    The scene's transform of a shape (:mod:`sphere3d.scene`): $world = translate + R (scale · local)$,
    $R = R_z R_y R_x$ of ``rotate``; ``NAME.translate.a`` adds θ to translate[a], ``NAME.rotate.a``
    to rotate[a], ``NAME.scale`` multiplies the scale by 1 + θ.
    """
    s = scene.shapes[_triangle_shape(scene)]
    translate, rotate, scale = _moved_transform(scene, s, param, theta, "the triangle")
    local = s.mesh.vertices[s.mesh.faces[0]]
    return translate + _rotate_xyz(local * scale, rotate)


def _rotate_xyz(points: Any, angles: Any) -> Any:
    """Rotate points (n, 3) by ``angles`` radians about x, then y, then z (the scene format's
    convention, :mod:`sphere3d.scene`), one coordinate plane at a time. Written apart from the
    renderer's rotation matrices (:func:`sphere3d.state.euler_matrix`), so that a mistake there
    shows against this closed form instead of being shared by it."""
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    a, b, c = angles[0], angles[1], angles[2]
    y, z = y * np.cos(a) - z * np.sin(a), y * np.sin(a) + z * np.cos(a)  # about x: y -> z
    z, x = z * np.cos(b) - x * np.sin(b), z * np.sin(b) + x * np.cos(b)  # about y: z -> x
    x, y = x * np.cos(c) - y * np.sin(c), x * np.sin(c) + y * np.cos(c)  # about z: x -> y
    return np.stack([x, y, z], axis=-1)


@dataclass(frozen=True)
class TriangleImage:
    """The exact image of a black triangle against the sky, and its θ-derivative, shape (height, width).

    ``coverage`` is $∫_T k$ per pixel; ``value = sky (1 - coverage)``; ``derivative`` its θ-derivative
    (zeros without a parameter); ``vertices`` the projected triangle (3, 2) in pixel coordinates.
    """

    value: np.ndarray
    derivative: np.ndarray
    coverage: np.ndarray
    vertices: np.ndarray


def triangle_image(scene: Any, param: str | None = None, theta: float = 0.0) -> TriangleImage:
    r"""The image $I(p) = sky (1 - ∫_T k(x - c_p) dx)$ of a one-triangle scene, and dI/dθ.

    Parameters
    ----------
    scene : scene source
        One black triangle (a ``mesh`` shape with one face, albedo 0, emission 0) in front
        of the camera, a constant ``sky``.
    param : str, optional
        A translate, rotate or scale parameter of the triangle, or ``camera.translate.x|y|z`` (the
        camera's position and look-at point move together: the image is the triangle's moved by -θ).
    theta : float
        The parameter's offset at which to evaluate (finite differences of this closed form
        take ±h).

    Returns
    -------
    TriangleImage

    Notes
    -----
    The vertices' film velocities come from the projection evaluated on Duals
    (:func:`project`, :func:`triangle_vertices`): $\dot a = d(\text{pixel coordinates})/dθ$ exactly.
    The pixel integral sees radiance 0 on the triangle from either side (albedo and
    emission 0) and ``sky`` elsewhere; the derivative is $-sky\, d/dθ ∫_T k$ by
    :func:`polygon_filter_derivative`.
    """
    scene = load_scene(scene)
    theta = float(check_vector("theta", [theta], 1)[0])
    dual = variable(theta) if param is not None else theta
    if param is not None and param.startswith("camera."):
        # the camera and its look-at point move together: the frame stays, every point shifts by -θ e_a
        axis = AXES.index(scene.check_param(param).rpartition(".")[2])
        vertices = triangle_vertices(scene) - np.eye(3)[axis] * dual
    else:
        vertices = triangle_vertices(scene, param, dual)
    x, y = project(scene.camera, vertices)
    film = np.stack([np.asarray(detach(x)), np.asarray(detach(y))], axis=-1)
    velocity = np.stack([np.asarray(tangent(x)), np.asarray(tangent(y))], axis=-1) * (param is not None)
    cam = scene.camera
    rows, cols = np.divmod(np.arange(cam.width * cam.height), cam.width)
    centres = np.stack([cols + 0.5, rows + 0.5], axis=-1)  # pixel (i, j) is centred at (j + ½, i + ½)
    coverage = polygon_filter_integral(film, centres, cam.filter).reshape(cam.height, cam.width)
    derivative = -scene.sky * polygon_filter_derivative(film, velocity, centres, cam.filter)
    return TriangleImage(
        value=scene.sky * (1.0 - coverage),
        derivative=derivative.reshape(cam.height, cam.width) + 0.0,
        coverage=coverage,
        vertices=film,
    )
