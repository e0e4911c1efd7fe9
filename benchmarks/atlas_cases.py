"""The cases of the bias atlas (:mod:`benchmarks.atlas`): scenes, motions and their closed forms.

Seven families, each a black feature against a constant sky of radiance 1 or a square light, where the
closed forms of :mod:`sphere3d.closed_form` and :mod:`flatland.closed_form` give the exact derivative:

``sphere3d film``
    A triangle (:data:`sphere3d.closed_form.TRIANGLE_SHAPE`) ``size`` px across in front of a
    pinhole camera at distance 4 (:func:`sphere3d.closed_form.pinhole_triangle_scene`), its plane
    tilted about the x axis so that the line of sight meets it at ``angle`` degrees (90: face-on;
    its film image is then ``size`` wide and ``size · sin(angle)`` tall). The exact image derivative
    is :func:`sphere3d.closed_form.triangle_image`.
``sphere3d shading``
    The irradiance at the origin, normal 30 degrees off the zenith, under the same triangle
    ``size`` radians across at distance 1 straight above, tilted alike: Lambert's formula,
    :func:`sphere3d.closed_form.occluded_sky_irradiance`.
``sphere3d light``
    The irradiance at the origin (normal +z) under a square light of side 1 at height 2 (radiance 5,
    sharp-edged), the same triangle ``size`` radians across at distance 1 between, tilted alike, its
    centre at :data:`LIGHT_OFFSET` so that its shadow on the light's plane lies off the light's centre
    (inside it for the small sizes, across its border for 0.5 rad): the light minus the shadow by
    Lambert's formula, :func:`sphere3d.closed_form.occluded_light_irradiance`. The emitter strategy's
    integral and the cosine strategy's kernels beside a light's border, which the sky families do not
    have.
``sphere3d mesh film``, ``sphere3d mesh shading``
    As ``sphere3d film`` and ``sphere3d shading``, with a convex mesh in place of the triangle: an
    icosphere of :data:`MESH_SUBDIVISIONS` subdivision (42 vertices, 80 faces, flat-shaded) ``size``
    across (its diameter), turned by ``angle`` as the triangle is tilted (so each angle shows another
    outline). Its outline is a polygon of several edges, whose corners move apart under a turn where a
    triangle's do not: :func:`sphere3d.closed_form.convex_image` on the film, Lambert's formula over
    its faces turned towards the point in shading (:func:`sphere3d.closed_form.occluded_sky_irradiance`).
    On their own, smaller grid (:data:`MESH`).
``flatland film``
    A segment ``size`` px long at depth 2.5 in front of flatland's camera (16 pixels), at ``angle``
    degrees to the line of sight: :func:`flatland.closed_form.segment_image`.
``flatland shading``
    The irradiance at the origin (normal 30 degrees off the vertical) under a segment ``size``
    radians long at distance 1 straight above, at ``angle`` degrees to the line of sight:
    :func:`flatland.closed_form.occluded_sky_irradiance`.

Motions are the parameters the scene formats have (:mod:`sphere3d.scene`, :mod:`flatland.scene`):
translations along every axis (the line of sight is +z in 3D, +y in 2D: depth), rotations about
every axis (about the line of sight too) and about a pivot off the feature's centre (3D: the
scene's rotations act about the shape's position, placed one size beside the triangle), scaling,
one vertex (flatland's ``vertex`` parameters; sphere3d has none) and the camera's motions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland import closed_form as fcf
from sphere3d import closed_form as scf
from sphere3d.shapes import icosphere

__all__ = ["FAMILIES", "Case", "grid"]

FAMILIES = (
    "sphere3d film",
    "sphere3d shading",
    "sphere3d light",
    "sphere3d mesh film",
    "sphere3d mesh shading",
    "flatland film",
    "flatland shading",
)
FILM_MOTIONS_3D = {
    "translate x": "tri.translate.x",
    "translate y": "tri.translate.y",
    "translate z (depth)": "tri.translate.z",
    "rotate x (tilt)": "tri.rotate.x",
    "rotate y (turn)": "tri.rotate.y",
    "rotate z (view axis)": "tri.rotate.z",
    "rotate z, off-centre pivot": "tri.rotate.z",
    "scale": "tri.scale",
    "camera translate x": "camera.translate.x",
    "camera translate y": "camera.translate.y",
    "camera translate z": "camera.translate.z",
}
SHADING_MOTIONS_3D = {k: v for k, v in FILM_MOTIONS_3D.items() if not k.startswith("camera")}
FILM_MOTIONS_2D = {
    "translate x": "seg.translate.x",
    "translate y (depth)": "seg.translate.y",
    "rotate": "seg.rotate",
    "scale": "seg.scale",
    "vertex 0 x": "seg.vertex.0.x",
    "vertex 0 y": "seg.vertex.0.y",
    "camera translate x": "camera.translate.x",
    "camera translate y": "camera.translate.y",
    "camera rotate": "camera.rotate",
}
SHADING_MOTIONS_2D = {k: v for k, v in FILM_MOTIONS_2D.items() if not k.startswith("camera")}
MOTIONS = {
    "sphere3d film": FILM_MOTIONS_3D,
    "sphere3d shading": SHADING_MOTIONS_3D,
    "sphere3d light": SHADING_MOTIONS_3D,
    "sphere3d mesh film": FILM_MOTIONS_3D,
    "sphere3d mesh shading": SHADING_MOTIONS_3D,
    "flatland film": FILM_MOTIONS_2D,
    "flatland shading": SHADING_MOTIONS_2D,
}
NORMAL_TILT = math.radians(30.0)
"""The shading point's normal, off the line of sight to the feature (so no motion is symmetric)."""
DEPTH_2D = 2.5
"""flatland: the segment's depth in front of the camera."""
FOV_2D = 0.5
PIXELS_2D = 16
PIXEL_2D = 2.0 * math.tan(0.5 * FOV_2D) / PIXELS_2D * DEPTH_2D
"""flatland: one pixel's width in world units at the segment's depth."""
LIGHT_OFFSET = (0.1, 0.05)
"""``sphere3d light``: the triangle's centre off the axis through the light's centre, at height 1 (its
shadow's centre twice as far off on the light's plane)."""
LIGHT = {"half": 0.5, "height": 2.0, "radiance": 5.0}
"""``sphere3d light``: the square light of :func:`sphere3d.closed_form.light_triangle_scene`."""
MESH_SUBDIVISIONS = 1
"""The mesh families' icosphere: 42 vertices, so that its outline is a polygon of several edges a few
pixels (or hundredths of a radian) long at the grid's sizes."""
_c, _s = np.cos([0.3, 0.2, 0.1]), np.sin([0.3, 0.2, 0.1])
MESH_TURN = (
    np.array([[_c[2], -_s[2], 0.0], [_s[2], _c[2], 0.0], [0.0, 0.0, 1.0]])
    @ np.array([[_c[1], 0.0, _s[1]], [0.0, 1.0, 0.0], [-_s[1], 0.0, _c[1]]])
    @ np.array([[1.0, 0.0, 0.0], [0.0, _c[0], -_s[0]], [0.0, _s[0], _c[0]]])
)
"""A fixed turn of the icosphere (0.3, 0.2, 0.1 rad about x, y, z) before its tilt: off its symmetry
axes, so that no face is seen exactly edge-on (where the closed forms' set of faces turned towards
the eye changes within a finite difference's step)."""
OFFSET = (0.13, -0.21)
"""The feature's centre off the optical axis, in pixels (no edge lines up with the pixel grid)."""


