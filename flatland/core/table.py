"""Text for the command line: fixed-width tables (study results, error tables, the textbook table) and
the short names of methods with their options that label their rows, legends and figures."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

__all__ = ["format_table", "method_label"]


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
