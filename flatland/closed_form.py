r"""Closed forms of flatland's two integrals for a black segment under a constant sky, and their
θ-derivatives: the film image of a segment and the irradiance under it.

A black segment S (albedo 0, emission 0) in front of a constant ``sky`` L has exact answers, values and
θ-derivatives, to rounding, for every parameter that moves it or the camera:

1. **The camera image** (:func:`segment_image`). Pixel j integrates its filter along the film,
   $I_j = ∫ k_j(t) L(t) dt$ (:mod:`flatland.integrator`); a camera ray sees 0 where it meets S and
   L elsewhere, and S covers the film interval between its endpoints' film coordinates
   $t_a < t_b$, so

       $I_j = L (1 - K_j(t_b) + K_j(t_a))$,    $dI_j/dθ = -L (k_j(t_b) \dot t_b - k_j(t_a) \dot t_a)$,

   $K_j$ the filter's integral (:func:`filter_cdf`): the Leibniz rule with the two ends as the
   moving limits (Loubet et al. 2019, Sec. 3.2).
2. **The irradiance at a point** (:func:`occluded_sky_irradiance`),
   $E = ∫ L_i(φ) \max(0, \cos(φ - φ_n)) dφ$: the open half circle gives 2L, the segment seen
   between angles $β_a < β_b$ from the normal (both above the horizon) removes
   $L (\sin β_b - \sin β_a)$.

Both are written from the scene's definition (film coordinate, filter profiles, the parameters of
:mod:`flatland.scene`), not from the renderer's code, and carry θ as a Dual: the endpoints' film
coordinates and angles come with their tangents. :func:`segment_scene` and :func:`sky_segment_scene`
build the scenes they are stated for.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import special

from flatland.core.dual import detach, tangent, variable
from flatland.core.validate import ValidationError, check_choice
from flatland.scene import FILTERS, Scene, check_direction, check_point, load_scene

__all__ = [
    "Flux",
    "SegmentImage",
    "boundary_flux",
    "filter_cdf",
    "filter_profile",
    "moved_camera",
    "moved_segment",
    "occluded_sky_irradiance",
    "segment_image",
    "segment_scene",
    "sky_segment_scene",
]


def filter_profile(kind: str, x: np.ndarray, width: float) -> np.ndarray:
    r"""The pixel filter $k(x)$ at offsets x from the pixel centre (film units), integral 1.

    box: $1/w$ on $|x| ≤ w/2$; tent: $\max(1 - |x|/w, 0) / w$; gaussian: the normal density of
    $σ = w/2$ (untruncated), w the pixel width (:mod:`flatland.scene`).
    """
    kind = check_choice("filter", kind, FILTERS)
    x = np.asarray(x, dtype=np.float64)
    if kind == "box":
        return np.where(np.abs(x) <= 0.5 * width, 1.0 / width, 0.0)
    if kind == "tent":
        return np.maximum(1.0 - np.abs(x) / width, 0.0) / width
    sigma = 0.5 * width
    return np.exp(-0.5 * (x / sigma) ** 2) / (sigma * math.sqrt(2.0 * math.pi))


def filter_cdf(kind: str, x: np.ndarray, width: float) -> np.ndarray:
    r"""$K(x) = ∫_{-∞}^x k$: box $\mathrm{clip}(x/w + ½, 0, 1)$; tent, with $u = x/w$ clipped to [-1, 1],
    $½(1 + u)^2$ for u ≤ 0 and $1 - ½(1 - u)^2$ above; gaussian $Φ(x/σ)$."""
    kind = check_choice("filter", kind, FILTERS)
    x = np.asarray(x, dtype=np.float64)
    if kind == "box":
        return np.clip(x / width + 0.5, 0.0, 1.0)
    if kind == "tent":
        u = np.clip(x / width, -1.0, 1.0)
        return np.where(u <= 0.0, 0.5 * (1.0 + u) ** 2, 1.0 - 0.5 * (1.0 - u) ** 2)
    return special.ndtr(x / (0.5 * width))


def _rotate(v: Any, angle: Any) -> Any:
    """The 2D vectors ``v`` (n, 2) turned counter-clockwise by ``angle``."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]], axis=1)


