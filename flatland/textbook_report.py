"""The textbook table: every method's derivative ± standard error next to the closed form.

For each integral of :data:`flatland.integrals.INTEGRALS` at its default θ, each
estimator of :func:`flatland.estimate` runs once with the same seed, and its
derivative is set against the closed-form dI/dθ with its z-score, first. ``BIASED`` flags
a z-score beyond the two-sided 99.9 % normal quantile (3.29): a bias the samples
resolve, which is what naive differentiation shows at every moving discontinuity
(Loubet et al. 2019, Sec. 3.2) and the translation without a kernel shows where two
discontinuities move at different speeds (Sec. 4.2). Computed at run time; nothing
in the table is stored.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from flatland.app.table import format_table, method_label
from flatland.core.image import Options
from flatland.core.stats import normal_quantile
from flatland.core.validate import check_int, check_seed
from flatland.integrals import INTEGRALS
from flatland.textbook import estimate

__all__ = ["DEFAULT_METHODS", "Z_FLAG", "TextbookRow", "textbook_rows", "textbook_table"]

DEFAULT_METHODS: tuple[tuple[str, Mapping[str, Any]], ...] = (
    ("naive", {}),
    ("finite_difference", {}),
    ("boundary", {}),
    ("reparam", {}),
    ("reparam", {"kappa": 100.0}),
    ("reparam", {"kappa": 100.0, "paired": True}),
)
"""The (method, options) columns of the table."""

Z_FLAG = normal_quantile(0.999)
"""|z| beyond this (3.29) is flagged as a resolved bias."""


@dataclass(frozen=True)
class TextbookRow:
    """One method on one integral: its estimate, the closed form and the z-score."""

    integral: str
    title: str
    theta: float
    method: str
    options: Mapping[str, Any] = field(default_factory=dict)
    derivative: float = 0.0
    stderr: float = 0.0
    closed_form: float = 0.0
    n: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "options", Options(self.options))

    @property
    def label(self) -> str:
        """``reparam kappa=100 paired`` style name."""
        return method_label(self.method, self.options.items())

    @property
    def z(self) -> float:
        """(derivative - closed form) / stderr; 0 for an exact match, ±inf for an exact miss."""
        error = self.derivative - self.closed_form
        if self.stderr > 0.0:
            return error / self.stderr
        # no sampling error: exact up to rounding, or a deterministic miss
        return (
            0.0 if abs(error) <= 1e-12 * max(1.0, abs(self.closed_form)) else math.copysign(math.inf, error)
        )

    @property
    def flagged(self) -> bool:
        """True if |z| exceeds :data:`Z_FLAG`."""
        return abs(self.z) > Z_FLAG


def textbook_rows(
    n: int = 20_000,
    seed: int = 0,
    methods: Sequence[tuple[str, Mapping[str, Any]]] = DEFAULT_METHODS,
    integrals: Sequence[str] | None = None,
) -> tuple[TextbookRow, ...]:
    """Run every method on every integral (at its default θ) with ``n`` samples and ``seed``."""
    n = check_int("n", n)
    seed = check_seed("seed", seed)
    rows = []
    for name in INTEGRALS if integrals is None else integrals:
        integral = INTEGRALS[name]
        theta = integral.default_theta
        for method, options in methods:
            e = estimate(integral, theta, method=method, n=n, seed=seed, **options)
            rows.append(
                TextbookRow(
                    integral=integral.name,
                    title=integral.title,
                    theta=theta,
                    method=method,
                    options=options,
                    derivative=e.derivative,
                    stderr=e.derivative_stderr,
                    closed_form=integral.derivative(theta),
                    n=n,
                )
            )
    return tuple(rows)


def textbook_table(n: int = 20_000, seed: int = 0, rows: Sequence[TextbookRow] | None = None) -> str:
    """The table as text: one block per integral, one line per method (see the module docstring)."""
    rows = textbook_rows(n, seed) if rows is None else rows
    lines = []
    previous = None
    for r in rows:
        first = r.integral != previous  # the integral's name, θ and closed form on its first line only
        previous = r.integral
        lines.append(
            (
                r.integral if first else "",
                f"{r.theta:g}" if first else "",
                f"{r.closed_form:+.5f}" if first else "",
                r.label,
                f"{r.z:+.1f}",
                "BIASED" if r.flagged else "",
                f"{r.derivative:+.5f} ± {r.stderr:.5f}",
            )
        )
    headers = ("integral", "θ", "closed form", "method", "z", "flag", "dI/dθ ± stderr")
    n_used = rows[0].n if rows else n
    title = (
        f"Textbook integrals: derivative estimates vs closed forms ({n_used} samples each; "
        f"z = (estimate - closed form) / stderr; |z| > {Z_FLAG:.2f} flags a resolved bias: BIASED)"
    )
    return format_table(headers, lines, title)
