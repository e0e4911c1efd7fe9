"""The four textbook estimators of the 1D integrals of :mod:`flatland.integrals`, behind :func:`estimate`.

The image gradient methods, which have the same names, are in :mod:`flatland.methods`.

========================  =====================================================
``naive``                 differentiate the estimator (biased at moving jumps)
``finite_difference``     central difference, common random numbers, step ``h``
``boundary``              interior term + exact discontinuity term (edge sampling)
``reparam``               translation following the nearest discontinuity;
                          options ``kappa`` (convolution kernel), ``paired``
========================  =====================================================
"""

from __future__ import annotations

from typing import Any

from flatland.core.contract import Estimate
from flatland.core.validate import check_int, check_seed
from flatland.integrals import Integrand, get_integral
from flatland.textbook import boundary as _boundary  # noqa: F401  (registers the method)
from flatland.textbook import finite_difference as _finite_difference  # noqa: F401
from flatland.textbook import naive as _naive  # noqa: F401
from flatland.textbook import reparam as _reparam  # noqa: F401
from flatland.textbook._common import METHODS

__all__ = ["METHODS", "estimate"]


def estimate(
    integrand: str | Integrand,
    theta: float,
    method: str = "naive",
    n: int = 10_000,
    seed: int = 0,
    **options: Any,
) -> Estimate:
    """Estimate a textbook integral and its derivative at ``theta`` with one method.

    Parameters
    ----------
    integrand : str or Integrand
        A name from :data:`flatland.integrals.INTEGRALS` or an Integrand.
    theta : float
        Parameter value θ0 where the derivative is taken.
    method : {"naive", "finite_difference", "boundary", "reparam"}
        The estimator.
    n : int
        Number of samples (integrand evaluations), >= 1.
    seed : int
        Seed; the same seed gives the same numbers, and every method draws the
        same primary samples from it.
    **options
        Method options: ``h`` (finite_difference), ``kappa`` and ``paired`` (reparam).

    Returns
    -------
    Estimate
        Value and derivative with standard errors.

    Raises
    ------
    ValueError
        Naming the argument and value: unknown method or option, ``n < 1``, NaN or
        out-of-range ``theta``, ``kappa <= 0``, ``h <= 0``.
    """
    integrand = get_integral(integrand)
    method_spec = METHODS.lookup(method)
    n = check_int("n", n)
    seed = check_seed("seed", seed)
    theta = integrand.check_theta(theta)
    resolved = METHODS.resolve_options(method_spec.name, options)
    return method_spec.func(integrand, theta, n, seed, **resolved)
