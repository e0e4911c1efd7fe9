"""Text for the command line: fixed-width tables (study results, error tables, the textbook table) and
the short names of methods with their options that label their rows, legends and figures."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

__all__ = ["error_table", "format_table", "method_label", "own_method_note"]


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

    Columns: rank (unbiased methods by relative error, then the flagged ones),
    ``z of Σ`` (the film sum's error in standard errors, |z| > 3.3 flags BIASED),
    ``px |z|>t`` (pixels above the Sidak-corrected Student-t threshold of
    :func:`flatland.core.bias.pixel_test`, batches - 1 degrees of freedom; shown,
    not a flag: see :mod:`flatland.core.bias`), the relative error ``mean|g - g_ref| / max|g_ref|``, the
    film sum ± its standard error and the seconds. The film sums' standard errors come from the
    per-batch sums (:meth:`GradientImage.film_sum <flatland.core.image.GradientImage.film_sum>`):
    neighbouring pixels share samples under a splatted film and edge points, so their errors are
    correlated. The footer states the tests.
    """
    from flatland.core.bias import Z_FLAG, pixel_test
    from flatland.core.stats import z_score

    ref = reference.film_sum()  # standard errors from the per-batch sums (pixels may be correlated)
    ref_sum, ref_se = ref.total, ref.stderr
    rows = []
    for method, g in gradients.items():
        total, se = (s := g.film_sum()).total, s.stderr
        z = z_score(total, ref_sum, math.hypot(se, ref_se))
        px = pixel_test(g.derivative, g.derivative_stderr, reference.derivative, reference.derivative_stderr,
                        g.batches - 1)  # fmt: skip
        biased = abs(z) > Z_FLAG  # the pixel count is shown, not a flag (see the footer)
        rows.append((biased, g.error_vs(reference), method, z, px, total, se))
    rows.sort(key=lambda r: (r[0], r[1]))  # unbiased first, each part by relative error
    heads = ("method", "rank", "z of Σ", "flag", "px |z|>t", "relative error", "Σ dI/dθ ± stderr", "seconds")
    body = [
        (method, str(k + 1), f"{z:+.1f}", "BIASED" if biased else "", px.summary(), f"{error:.4f}",
         f"{total:+.4g} ± {se:.2g}", f"{seconds[method]:.2f}")
        for k, (biased, error, method, z, px, total, se) in enumerate(rows)
    ]  # fmt: skip
    threshold = rows[0][4].threshold if rows else float("nan")
    footer = (
        f"z of Σ = (Σg - Σg_ref) / sqrt(se² + se_ref²), Σ over the film, se from the per-batch sums:"
        f" |z| > {Z_FLAG}\n(two-sided 99.9 %) flags BIASED\n"
        f"px |z|>t: pixels with |g_j - g_ref,j| / sqrt(se_j² + se_ref,j²) above t = {threshold:.2f}, the"
        " Student-t quantile (batches - 1 dof)\nat the Sidak-corrected level 1-(1-0.01)^(1/m) over m pixels;"
        " ~0.01 expected if unbiased; shown, not a flag:\nrare-event pixels make its t law fail (measured:"
        " finite differences against a finite-difference reference exceed)\n"
        "rank: unbiased methods by relative error = mean|g - g_ref| / max|g_ref| (bias and noise), then the"
        " BIASED ones"
    )
    note = own_method_note(gradients, getattr(reference, "method", ""))
    if note:
        footer += "\n" + note
    return format_table(heads, body, title) + "\n" + footer
