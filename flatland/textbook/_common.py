"""Pieces shared by the textbook estimators: the method table, primary samples, the result."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core.contract import Estimate, MethodTable
from flatland.core.dual import detach, tangent
from flatland.core.image import check_finite_result
from flatland.core.rng import stream
from flatland.core.stats import summarize
from flatland.integrals import Integrand

METHODS = MethodTable("estimator")
"""Textbook estimators by name; see :mod:`flatland.core.contract` for how to add one."""


@dataclass(frozen=True)
class Samples:
    r"""Primary samples $x_i \sim p$ (θ-independent) and their density $p(x_i)$."""

    x: np.ndarray
    pdf: np.ndarray


def primary_samples(integrand: Integrand, n: int, seed: int) -> Samples:
    """The ``n`` proposal samples every method draws first, from the ``"samples"`` stream.

    All methods given the same seed see these same samples (Loubet et al. 2019, Sec. 3.2).
    """
    x = integrand.sample(stream(seed, "samples").random(n))
    return Samples(x=x, pdf=integrand.pdf(x))


def to_estimate(
    per_sample: Any, n: int, method: str, options: dict[str, Any], extra_derivative: float = 0.0
) -> Estimate:
    """Estimate from i.i.d. per-sample contributions (a Dual or a plain array).

    ``extra_derivative`` is a deterministic term added to the derivative (the exact
    discontinuity term of the boundary estimator); it adds no variance.
    """
    check_finite_result("per-sample values", np.asarray(detach(per_sample)))
    check_finite_result(f"per-sample derivatives ({method})", np.asarray(tangent(per_sample)))
    values = summarize(detach(per_sample))
    derivs = summarize(tangent(per_sample))
    return Estimate(
        value=float(values.mean),
        derivative=float(derivs.mean) + extra_derivative,
        value_stderr=float(values.stderr),
        derivative_stderr=float(derivs.stderr),
        n=n,
        method=method,
        options=options,
    )