def _tilt(points: np.ndarray, angle_deg: float) -> np.ndarray:
    """Points (n, 3) in the plane z = 0 turned about the x axis so that +z meets the plane at ``angle``."""
    a = math.radians(90.0 - angle_deg)
    y, z = points[:, 1], points[:, 2]
    return np.stack(
        [points[:, 0], y * math.cos(a) - z * math.sin(a), y * math.sin(a) + z * math.cos(a)], axis=1
    )


@dataclass(frozen=True)
class Case:
    """One cell of the atlas but its method: a family, motion, feature size, viewing angle, filter.

    ``size`` is in pixels (film) or radians (shading); ``angle`` in degrees between the line of sight
    and the feature's plane (3D) or line (2D); ``filter`` is "" for the shading integrals.
    """

    family: str
    motion: str
    size: float
    angle: float
    filter: str = ""

    @property
    def package(self) -> str:
        return self.family.split()[0]

    @property
    def film(self) -> bool:
        return self.family.endswith("film")

    @property
    def param(self) -> str:
        return MOTIONS[self.family][self.motion]

    @property
    def pivot(self) -> bool:
        return "pivot" in self.motion

    def label(self) -> str:
        unit = "px" if self.film else "rad"
        tail = f", {self.filter}" if self.filter else ""
        return f"{self.family}: {self.motion}, {self.size:g} {unit}, {self.angle:g} deg{tail}"

    # ------------------------------------------------------------ scenes
    def scene(self) -> dict:
        """The scene dict of this case (a black triangle, icosphere or segment under a sky of radiance 1)."""
        return {
            "sphere3d film": self._film_3d,
            "sphere3d shading": self._shading_3d,
            "sphere3d light": self._light_3d,
            "sphere3d mesh film": self._film_3d,
            "sphere3d mesh shading": self._shading_3d,
            "flatland film": self._film_2d,
            "flatland shading": self._shading_2d,
        }[self.family]()

    def _triangle(self, unit: float, centre: np.ndarray) -> tuple[list, list]:
        """Local vertices and position of the tilted triangle (``unit``: world size of 1), the position
        one size beside it for the off-centre pivot."""
        local = _tilt(np.array(scf.TRIANGLE_SHAPE) * self.size * unit, self.angle)
        pivot = np.array([1.0, 0.5, 0.0]) * self.size * unit if self.pivot else np.zeros(3)
        return (local - pivot).tolist(), (centre + pivot).tolist()

    def _mesh(self, unit: float, centre: np.ndarray) -> tuple[list, list, list]:
        """Local vertices, faces and position of the turned icosphere ``size`` across (``unit``: world
        size of 1), the position one size beside it for the off-centre pivot (as :meth:`_triangle`)."""
        ball = icosphere(0.5 * self.size * unit, MESH_SUBDIVISIONS)
        local = _tilt(ball.vertices @ MESH_TURN.T, self.angle)
        pivot = np.array([1.0, 0.5, 0.0]) * self.size * unit if self.pivot else np.zeros(3)
        return (local - pivot).tolist(), ball.faces.tolist(), (centre + pivot).tolist()

    def _place(self, shape: dict, unit: float, centre: np.ndarray) -> None:
        """The feature of this case into ``shape`` (a mesh): the triangle, or the mesh families' icosphere."""
        if "mesh" in self.family.split():
            shape["vertices"], shape["faces"], shape["translate"] = self._mesh(unit, centre)
        else:
            shape["vertices"], shape["translate"] = self._triangle(unit, centre)

    def _film_3d(self) -> dict:
        width = 8 if self.size <= 2.0 else (12 if self.size <= 4.0 else 16)
        scene = scf.pinhole_triangle_scene(self.size, width=width, filter=self.filter)
        centre = np.array([OFFSET[0] * scf.PIXEL, OFFSET[1] * scf.PIXEL, 0.0])
        self._place(scene["shapes"][0], scf.PIXEL, centre)
        return scene

    def _shading_3d(self) -> dict:
        scene = scf.sky_triangle_scene(np.array(scf.TRIANGLE_SHAPE) + np.array([0.0, 0.0, 1.0]))
        self._place(scene["shapes"][0], 1.0, np.array([0.0, 0.0, 1.0]))
        return scene

    def _light_3d(self) -> dict:
        centre = np.array([*LIGHT_OFFSET, 1.0])
        scene = scf.light_triangle_scene(np.array(scf.TRIANGLE_SHAPE) + centre, **LIGHT)
        shape = next(s for s in scene["shapes"] if s["name"] == "tri")
        shape["vertices"], shape["translate"] = self._triangle(1.0, centre)
        return scene

    def _segment(self, length: float, centre: np.ndarray) -> np.ndarray:
        a = math.radians(self.angle)
        half = 0.5 * length * np.array([math.sin(a), math.cos(a)])  # 90 deg: across the line of sight (+y)
        return np.stack([centre - half, centre + half])

    def _film_2d(self) -> dict:
        centre = np.array([OFFSET[0] * PIXEL_2D, DEPTH_2D])
        points = self._segment(self.size * PIXEL_2D, centre)
        return fcf.segment_scene(points, pixels=PIXELS_2D, filter=self.filter, fov=FOV_2D)

    def _shading_2d(self) -> dict:
        return fcf.sky_segment_scene(self._segment(self.size, np.array([0.0, 1.0])))

    # ------------------------------------------------------------ shading point
    @property
    def point(self) -> tuple:
        return (0.0, 0.0, 0.0) if self.package == "sphere3d" else (0.0, 0.0)

    @property
    def normal(self) -> tuple:
        if self.family == "sphere3d light":  # the closed form's point: normal +z
            return (0.0, 0.0, 1.0)
        s, c = math.sin(NORMAL_TILT), math.cos(NORMAL_TILT)
        return (s, 0.0, c) if self.package == "sphere3d" else (s, c)

    # ------------------------------------------------------------ closed forms
    def value(self, theta: float = 0.0) -> Any:
        """The exact image (film) or irradiance (shading) with the parameter offset by ``theta``."""
        return self._exact(theta)[0]

    def derivative(self) -> Any:
        """The exact derivative at θ = 0: an image (film) or a number (shading)."""
        return self._exact(0.0)[1]

    def central_difference(self, h: float) -> Any:
        """The closed form's own central difference at step h: what ``finite_difference`` estimates."""
        return (self.value(h) - self.value(-h)) / (2.0 * h)

    def _exact(self, theta: float) -> tuple[Any, Any]:
        scene = self.scene()
        if self.family == "sphere3d film":
            image = scf.triangle_image(scene, self.param, theta)
            return image.value, image.derivative
        if self.family == "sphere3d mesh film":
            image = scf.convex_image(scene, self.param, theta)
            return image.value, image.derivative
        if self.family == "flatland film":
            segment = fcf.segment_image(scene, self.param, theta)
            return segment.value, segment.derivative
        if self.family == "sphere3d light":  # seen from the shadow rays' origin, ε above the point
            return scf.occluded_light_irradiance(scene, self.param, self.origin(theta)[2], theta)
        if self.package == "sphere3d":
            return scf.occluded_sky_irradiance(scene, self.origin(theta), self.normal, self.param, theta)
        return fcf.occluded_sky_irradiance(scene, self.point, self.normal, self.param, theta)

    def flux(self) -> float:
        """The gross boundary flux of the shading integral (what its error is measured against): the
        triangle's edges' (:func:`sphere3d.closed_form.boundary_flux`), for ``sphere3d light`` where they
        lie in front of the light."""
        if self.package == "flatland":
            return fcf.boundary_flux(self.scene(), self.point, self.normal, self.param).gross
        if self.family != "sphere3d light":
            return scf.boundary_flux(self.scene(), self.origin(), self.normal, self.param).gross
        half, height = LIGHT["half"], LIGHT["height"]

        def window(omega: np.ndarray) -> np.ndarray:  # the direction meets the light's square
            up = omega[:, 2] > 0.0
            at = omega[:, :2] * (height / np.where(up, omega[:, 2], 1.0))[:, None]
            return up & np.all(np.abs(at) <= half, axis=1)

        scene = self.scene()
        alone = {
            **scene,
            "shapes": [s for s in scene["shapes"] if s["name"] == "tri"],
        }  # the triangle's edges
        flux = scf.boundary_flux(
            alone, self.origin(), self.normal, self.param, 256, LIGHT["radiance"], window
        )
        return flux.gross

    def origin(self, theta: float = 0.0) -> tuple:
        """Where the renderer evaluates the shading integral: sphere3d traces its rays from
        ``point + ε normal`` (its offset against self-intersection, ε = 1e-4 of the scene's extent at
        θ, :class:`sphere3d.integrator.Shading`), flatland from the point itself. The closed form is
        taken there: the atlas measures the methods, and the offset's own effect on the integral, a
        primal approximation of the renderer, is the same for every method (up to 3 % of the gross
        boundary flux of a 0.01 rad triangle at distance 1)."""
        if self.package != "sphere3d":
            return self.point
        from sphere3d.scene import load_scene
        from sphere3d.state import build_state

        eps = build_state(load_scene(self.scene()), self.param, float(theta)).epsilon
        return tuple(np.asarray(self.point) + eps * np.asarray(self.normal))


