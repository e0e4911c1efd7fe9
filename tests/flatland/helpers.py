"""Helpers shared by the flatland plotting tests."""

from __future__ import annotations

import numpy as np

from flatland.core.image import GradientImage
from flatland.plotting import films


def capture_figures(monkeypatch, module):
    """Figures ``module`` saves through ``save_png``, in order (they are written as usual)."""
    figures = []
    original = films.save_png

    def keep(fig, path):
        figures.append(fig)
        return original(fig, path)

    monkeypatch.setattr(module, "save_png", keep)
    return figures


def gradient_image(derivative, method="reparam"):
    """A gradient image of ``derivative`` with made-up value and standard errors."""
    derivative = np.asarray(derivative, dtype=np.float64)
    return GradientImage(
        value=np.abs(derivative) + 0.5,
        derivative=derivative,
        value_stderr=np.full(derivative.shape, 0.01),
        derivative_stderr=np.full(derivative.shape, 0.02),
        param="occluder.translate.x",
        method=method,
        spp=16,
        seed=0,
        batches=4,
        scene="test",
    )
