r"""Materials at shading points of a scene with glossy shapes: the reflection lobe, its sample and density.

A shading point x seen along the direction $φ_i$ (towards the camera or the previous path vertex)
reflects $L_r(x) = ∫ L_i(x, φ) w(φ)\, dφ$ with the lobe

- $w(φ) = (ρ/2) \max(0, \cos(φ - φ_n))$ on a diffuse primitive (BRDF ρ/2, theory/radiometry);
- $w(φ) = f(φ_i, φ) \max(0, \cos(φ - φ_n))$ on a glossy one, f the GGX BSDF of :mod:`flatland.bsdf`
  with the primitive's roughness α and its albedo as the Fresnel reflectance F.

Its BSDF sample is the cosine sample $φ - φ_n = \arcsin(2u - 1)$ (density $\cos / 2$) on a
diffuse row and :func:`~flatland.bsdf.sample_ggx` (density :func:`~flatland.bsdf.pdf_ggx`) on a
glossy one; :func:`flatland.integrator.shade` combines it with the emitter sample by the balance
heuristic. Samples and densities are θ-free (drawn from and evaluated on detached values), the
lobe :func:`weight` is Dual-aware in every argument: $φ_i$, the normal, α and the albedo (theory/bsdf).

A scene without glossy shapes never builds a :class:`Lobe` (:func:`lobe_at` returns None), so its
shading runs the diffuse code as before, bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.bsdf import eval_ggx, pdf_ggx, sample_ggx
from flatland.core.dual import detach
from flatland.state import SceneState

__all__ = ["Lobe", "angle_of_vector", "lobe_at", "pdf", "sample", "weight"]


@dataclass(frozen=True)
class Lobe:
    """The materials of n shading points: ``glossy`` (n,) bool, ``phi_i`` (n,) the angle towards the
    viewer, ``alpha`` (n,) the roughness (1.0 on diffuse rows, where it is not used) and ``albedo``
    (n,) ρ or F. ``phi_i``, ``alpha`` and ``albedo`` may be Duals."""

    glossy: np.ndarray
    phi_i: Any
    alpha: Any
    albedo: Any

    def take(self, rows: np.ndarray) -> Lobe:
        """The lobes of ``rows`` (an index array; repeats allowed)."""
        return Lobe(self.glossy[rows], self.phi_i[rows], self.alpha[rows], self.albedo[rows])


def angle_of_vector(v: Any) -> Any:
    """The angle of 2D vectors ``v`` (n, 2), Dual-aware."""
    return np.arctan2(v[:, 1], v[:, 0])


def lobe_at(geom: SceneState, prim: np.ndarray, arriving: Any) -> Lobe | None:
    """The lobes of points on primitives ``prim`` reached along directions ``arriving`` (n, 2), or None
    when none of them is glossy (the diffuse shading of :func:`flatland.integrator.shade`)."""
    glossy = geom.glossy[prim]
    if not np.any(glossy):
        return None
    alpha = np.where(glossy, geom.roughness[prim], 1.0)  # a valid α on diffuse rows, never used there
    return Lobe(glossy, angle_of_vector(-arriving), alpha, geom.albedo[prim])


def sample(lobe: Lobe, u: np.ndarray, phi_n0: np.ndarray) -> np.ndarray:
    """Plain BSDF-sample angles from uniforms ``u`` (n,) about the detached normal angles ``phi_n0``."""
    cosine = phi_n0 + np.arcsin(2.0 * u - 1.0)  # φ - φn = arcsin(2u - 1)   (theory/radiometry)
    gloss = sample_ggx(u, detach(lobe.phi_i), phi_n0, detach(lobe.alpha))
    return np.where(lobe.glossy, gloss, cosine)


def pdf(lobe: Lobe, phi: np.ndarray, phi_n0: np.ndarray) -> np.ndarray:
    """The BSDF sample's density per radian at plain angles ``phi``, θ-free: $\\cos_0/2$ or pdf_ggx."""
    cosine = 0.5 * np.maximum(np.cos(phi - phi_n0), 0.0)
    gloss = pdf_ggx(phi, detach(lobe.phi_i), phi_n0, detach(lobe.alpha))
    return np.where(lobe.glossy, gloss, cosine)


def weight(lobe: Lobe, phi: Any, normal_angle: Any, cos: Any) -> Any:
    r"""The lobe $w(φ)$ at angles ``phi`` for normals at ``normal_angle`` with cosines ``cos``
    ($\cos(φ - φ_n)$, the caller's dot product): $(ρ/2) \max(0, \cos)$ or $f_\mathrm{GGX} \cos$."""
    diffuse = 0.5 * lobe.albedo * np.where(detach(cos) > 0.0, cos, 0.0)
    gloss = eval_ggx(lobe.phi_i, phi, normal_angle, lobe.alpha, lobe.albedo) * cos  # f = 0 where cos <= 0
    return np.where(lobe.glossy, gloss, diffuse)


def weight_plain(lobe: Lobe, phi: np.ndarray, phi_n0: np.ndarray) -> np.ndarray:
    """:func:`weight` on detached values at plain angles ``phi`` (the boundary method's jump points)."""
    plain = Lobe(lobe.glossy, detach(lobe.phi_i), detach(lobe.alpha), detach(lobe.albedo))
    return weight(plain, phi, phi_n0, np.cos(phi - phi_n0))
