"""The textbook table: every method's derivative and its interval next to the closed form, flags explained.

For each integral of :data:`flatland.integrals.INTEGRALS` at its default θ, each
estimator of :func:`flatland.estimate` runs once with the same seed, and its
derivative is set against the closed-form dI/dθ. Each row prints the estimate with its
:data:`~flatland.core.stats.LEVEL` interval, the intervals of the table's rows
simultaneous (:func:`~flatland.core.stats.family_quantile`); ``BIASED`` flags a row whose
interval excludes the closed form (:func:`~flatland.core.bias.error_interval`): a bias the
samples resolve. An estimate without spread (every sample gave the same number) is
printed as exact, with no z.

The reparameterization without a kernel sits beside its kernel variants: one
translation per sample cannot follow two jumps moving at different speeds (Loubet et
al. 2019, Sec. 4.2), the case for convolution kernels. Under the table, one line per
flagged row says why it is biased, with the bias predicted for it where the estimator
has a closed form for its bias (naive: minus the jump term, Sec. 3.2; the translation
without a kernel: :func:`~flatland.textbook.reparam.translation_bias`). Computed at run
time; nothing in the table is stored.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from flatland.app.table import (
    format_exact,
    format_interval,
    format_level,
    format_number,
    format_table,
    format_z,
)
from flatland.core import progress as _progress
from flatland.core.bias import ErrorInterval, error_interval
from flatland.core.dual import detach, variable
from flatland.core.image import Options
from flatland.core.stats import LEVEL, family_quantile
from flatland.core.validate import check_int, check_seed
from flatland.integrals import INTEGRALS, Circle
from flatland.textbook import estimate
from flatland.textbook.reparam import translation_bias

__all__ = ["DEFAULT_METHODS", "TextbookRow", "explain", "textbook_rows", "textbook_table"]

DEFAULT_METHODS: tuple[tuple[str, Mapping[str, Any]], ...] = (
    ("naive", {}),
    ("finite_difference", {}),
    ("boundary", {}),
    ("reparam", {}),
    ("reparam", {"kappa": 100.0}),
    ("reparam", {"kappa": 100.0, "paired": True}),
)
"""The (method, options) rows of each integral, the translation without a kernel beside its kernels."""


@dataclass(frozen=True)
class TextbookRow:
    """One method on one integral: its estimate, the closed form and the test against it.

    ``quantile`` is the half-width of the row's interval in standard errors (one row of a
    table at :data:`~flatland.core.stats.LEVEL`, :func:`~flatland.core.stats.family_quantile`).
    """

    integral: str
    title: str
    theta: float
    method: str
    options: Mapping[str, Any] = field(default_factory=dict)
    derivative: float = 0.0
    stderr: float = 0.0
    closed_form: float = 0.0
    n: int = 0
    seed: int = 0
    quantile: float = family_quantile(1)

    def __post_init__(self) -> None:
        object.__setattr__(self, "options", Options(self.options))

    @property
    def label(self) -> str:
        """The method and its options as the table names them: ``reparam, kernel kappa=100, paired``."""
        if self.method != "reparam":
            return self.method
        kappa, paired = self.options.get("kappa"), self.options.get("paired")
        if kappa is None:
            return "reparam, no kernel"
        return f"reparam, kernel kappa={kappa:g}" + (", paired" if paired else "")

    @property
    def test(self) -> ErrorInterval:
        """The error against the closed form with its interval (the closed form has no noise)."""
        return error_interval(self.derivative, self.closed_form, self.stderr, 0.0, self.quantile)

    @property
    def z(self) -> float:
        """(derivative - closed form) / stderr; 0 within rounding, ±inf for a miss without spread."""
        return self.test.z

    @property
    def flagged(self) -> bool:
        """True if the row's interval excludes the closed form."""
        return self.test.biased

    def estimate_text(self) -> str:
        """``+1.60 [+0.77, +2.42]``, or ``0 exactly (σ = 0)`` for an estimate without spread."""
        t = self.test
        if not self.stderr > 0.0:
            return format_exact(self.derivative)
        return format_interval(self.derivative, self.closed_form + t.low, self.closed_form + t.high)


def textbook_rows(
    n: int = 20_000,
    seed: int = 0,
    methods: Sequence[tuple[str, Mapping[str, Any]]] = DEFAULT_METHODS,
    integrals: Sequence[str] | None = None,
    progress: bool | None = None,
) -> tuple[TextbookRow, ...]:
    """Run every method on every integral (at its default θ) with ``n`` samples and ``seed``.

    ``progress``: a progress bar per estimate (None: when stderr is a terminal,
    :mod:`flatland.core.progress`).
    """
    n = check_int("n", n)
    seed = check_seed("seed", seed)
    names = list(INTEGRALS if integrals is None else integrals)
    quantile = family_quantile(len(names) * len(methods))  # the table's rows judged together
    rows = []
    with _progress.run("textbook table", progress, unit="estimate"):
        _progress.start(len(names) * len(methods))
        for name in names:
            rows += _integral_rows(INTEGRALS[name], methods, n, seed, quantile)
    return tuple(rows)


