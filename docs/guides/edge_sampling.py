"""Edge sampling for the textbook integrals: the Leibniz jump term estimated by sampling one jump per sample.

The worked example of the guide "How to add an estimator". It is a complete estimator,
tested by ``tests/test_docs.py``, registered in a method table of its own so that
importing it leaves the package's table unchanged; a real new estimator registers in
``flatland.textbook._common.METHODS`` instead (step 5 of the guide).
"""

from __future__ import annotations

import numpy as np

from flatland.core.contract import Estimate, MethodTable
from flatland.core.dual import Dual, detach, tangent, variable
from flatland.core.rng import stream
from flatland.integrals import Integrand
from flatland.textbook._common import primary_samples, to_estimate

__all__ = ["EXAMPLE_METHODS", "edge_sampling"]

EXAMPLE_METHODS = MethodTable("example estimator")
"""The guide's own method table (a new estimator of the package uses ``METHODS``)."""


@EXAMPLE_METHODS.register("edge_sampling")
def edge_sampling(integrand: Integrand, theta: float, n: int, seed: int) -> Estimate:
    """Interior term by AD plus the jump term sampled: one jump per sample, chosen ∝ |jump · c'|.

    The Monte Carlo counterpart of :func:`flatland.textbook.boundary.boundary`, in the
    spirit of edge sampling (Li et al. 2018; Loubet et al. 2019, Sec. 2): instead of
    summing the Leibniz term ``Σ_j t_j``, ``t_j = [f(c_j⁻) - f(c_j⁺)] c_j'(θ)`` (theory/leibniz),
    each sample picks one jump J with probability ``P_j = |t_j| / Σ_k |t_k|``
    and adds ``t_J / P_J``. Unbiased whenever the list of jumps is complete:
    ``E[t_J / P_J] = Σ_j P_j t_j / P_j = Σ_j t_j``. The jump choice adds the variance
    ``(Σ|t_j|)² - (Σ t_j)²`` per sample, zero when all terms share a sign.

    Parameters
    ----------
    integrand : Integrand
        A textbook integral (it lists its jumps).
    theta : float
        Parameter value θ0 where the derivative is taken.
    n : int
        Number of samples.
    seed : int
        Seed; the primary samples are the naive estimator's, the jump choice comes
        from its own stream ``"edges"``.

    Returns
    -------
    Estimate
        Value (the naive estimate, sample for sample) and derivative with standard errors.
    """
    theta_d = variable(theta)
    s = primary_samples(integrand, n, seed)
    interior = integrand.f(s.x, theta_d) / s.pdf  # a Dual: value f/p, tangent ∂f/∂θ / p   (Sec. 3.1)
    # Leibniz jump terms t_j = (f(c-) - f(c+)) * dc/dtheta, one per listed jump   (theory/leibniz)
    terms = np.array([d.jump * float(tangent(d.location)) for d in integrand.discontinuities(theta_d)])
    total = float(np.abs(terms).sum())
    if total == 0.0:  # no jump moves: the interior term is the whole derivative
        return to_estimate(interior, n, "edge_sampling", {})
    prob = np.abs(terms) / total
    u = stream(seed, "edges").random(n)
    # inverse CDF of the discrete choice; a jump with P_j = 0 is never chosen, and u above a rounded-down
    # last CDF value goes to the last jump that can be chosen
    last = int(np.flatnonzero(prob)[-1])
    pick = np.minimum(np.searchsorted(np.cumsum(prob), u, side="right"), last)
    boundary = terms[pick] / prob[pick]  # t_J / P_J: unbiased for Σ_j t_j
    per_sample = Dual(detach(interior), tangent(interior) + boundary)
    return to_estimate(per_sample, n, "edge_sampling", {})