def _segment(scene: Scene, field: str = "scene") -> int:
    """Index of the scene's black segment; one ValidationError if the scene is not one black segment."""
    if len(scene.shapes) != 1 or scene.shapes[0].type != "segment":
        raise ValidationError(f"{field}.shapes", "must hold exactly one segment")
    s = scene.shapes[0]
    if s.albedo != 0.0 or s.emission != 0.0:
        raise ValidationError(
            f"{field}.shapes[0]", f"must be black (albedo 0, emission 0), got {s.albedo!r}, {s.emission!r}"
        )
    return 0


def moved_segment(scene: Scene, param: str | None, theta: Any) -> Any:
    """The segment's two points (2, 2) with ``param`` offset by ``theta`` (float or Dual).

    From :mod:`flatland.scene`'s table: ``translate.x|y`` adds θ to both points, ``rotate`` turns them
    counter-clockwise about their mean, ``scale`` scales them by 1 + θ about it, ``vertex.K.x|y`` adds
    θ to point K; camera parameters leave it.
    """
    s = scene.shapes[_segment(scene)]
    pts = np.array(s.points, dtype=np.float64)
    owner, _, rest = (param or "").partition(".")
    if owner != s.name:
        return pts + 0.0 * theta
    centre = pts.mean(axis=0)
    parts = rest.split(".")
    if parts[0] == "translate":
        return pts + theta * np.eye(2)[("x", "y").index(parts[1])]
    if parts[0] == "rotate":
        return centre + _rotate(pts - centre, theta)
    if parts[0] == "scale":
        return centre + (1.0 + theta) * (pts - centre)
    if parts[0] == "vertex":
        step = np.zeros((2, 2))
        step[int(parts[1]), ("x", "y").index(parts[2])] = 1.0
        return pts + theta * step
    raise ValidationError("param", f"must move the segment or the camera, got {param!r}")


def moved_camera(scene: Scene, param: str | None, theta: Any) -> tuple[Any, Any]:
    """The camera's position and unit forward direction with ``param`` offset by ``theta``:
    ``camera.translate.x|y`` moves the position, ``camera.rotate`` turns the direction
    counter-clockwise."""
    cam = scene.camera
    position = np.array(cam.position, dtype=np.float64) + 0.0 * theta
    forward = np.array(cam.direction, dtype=np.float64)[None] + 0.0 * theta
    if param is not None and param.startswith("camera."):
        kind, _, axis = param[len("camera.") :].partition(".")
        if kind == "translate":
            position = position + theta * np.eye(2)[("x", "y").index(axis)]
        else:
            forward = _rotate(forward, theta)
    return position, forward[0]


@dataclass(frozen=True)
class SegmentImage:
    """The exact film image of a black segment against the sky, and its θ-derivative, shape (pixels,).

    ``ends`` are the film coordinates of the two endpoints (ascending), ``rates`` their θ-derivatives.
    """

    value: np.ndarray
    derivative: np.ndarray
    ends: np.ndarray
    rates: np.ndarray


def segment_image(scene: Any, param: str | None = None, theta: float = 0.0) -> SegmentImage:
    r"""$I_j = L (1 - K_j(t_b) + K_j(t_a))$ and $dI_j/dθ$ (module docstring) for a one-segment scene.

    The film coordinate of a point P is $t = (P - o)·r / (P - o)·f$ (f forward, r = f turned
    clockwise: :mod:`flatland.scene`); both endpoints must lie in front of the camera, where the
    segment's image is the interval between theirs.
    """
    scene = load_scene(scene)
    theta_d = variable(float(theta)) if param is not None else float(theta)
    pts = moved_segment(scene, param, theta_d)
    origin, forward = moved_camera(scene, param, theta_d)
    right = np.stack([forward[1], -forward[0]])
    q = pts - origin
    depth = q[:, 0] * forward[0] + q[:, 1] * forward[1]
    if not np.all(np.asarray(detach(depth)) > 0.0):
        raise ValidationError("scene.shapes[0].points", "must lie in front of the camera")
    t = (q[:, 0] * right[0] + q[:, 1] * right[1]) / depth
    value, rate = np.asarray(detach(t), dtype=np.float64), np.asarray(tangent(t), dtype=np.float64)
    rate = rate * (param is not None)
    order = np.argsort(value)
    (ta, tb), (ra, rb) = value[order], rate[order]
    cam = scene.camera
    centres = cam.pixel_centers()
    w = cam.pixel_width
    kind = cam.filter
    covered = filter_cdf(kind, tb - centres, w) - filter_cdf(kind, ta - centres, w)
    moving = filter_profile(kind, tb - centres, w) * rb - filter_profile(kind, ta - centres, w) * ra
    return SegmentImage(scene.sky * (1.0 - covered), -scene.sky * moving + 0.0, value[order], rate[order])


