"""The boundary estimator: interior term by AD plus the exact discontinuity term (edge sampling)."""

from __future__ import annotations

from flatland.core.contract import Estimate
from flatland.core.dual import variable
from flatland.integrals import Integrand
from flatland.textbook._common import METHODS, primary_samples, to_estimate


@METHODS.register("boundary")
def boundary(integrand: Integrand, theta: float, n: int, seed: int) -> Estimate:
    """Naive interior term plus $Σ_i [f(c_i^-) - f(c_i^+)] c_i'(θ)$ computed exactly (theory/boundary).

    In 1D the discontinuities are points that the integrand enumerates, so the
    boundary term of the Leibniz rule needs no sampling: it is added as a constant
    and contributes no variance. Unbiased whenever the list of discontinuities is
    complete; this is the role edge sampling plays in Li et al. 2018, and the
    reference the reparameterization is judged against.
    """
    theta_d = variable(theta)
    s = primary_samples(integrand, n, seed)
    interior = integrand.f(s.x, theta_d) / s.pdf
    # discontinuity term: (f(c-) - f(c+)) * dc/dtheta, summed   (Leibniz rule, theory/leibniz)
    term = sum(d.jump * float(d.location.tangent) for d in integrand.discontinuities(theta_d))
    return to_estimate(interior, n, "boundary", {}, extra_derivative=float(term))
