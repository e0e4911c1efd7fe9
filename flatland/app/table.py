"""Text for the command line: fixed-width tables (study results, error tables, the textbook table), the
short names of methods with their options that label their rows, legends and figures, and numbers
written with the digits their uncertainty supports.

Rounding rule (:func:`format_number`): an estimate is written to two significant digits of the
uncertainty printed with it (the half-width of its interval), so ``+12.5 [+5.6, +19.4]``, never
``+12.53 ± 7`` or ``+3.004 [-4, +10]``; an estimate with no spread at all (every sample gave the same
number) is written with six significant digits and marked ``(σ = 0)``, never given a z of ±inf.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

__all__ = [
    "error_table",
    "format_exact",
    "format_interval",
    "format_level",
    "format_number",
    "format_table",
    "format_z",
    "method_label",
    "own_method_note",
]


def method_label(method: str, options: Iterable[tuple[str, Any]] = ()) -> str:
    """``method`` followed by its ``(name, value)`` options, e.g. ``reparam kappa=100 paired``.

    A True option shows its name only; False and None options are left out; floats
    are written with ``%g`` (``kappa=100``, ``h=0.01``).
    """
    parts = [method]
    for k, v in options:
        if v is None or v is False:
            continue
        parts.append(k if v is True else f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}")
    return " ".join(parts)


def format_table(headers: Sequence[str], rows: Sequence[Sequence[str]], title: str = "") -> str:
    """Columns padded to their widest cell: the first left-aligned, the others right-aligned."""
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(headers)]

    def line(cells: Sequence[str]) -> str:
        padded = [
            c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths, strict=True))
        ]
        return "  ".join(padded).rstrip()

    out = [title] if title else []
    out += [line(headers), line(["-" * w for w in widths]), *(line(r) for r in rows)]
    return "\n".join(out)


def format_number(value: float, spread: float) -> str:
    """``value`` (signed) to two significant digits of ``spread``, the uncertainty printed beside it.

    Fixed-point for magnitudes in [1e-3, 1e5) (``+12.5`` for 12.53 with spread 6.9, ``+1230`` for
    1234 with spread 220), else scientific with as many significant digits; a zero or
    non-finite spread: six significant digits (``%+.6g``).
    """
    value = float(value)
    if not math.isfinite(value):
        return f"{value:+}"
    if not (spread > 0.0 and math.isfinite(spread)):
        return f"{value:+.6g}"
    top = math.floor(math.log10(spread))  # the spread's first significant digit
    size = max(abs(value), spread)
    if 1e-3 <= size < 1e5:
        decimals = 1 - top  # two significant digits of the spread
        rounded = round(value, decimals) + 0.0  # + 0.0: no "-0"
        return f"{rounded:+.{max(decimals, 0)}f}"
    digits = max(math.floor(math.log10(size)) - top + 2, 2)
    return f"{value:+.{digits - 1}e}"


def format_level(level: float) -> str:
    """A coverage as text: 0.99 -> ``"99 %"``."""
    return f"{100.0 * level:.10g} %"


def format_interval(value: float, low: float, high: float) -> str:
    """``value [low, high]``, all three to two significant digits of the half-width.

    The rounding of :func:`format_number`, with the half-width ``(high - low) / 2`` as the spread.
    """
    half = 0.5 * (float(high) - float(low))
    return f"{format_number(value, half)} [{format_number(low, half)}, {format_number(high, half)}]"


def format_exact(value: float) -> str:
    """A number without spread: ``0 exactly (σ = 0)``, or six significant digits and ``(σ = 0)``."""
    return "0 exactly (σ = 0)" if value == 0.0 else f"{float(value):+.6g} (σ = 0)"


def format_z(z: float) -> str:
    """A z-score to one decimal; "—" for ±inf (a difference with no spread: there is no z to print)."""
    return f"{z:+.1f}" if math.isfinite(z) else "—"


def own_method_note(methods: Iterable[str], reference_method: str) -> str:
    """The footer line for a method judged by a reference made with that same method ('' if none).

    Finite differences against a finite-difference reference with the same step share
    its $O(h^2)$ bias, which then cancels: the table cannot show it.
    """
    if reference_method not in set(methods):
        return ""
    which = " (finite differences: O(h²))" if reference_method == "finite_difference" else ""
    return (
        f"{reference_method} is the reference's own method: a bias it has{which} is the reference's too"
        "\nand cancels here, so its rows cannot show it"
    )


def error_table(
    gradients: Mapping[str, Any], seconds: Mapping[str, float], reference: Any, title: str = ""
) -> str:
    """The demo's error table: each method's gradient image against a reference, bias tests first.

    Columns: rank (unbiased methods by relative error, then the flagged ones), ``flag``, the film
    sum ``Σ dI/dθ``, its error against the reference's with its :data:`~flatland.core.stats.LEVEL`
    interval (simultaneous over the table's rows, :func:`~flatland.core.bias.error_interval`;
    BIASED exactly when it excludes 0), the error's z, ``px |z|>t`` (pixels above the
    Sidak-corrected Student-t threshold of :func:`flatland.core.bias.pixel_test`, batches - 1
    degrees of freedom, out of the pixels tested; shown, not a flag: see
    :mod:`flatland.core.bias`), the relative error ``mean|g - g_ref| / max|g_ref|`` and the
    seconds. The film sums' standard errors come from the per-batch sums
    (:meth:`GradientImage.film_sum <flatland.core.image.GradientImage.film_sum>`): neighbouring
    pixels share samples under a splatted film and edge points, so their errors are correlated.
    The legend under the table says what every column counts.
    """
    from flatland.core.bias import error_interval, pixel_test
    from flatland.core.stats import LEVEL, family_level, family_quantile

    ref = reference.film_sum()  # standard errors from the per-batch sums (pixels may be correlated)
    q = family_quantile(max(len(gradients), 1))
    rows = []
    for method, g in gradients.items():
        s = g.film_sum()
        judged = error_interval(s.total, ref.total, s.stderr, ref.stderr, q)
        px = pixel_test(g.derivative, g.derivative_stderr, reference.derivative, reference.derivative_stderr,
                        g.batches - 1)  # fmt: skip
        rows.append((judged.biased, g.error_vs(reference), method, judged, px, s))
    rows.sort(key=lambda r: (r[0], r[1]))  # unbiased first, each part by relative error
    level = format_level(LEVEL)
    heads = ("method", "rank", "flag", "Σ dI/dθ", f"Σ - reference [{level} interval]", "z", "px |z|>t",
             "relative error", "seconds")  # fmt: skip
    body = [
        (method, str(k + 1), "BIASED" if biased else "",
         format_number(s.total, s.stderr) if s.stderr > 0.0 else format_exact(s.total),
         format_interval(e.error, e.low, e.high) if e.spread > 0.0 else format_exact(e.error),
         format_z(e.z), px.summary(), f"{error:.2g}", f"{seconds[method]:.2f}")
        for k, (biased, error, method, e, px, s) in enumerate(rows)
    ]  # fmt: skip
    threshold = rows[0][4].threshold if rows else float("nan")
    m = len(rows)
    legend = [
        f"Σ dI/dθ: the derivative image summed over the film's {reference.derivative.size} pixels; its"
        " standard error se from the spread of the per-batch sums",
        f"Σ - reference [{level} interval]: the error of Σ and its {level} interval, simultaneous over the"
        f" {m} rows: each ± {q:.2f} sqrt(se² + se_ref²)",
        f"  (per row {family_level(m):.2%}, Šidák); BIASED: the interval excludes 0; (σ = 0): no spread",
        f"z: (Σ - Σ_ref) / sqrt(se² + se_ref²); BIASED exactly when |z| > {q:.2f}; — : no spread, no z",
        "px |z|>t: k/m, k the pixels whose |g_j - g_ref,j| / sqrt(se_j² + se_ref,j²) exceeds"
        f" t = {threshold:.2f} (Student-t, batches - 1 dof, level 1-{LEVEL:g}^(1/m)),",
        "  m the pixels the method's se_j > 0 lets test (a pixel whose samples all agreed has none);"
        f" {1 - LEVEL:.2g} exceeding expected if unbiased;",
        "  shown, not a flag: rare-event pixels make its t law fail",
        "relative error: mean|g - g_ref| / max|g_ref| over the pixels (bias and noise)",
        "rank: unbiased methods by relative error, then the BIASED ones",
    ]
    note = own_method_note(gradients, getattr(reference, "method", ""))
    return "\n".join([format_table(heads, body, title), *legend, *([note] if note else [])])
