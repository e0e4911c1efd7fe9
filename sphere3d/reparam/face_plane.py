r"""The face's own plane in a cosine kernel at a smooth-shaded point: probes below it are misses, and
the kernel follows its great circle where it follows nothing else.

At a point x of a smooth-shaded mesh the shading normal $n_s$ differs from its face's normal $n_g$.
Rays leave x from $x + ε n_g$ (:class:`~sphere3d.integrator.Shading`), so a direction ω above the
shading horizon ($ω·n_s > 0$) but below the face's plane ($ω·n_g < 0$) meets the face itself, about
$ε / |ω·n_g|$ away: the cosine strategy's integrand $L_i(ω) \cos θ$ is the surface's own radiance there
and the scene's above the plane. It jumps along the plane's great circle $\{ω : ω·n_g = 0\}$ (the
terminator of smooth shading; on a convex mesh every ray below the plane meets the mesh). That circle
moves with $n_g(θ)$ alone, not with x: a translation leaves it where it is, a turn Ω of the shape moves
it by $\dot n_g = Ω × n_g$.

Two rules amend the probe heuristic (Loubet et al. 2019, Sec. 4.3) there:

- a probe below the face's plane counts as a miss (:func:`below_face`), as one below the shading
  horizon does: its hit is a point of the face, whose direction from x turns *in* the plane at
  $|\dot x - v| / r$ (r its distance, down to ε / sin of the probe's angle below the plane) while the
  circle does not turn under a translation: followed, that point drags the rest of the kernel at that
  rate (kernel weights' tangents of $10^3$ and more: a heavy tail, and a bias where the kernel holds
  another edge);
- where the rule then follows nothing and the circle is within the kernel's reach, the rotation
  follows the circle (:func:`face_plane_rotation`): the foot $d ∝ c - (c·n_g) n_g$ of the kernel's
  centre c on it, moving with $n_g(θ)$, and a turn about d at the rate $\dot ψ = (n_g × \dot n_g)·d$,
  so that the angular velocity is $Ω_⊥ = n_g × \dot n_g$ and $Ω_⊥ × n_g = \dot n_g$: every direction
  of the circle stays on the moving circle.

Assumed: x lies on the face (a camera hit or a path vertex), the face's neighbours do not reach above
its plane within the kernel (convex near x; a ray below the plane that passes the face's edge, a
sliver of angle ε / distance, is neglected). Biased where the kernel holds the circle and another
discontinuity that moves otherwise: the rule follows that one and drags the circle (the paper's limit
of one rotation per kernel; tests/sphere3d/test_face_plane.py measures both cases).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flatland.core.dual import Dual, detach, tangent
from sphere3d.integrator import Shading
from sphere3d.live import any_rows, moves
from sphere3d.rotation import Rotation
from sphere3d.vector import cross, dot

__all__ = ["below_face", "face_plane_rotation", "smooth_rows"]


def smooth_rows(shading: Shading) -> np.ndarray:
    """Where the shading normal differs from the face's (a smooth-shaded face): (n,) bool; none
    without a geometric normal (:attr:`~sphere3d.integrator.Shading.geometric`)."""
    if shading.geometric is None:
        return np.zeros(len(shading), dtype=bool)
    return any_rows(np.asarray(detach(shading.n)) != np.asarray(detach(shading.geometric)))


def below_face(shading: Shading, directions: np.ndarray) -> np.ndarray:
    """Which ``directions`` (n, P, 3) lie on or below the shading horizon or the face's plane: (n, P)."""
    below = dot(directions, np.asarray(detach(shading.n))[:, None]) <= 0.0
    if shading.geometric is None:
        return below
    return below | (dot(directions, np.asarray(detach(shading.geometric))[:, None]) <= 0.0)


def face_plane_rotation(shading: Shading, centre: np.ndarray, reach: Any, rotation: Rotation) -> Rotation:
    r"""``rotation``, and where it is the identity at a smooth-shaded point whose face turns and whose
    plane's great circle passes within the angle ``reach`` (one, or (n,)) of the kernel's unit
    ``centre`` (n, 3), the rotation following that circle (module docstring)."""
    smooth = smooth_rows(shading)
    if not smooth.any():
        return rotation
    g = shading.geometric
    near = np.abs(dot(centre, np.asarray(detach(g)))) < np.sin(np.minimum(reach, 0.5 * np.pi))
    rows = np.flatnonzero(smooth & near & ~rotation.active & any_rows(moves(g)))
    if not rows.size:
        return rotation
    g_r, c = g[rows], centre[rows]
    # the foot of c on the circle {ω·n_g = 0}: moves across the circle as n_g(θ) does
    foot = c - dot(c, g_r)[:, None] * g_r
    g0, g_dot = np.asarray(detach(g_r)), tangent(g_r)
    d0 = np.asarray(detach(foot))
    d0 = d0 / np.linalg.norm(d0, axis=-1, keepdims=True)
    # the turn about d: Ω⊥ = n_g × ṅ_g has the part (Ω⊥·d) d the foot's motion does not give
    spin = Dual(np.zeros(rows.size), dot(cross(g0, g_dot), d0), g.k)
    plane = Rotation.following(foot, np.ones(rows.size, dtype=bool), spin)
    return _merged(rotation, plane, rows)


def _merged(rotation: Rotation, plane: Rotation, rows: np.ndarray) -> Rotation:
    """``rotation`` with the rows ``rows`` (where it is the identity) replaced by ``plane``'s."""
    target = rotation.target * 1.0  # a copy: Dual or plain, its k tangents kept
    target[rows] = plane.target
    active = rotation.active.copy()
    active[rows] = plane.active
    k = target.k
    shape = rotation.active.shape if k is None else (k, *rotation.active.shape)
    spin_dot = np.zeros(shape) if rotation.spin is None else np.array(tangent(rotation.spin), copy=True)
    spin_dot[..., rows] = tangent(plane.spin)
    return Rotation(target, active, Dual(np.zeros(rotation.active.shape), spin_dot, k))
