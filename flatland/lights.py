"""Emitter sampling for the shading integral: which emitter, which direction, and its density.

The light-sampling technique picks an emitter e with probability $P(e)$ proportional
to its power (radiance × length × (1 - fade) for segments, radiance × diameter
for circles) and a direction toward it: a point uniform on a segment
(:func:`~flatland.sampling.sample_segment_direction`), or a direction uniform in
the cone a circle subtends (:func:`~flatland.sampling.sample_circle_direction`).
The technique only *proposes* directions: the renderer traces the ray and takes
whatever it hits, so the technique's density at a direction φ is the mixture
$p_l(φ) = Σ_e P(e) p_e(φ)$ over every emitter the ray from x would meet, occluded or
not (:meth:`Lights.pdf`). That is the density multiple importance sampling needs
(Veach's balance heuristic), and it keeps the combined estimator unbiased when
emitters overlap in angle.

Everything here is evaluated on the detached geometry at θ0: the proposal is a
fixed, θ-free density, which is what the gradient methods require (Loubet et al. 2019, Sec. 3.2).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from flatland.core.dual import detach
from flatland.sampling import (
    pdf_circle_direction,
    pdf_segment_direction,
    sample_circle_direction,
    sample_segment_direction,
)
from flatland.state import SceneState

__all__ = ["Lights"]


@dataclass(frozen=True)
class Lights:
    """The emitters of a geometry (at θ0) and their selection probabilities."""

    geom: SceneState  # detached
    prims: np.ndarray  # emitter primitive indices
    probs: np.ndarray  # P(e)
    cdf: np.ndarray  # cumulative P(e), last entry 1

    @classmethod
    def of(cls, geom: SceneState) -> Lights:
        """Emitters of ``geom`` (values only)."""
        g = geom.detached()
        prims = g.emitters()
        power = np.zeros(prims.size)
        for i, k in enumerate(prims):
            if k < g.n_seg:
                length = float(np.hypot(*(g.seg_b[k] - g.seg_a[k])))
                power[i] = g.emission[k] * length * (1.0 - g.fade[k])
            else:
                power[i] = g.emission[k] * 2.0 * g.circ_r[k - g.n_seg]
        probs = power / power.sum() if prims.size else power
        return cls(g, prims, probs, np.cumsum(probs))

    @property
    def empty(self) -> bool:
        """True when the scene has no emitter to sample (the sky is reached by cosine sampling)."""
        return self.prims.size == 0

    def _technique(self, k: int) -> tuple[Callable[..., np.ndarray], Callable[..., np.ndarray], tuple]:
        """Sampler, density and shape arguments (after ``u``/``phi`` and ``x``) for emitter primitive k."""
        g = self.geom
        if k < g.n_seg:
            return sample_segment_direction, pdf_segment_direction, (g.seg_a[k], g.seg_b[k])
        j = k - g.n_seg
        return sample_circle_direction, pdf_circle_direction, (g.circ_c[j], g.circ_r[j])

    def sample(
        self, u_choice: np.ndarray, u_point: np.ndarray, x: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Directions (angles) from points ``x`` (n, 2) toward emitters chosen by ``u_choice``.

        Returns the angles and the chosen emitters' primitive indices (a shading point
        that picks the emitter it lies on gets a direction along its own surface, where
        the integrand is zero; the renderer drops those samples).
        """
        x = np.asarray(detach(x))
        choice = np.minimum(np.searchsorted(self.cdf, u_choice, side="right"), self.prims.size - 1)
        phi = np.zeros(np.shape(u_choice))
        for i, k in enumerate(self.prims):  # a handful of emitters, each vectorized over its samples
            rows = np.flatnonzero(choice == i)
            if rows.size:
                sample, _, shape = self._technique(k)
                phi[rows] = sample(u_point[rows], x[rows], *shape)
        return phi, self.prims[choice]

    def pdf(self, phi: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Density $p_l(φ) = Σ_e P(e) p_e(φ)$ of the light technique at directions ``phi`` from ``x``."""
        x = np.asarray(detach(x))
        out = np.zeros(np.shape(phi))
        for i, k in enumerate(self.prims):
            _, pdf, shape = self._technique(k)
            out += self.probs[i] * pdf(phi, x, *shape)
        return out