@dataclass(frozen=True)
class Grid:
    """The axes of the atlas: sizes (film px, shading rad), viewing angles (degrees), filters."""

    film_sizes: tuple[float, ...]
    shading_sizes: tuple[float, ...]
    angles: tuple[float, ...]
    filters: tuple[str, ...]


FULL = Grid((0.5, 1.0, 2.0, 4.0, 8.0), (0.01, 0.03, 0.1, 0.5), (90.0, 30.0, 10.0, 5.0), ("tent", "gaussian"))
QUICK = Grid((0.5, 2.0, 8.0), (0.01, 0.1, 0.5), (90.0, 10.0), ("gaussian",))
MESH = Grid((1.0, 2.0, 4.0, 8.0), (0.03, 0.1, 0.3), (90.0, 30.0), ("gaussian",))
"""The mesh families' grid (full and quick): the icosphere's diameter, two of its orientations (an angle
turns it; seen from anywhere it is a ball) and the gaussian filter; the triangle's cells cover the rest."""


def grid(quick: bool = False, families: tuple[str, ...] = FAMILIES) -> list[Case]:
    """Every case of the full (or quick) grid of ``families``, in the atlas's order."""
    cases = []
    for family in families:
        g = MESH if "mesh" in family.split() else (QUICK if quick else FULL)
        film = family.endswith("film")
        for motion in MOTIONS[family]:
            for size in g.film_sizes if film else g.shading_sizes:
                for angle in g.angles:
                    for kind in g.filters if film else ("",):
                        cases.append(Case(family, motion, size, angle, kind))
    return cases