def _integral_rows(
    integral: Any, methods: Sequence[tuple[str, Mapping[str, Any]]], n: int, seed: int, quantile: float
) -> list[TextbookRow]:
    """The rows of one integral, each estimate one step of the progress bar."""
    theta = integral.default_theta
    rows = []
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
                seed=seed,
                quantile=quantile,
            )
        )
        _progress.advance()
    return rows


def _measured(row: TextbookRow) -> str:
    """The measured bias, to two significant digits of its interval's half-width; exact without spread."""
    t = row.test
    if row.stderr > 0.0:
        return f"{format_number(t.error, t.halfwidth)} measured"
    return f"{t.error:+#.3g} measured (σ = 0)"


def explain(row: TextbookRow, rows: Sequence[TextbookRow] = ()) -> str:
    """One line saying why a flagged row is biased: the mechanism, and the bias predicted against the one
    measured where the estimator's bias has a closed form. ``rows`` (the table) lets the line of a
    translation without a kernel quote its kernel variant on the same integral."""
    integral = INTEGRALS[row.integral]
    head = f"{row.integral}, {row.label}:"
    measured = _measured(row)
    if row.method == "naive":
        term = integral.discontinuity_term(row.theta)
        drops = "drops the moving jumps' term Σ [f(c-) - f(c+)] c'(θ)"
        return f"{head} {drops}: bias {-term:+#.3g} predicted, {measured}"
    if row.method == "reparam" and row.options.get("kappa") is None:
        kernel = next(
            (r for r in rows if r.integral == row.integral and r.method == "reparam"
             and r.options.get("kappa") is not None and not r.flagged),
            None,
        )  # fmt: skip
        beside = (
            f"; with kernel kappa={kernel.options['kappa']:g}: {kernel.estimate_text()}" if kernel else ""
        )
        predicted = translation_bias(integral, row.theta)
        return (
            f"{head} {_jumps(integral, row.theta)}; one translation per sample follows only the nearer:"
            f" bias {predicted:+#.3g} predicted, {measured}{beside}"
        )
    if row.method == "reparam":
        reach = "its kernel reaches a jump the translation does not follow (less as kappa grows)"
        return f"{head} {reach}; {measured}"
    if row.method == "finite_difference":
        return f"{head} truncation error h² I'''/6 (O(1) at a jump within h), or a false alarm; {measured}"
    return f"{head} no bias is expected: a false alarm (1 - {LEVEL:g} for the whole table) or a defect"


def _jumps(integral: Any, theta: float) -> str:
    """``jumps at x = 2, 4 move at 2, 4 per unit θ`` from the integrand's discontinuities."""
    found = integral.discontinuities(variable(theta))
    axis = "φ" if integral.domain is Circle else "x"
    at = ", ".join(f"{float(detach(d.location)):.3g}" for d in found)
    speed = ", ".join(f"{float(d.location.tangent):.3g}" for d in found)
    return f"jumps at {axis} = {at} move at {speed} per unit θ"


def textbook_table(
    n: int = 20_000, seed: int = 0, rows: Sequence[TextbookRow] | None = None, progress: bool | None = None
) -> str:
    """The table as text: one block per integral, one line per method, a legend and one line per flag.

    Without ``rows`` it runs :func:`textbook_rows` (``progress``: its progress bar).
    """
    rows = textbook_rows(n, seed, progress=progress) if rows is None else rows
    level = format_level(LEVEL)
    lines = []
    previous = None
    for r in rows:
        first = r.integral != previous  # the integral's name, θ and closed form on its first line only
        previous = r.integral
        lines.append(
            (
                r.integral if first else "",
                f"{r.theta:g}" if first else "",
                f"{r.closed_form:+.5g}" if first else "",
                r.label,
                r.estimate_text(),
                format_z(r.z),
                "BIASED" if r.flagged else "",
            )
        )
    headers = ("integral", "θ", "closed form", "method", f"dI/dθ [{level} interval]", "z", "flag")
    n_used, seed_used = (rows[0].n, rows[0].seed) if rows else (n, seed)
    q = rows[0].quantile if rows else family_quantile(1)
    title = (
        f"Textbook integrals: each method's dI/dθ against the closed form ({n_used} samples each,"
        f" seed {seed_used})"
    )
    legend = [
        f"dI/dθ [{level} interval]: the estimate and its interval, simultaneous over the {len(rows)} rows"
        f" (each ± {q:.2f} stderr); (σ = 0): every sample gave the same number",
        f"z: (estimate - closed form) / stderr; BIASED exactly when the interval excludes the closed form"
        f" (|z| > {q:.2f}); — : no spread, no z",
        "reparam, no kernel: one translation per sample, following the nearest jump (Sec. 3.2, 4.1);"
        " kernel kappa: a convolution",
        "  kernel of concentration kappa (Sec. 4.2); paired: two kernel samples share a translation"
        " (theory/kernels)",
    ]
    flagged = [r for r in rows if r.flagged]
    if flagged:
        legend.append(
            f"Why the {len(flagged)} flagged rows are biased (naive: Loubet et al. 2019, Sec. 3.2;"
            " the translation without a kernel: Sec. 4.2):"
        )
        legend += [f"  {explain(r, rows)}" for r in flagged]
    return format_table(headers, lines, title) + "\n" + "\n".join(legend)