def occluded_sky_irradiance(
    scene: Any, point: Any, normal: Any, param: str | None = None, theta: float = 0.0
) -> tuple[float, float]:
    r"""$E = L (2 - \sin β_b + \sin β_a)$ at ``point`` (normal ``normal``) under the sky with the scene's
    black segment seen between the angles $β_a < β_b$ from the normal, and dE/dθ.

    Both endpoints must lie strictly above the point's horizon ($|β| < π/2$); the point does not move.
    """
    scene = load_scene(scene)
    x = np.array(check_point("point", point))
    n = np.array(check_direction("normal", normal))
    theta_d = variable(float(theta)) if param is not None else float(theta)
    d = moved_segment(scene, param, theta_d) - x
    along = d[:, 0] * n[0] + d[:, 1] * n[1]
    across = d[:, 0] * n[1] - d[:, 1] * n[0]  # along n turned clockwise: β > 0 to the normal's right
    if not np.all(np.asarray(detach(along)) > 0.0):
        raise ValidationError("scene.shapes[0].points", "must lie strictly above the point's horizon")
    beta = np.arctan2(across, along)
    sines = np.sin(beta)
    e = scene.sky * (2.0 - np.abs(sines[1] - sines[0]))
    return float(np.asarray(detach(e))), float(np.asarray(tangent(e))) if param is not None else 0.0


@dataclass(frozen=True)
class Flux:
    r"""The boundary term of dE/dθ, $-L Σ_{ends} ±\cos β_i \dot β_i$ (``net``, the derivative of
    :func:`occluded_sky_irradiance`), and its gross flux $L Σ |\cos β_i \dot β_i|$ (``gross``): the
    scale a method's error is measured against where the net is a small difference of the two ends'
    terms (a sideways turn)."""

    net: float
    gross: float


def boundary_flux(scene: Any, point: Any, normal: Any, param: str) -> Flux:
    r""":class:`Flux` of the scene's black segment seen from ``point`` (normal ``normal``) under ``param``:
    each end's angle β from the normal moves at $\dot β$, where the integrand $L \cos β$ jumps."""
    scene = load_scene(scene)
    x = np.array(check_point("point", point))
    n = np.array(check_direction("normal", normal))
    d = moved_segment(scene, param, variable(0.0)) - x
    beta = np.arctan2(d[:, 0] * n[1] - d[:, 1] * n[0], d[:, 0] * n[0] + d[:, 1] * n[1])
    rate = np.asarray(tangent(beta)) * np.cos(np.asarray(detach(beta)))
    order = np.argsort(np.asarray(detach(beta)))  # the end at the larger angle closes the interval
    net = -scene.sky * (rate[order[1]] - rate[order[0]])
    return Flux(float(net), float(scene.sky * np.sum(np.abs(rate))))


def segment_scene(
    points: Any, pixels: int = 16, filter: str = "gaussian", fov: float = 0.5, sky: float = 1.0
) -> dict:
    """A black segment between ``points`` (2, 2) under the sky, the camera at the origin looking along +y."""
    return {
        "name": "segment",
        "camera": {
            "position": [0.0, 0.0],
            "direction": [0.0, 1.0],
            "fov": fov,
            "pixels": pixels,
            "filter": filter,
        },
        "sky": sky,
        "shapes": [
            {"name": "seg", "type": "segment", "points": np.asarray(points, float).tolist(), "albedo": 0.0}
        ],
    }


def sky_segment_scene(points: Any, sky: float = 1.0) -> dict:
    """:func:`segment_scene` for the irradiance at a point (the camera is a placeholder)."""
    return segment_scene(points, pixels=4, filter="tent", sky=sky)
