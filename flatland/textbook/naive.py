"""The naive estimator: differentiate the Monte Carlo estimator as it stands.

Deliberately minimal: it is the baseline that is wrong at moving discontinuities.
"""

from __future__ import annotations

from flatland.core.contract import Estimate
from flatland.core.dual import variable
from flatland.integrals import Integrand
from flatland.textbook._common import METHODS, primary_samples, to_estimate


@METHODS.register("naive")
def naive(integrand: Integrand, theta: float, n: int, seed: int) -> Estimate:
    """Forward-mode derivative of $(1/N) Σ_i f(x_i, θ) / p(x_i)$ (Loubet et al. 2019, Sec. 3.1).

    Assumes f is continuous in θ at every sample (Loubet et al. 2019, Sec. 3.1). Where f has
    discontinuities that move with θ, each sample's derivative misses them and the
    estimate converges to the interior term $∫ ∂f/∂θ dx$ alone: it is biased by
    minus the discontinuity term $Σ_i [f(c_i^-) - f(c_i^+)] c_i'$ (Loubet et al. 2019, Sec. 3.2).
    The value estimate is unbiased.
    """
    theta_d = variable(theta)
    s = primary_samples(integrand, n, seed)
    return to_estimate(integrand.f(s.x, theta_d) / s.pdf, n, "naive", {})
