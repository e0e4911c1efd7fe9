"""Central finite differences with common random numbers."""

from __future__ import annotations

import numpy as np

from flatland.core.contract import Estimate, Option
from flatland.core.dual import Dual, detach
from flatland.core.translation import central_difference
from flatland.core.validate import check_positive
from flatland.integrals import Integrand
from flatland.textbook._common import METHODS, primary_samples, to_estimate


@METHODS.register("finite_difference", Option("h", 1e-2, check_positive))
def finite_difference(integrand: Integrand, theta: float, n: int, seed: int, h: float) -> Estimate:
    """Central difference $[Î(θ + h) - Î(θ - h)] / 2h$ with the same samples at both ends.

    Common random numbers make the two estimates correlated, so their difference
    only sees the samples whose integrand changed: near a discontinuity, within
    $h |c'|$ of it. Assumes nothing about continuity, but is biased by the
    truncation error: its expectation is exactly $[I(θ + h) - I(θ - h)] / 2h$, which is
    $I'(θ) + h^2 I'''(θ) / 6 + O(h^4)$ where I is smooth. Its variance grows like $1/h$ at a
    jump (like $1/h^2$ without common random numbers). Not part of the paper: the
    reference every gradient is checked against.
    """
    integrand.check_theta(theta - h, "theta - h")
    integrand.check_theta(theta + h, "theta + h")
    s = primary_samples(integrand, n, seed)

    def estimates(t: float) -> np.ndarray:  # per-sample f(x_i, t) / p(x_i), the same x_i at every t
        return detach(integrand.f(s.x, t)) / s.pdf

    # per-sample central difference as the tangent: common random numbers cancel everything that did not move
    per_sample = Dual(estimates(theta), central_difference(estimates, theta, h))
    return to_estimate(per_sample, n, "finite_difference", {"h": h})
