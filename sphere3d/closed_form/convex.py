r"""The camera image of a black convex mesh against the sky: the sum of its front faces' filtered images.

Seen from the camera, a convex mesh's front faces (turned towards it, $n·(V - o) < 0$ for outward
normals) project onto its outline without overlap, so the share of a pixel's filter the mesh covers
is the sum of theirs, each a triangle by Green's theorem (:func:`~sphere3d.closed_form.film.
polygon_filter_integral`), and its θ-derivative the sum of their Reynolds transports
(:func:`~sphere3d.closed_form.film.polygon_filter_derivative`): an edge between two front faces
enters twice with opposite normals and cancels, leaving the outline's silhouette edges, whose images
move differently when the mesh turns or recedes (Loubet et al. 2019, Sec. 3.2). Valid while no face
changes side within the derivative (no face seen exactly edge-on at θ).

The mesh's world vertices come from the scene format's transform written here anew
(:func:`mesh_vertices`, as :func:`~sphere3d.closed_form.film.triangle_vertices` for one triangle),
not from the renderer's.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flatland.core.dual import detach, tangent, variable
from flatland.core.validate import ValidationError
from sphere3d.closed_form.film import (
    TriangleImage,
    _moved_transform,
    _rotate_xyz,
    polygon_filter_derivative,
    polygon_filter_integral,
    project,
)
from sphere3d.scene import AXES, Scene, load_scene

__all__ = ["convex_image", "mesh_vertices"]


def mesh_vertices(scene: Scene, param: str | None = None, theta: Any = 0.0) -> Any:
    """World vertices (V, 3) of the scene's one shape with ``param`` (its translate, rotate or scale) offset
    by ``theta`` (float or Dual): $world = translate + R (scale · local)$, $R = R_z R_y R_x$."""
    if len(scene.shapes) != 1:
        raise ValidationError("scene.shapes", f"must hold exactly one shape, got {len(scene.shapes)}")
    s = scene.shapes[0]
    translate, rotate, scale = _moved_transform(scene, s, param, theta, "the shape")
    return translate + _rotate_xyz(s.mesh.vertices * scale, rotate)


def convex_image(scene: Any, param: str | None = None, theta: float = 0.0) -> TriangleImage:
    """The image $I(p) = sky (1 - Σ_{front} ∫_{T_f} k(x - c_p) dx)$ of one black convex mesh (albedo and
    emission 0) in front of the camera, and dI/dθ for ``param`` (its translate, rotate or scale, or
    ``camera.translate.x|y|z`` as in :func:`~sphere3d.closed_form.triangle_image`; module docstring), at
    the parameter's offset ``theta``; ``vertices``: the front faces' projected triangles (F, 3, 2)."""
    scene = load_scene(scene)
    s = scene.shapes[0] if len(scene.shapes) == 1 else None
    if s is None or s.albedo != 0.0 or s.emission != 0.0:
        raise ValidationError("scene.shapes", "must hold one black shape (albedo 0, emission 0)")
    dual = variable(float(theta)) if param is not None else 0.0
    if param is not None and param.startswith("camera."):
        # the camera and its look-at point move together: the frame stays, every point shifts by -θ e_a
        axis = AXES.index(scene.check_param(param).rpartition(".")[2])
        world = mesh_vertices(scene) - np.eye(3)[axis] * dual
    else:
        world = mesh_vertices(scene, param, dual)
    faces = s.mesh.faces
    plain = np.asarray(detach(world))
    tri = plain[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    centre = plain.mean(axis=0)
    outward = np.sign(np.sum(normal * (tri.mean(axis=1) - centre), axis=1))  # either winding
    front = np.sum(outward[:, None] * normal * (tri[:, 0] - np.asarray(scene.camera.position)), axis=1) < 0.0
    x, y = project(scene.camera, world)
    film = np.stack([np.asarray(detach(x)), np.asarray(detach(y))], axis=-1)
    velocity = np.stack([np.asarray(tangent(x)), np.asarray(tangent(y))], axis=-1) * (param is not None)
    cam = scene.camera
    rows, cols = np.divmod(np.arange(cam.width * cam.height), cam.width)
    centres = np.stack([cols + 0.5, rows + 0.5], axis=-1)
    coverage, derivative = np.zeros(len(centres)), np.zeros(len(centres))
    for f in faces[front]:  # a few dozen front faces: one closed form each
        coverage += polygon_filter_integral(film[f], centres, cam.filter)
        derivative -= scene.sky * polygon_filter_derivative(film[f], velocity[f], centres, cam.filter)
    return TriangleImage(
        value=scene.sky * (1.0 - coverage.reshape(cam.height, cam.width)),
        derivative=derivative.reshape(cam.height, cam.width) + 0.0,
        coverage=coverage.reshape(cam.height, cam.width),
        vertices=film[faces[front]],
    )
