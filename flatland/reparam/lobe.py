r"""The shading kernel at glossy points of flatland: a von Mises concentration per point that follows the
lobe's width (the 2D counterpart of :mod:`sphere3d.reparam.lobe`, whose docstring has the argument).

The convolution $∫ f(φ) dφ = ∫∫ f(φ) k_x(φ, ω) dφ dω$ holds for a kernel fixed at the point x (its
roughness at θ0), whatever the sample; given the kernel's centre ω the samples a translation must
carry lie where $p(φ) k_x(φ, ω)$ is large, the lobe itself when the kernel is wider than it. The
probes lie at ω ± ``spread`` $σ_k$, $σ_k = 1/\sqrt{κ}$ (:class:`~flatland.reparam.default.ReparamTransforms`):
the rule puts the outermost at most ``fraction`` times the lobe's radius $r_l$ from the centre,

$κ_x = \max(κ, (\mathrm{spread} / (\mathrm{fraction}\; r_l))^2)$

at glossy points, κ (the user's) at diffuse ones and as the lower bound (the rule binds only where the
lobe is narrower than the user's probe span: $r_l < 3 / \sqrt{1000}$, α < 0.082, at the defaults).

**The lobe's radius** (GGX on a profile, :mod:`flatland.bsdf`). The slopes are distributed as
$P_2(s) = α^2 / (2 (α^2 + s^2)^{3/2})$, so $P(|s| ≤ t) = t / \sqrt{α^2 + t^2}$ and the median slope
is $α / \sqrt 3$. In the plane the reflected angle is $b = 2 θ_h - a$, exactly: a facet tilted by
$θ_h = \arctan s$ moves the reflection by $2 θ_h$ at every incidence (no $\cos θ_i$ as across the plane
of incidence in 3D). Hence $r_l = 2 \arctan(α / \sqrt 3)$, the median of the reflection's deviation
under the distribution of normals (the visible normals shift it by a factor near 1 away from grazing).
Biased where the kernel, narrow as it is, still holds two discontinuities that move differently,
as at a diffuse point; the narrower kernel's weight has a larger derivative (variance of order κ).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flatland.core.validate import check_positive

__all__ = ["LOBE", "check_lobe", "lobe_kappa", "lobe_radius"]

LOBE = 1.0
"""Default of the ``reparam`` option ``lobe``: the outermost probe within the lobe's median radius."""


def check_lobe(name: str, value: Any) -> float | None:
    """The option ``lobe``: a fraction > 0, or None (every point the user's κ)."""
    return None if value is None else check_positive(name, value)


def lobe_radius(alpha: np.ndarray) -> np.ndarray:
    r"""The 2D GGX lobe's median angular radius $r_l = 2 \arctan(α / \sqrt 3)$ (radians; module docstring)."""
    return 2.0 * np.arctan(np.asarray(alpha, dtype=np.float64) / np.sqrt(3.0))


def lobe_kappa(
    kappa: float, spread: float, fraction: float, radius: np.ndarray, glossy: np.ndarray
) -> np.ndarray:
    r"""Per-row von Mises concentrations: $\max(κ, (\mathrm{spread} / (\mathrm{fraction}\; r_l))^2)$ on
    ``glossy`` rows (``radius`` their $r_l$, :func:`lobe_radius`), ``kappa`` on the others; ``spread`` 0
    (every probe at the centre) gives ``kappa`` everywhere."""
    ring = (spread / (fraction * np.asarray(radius, dtype=np.float64))) ** 2
    return np.where(np.asarray(glossy, dtype=bool), np.maximum(kappa, ring), kappa)
