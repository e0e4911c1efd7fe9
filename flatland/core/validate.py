"""Input validation shared by both packages: one clear error naming the field and value.

Every public entry point checks its arguments with these helpers, so a bad value is
reported where it enters (``n must be an integer >= 1, got 0``) instead of surfacing
as a NaN three modules later. The errors are :class:`ValueError` subclasses; the
command-line interfaces turn them into one line on stderr and exit status 2.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable
from typing import Any

import numpy as np

__all__ = [
    "ValidationError",
    "check_bool",
    "check_choice",
    "check_finite",
    "check_int",
    "check_positive",
    "check_seed",
]


class ValidationError(ValueError):
    """A bad input value; ``field`` names it (a dotted path for scene files)."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}" if field else message)
        self.field = field


def check_finite(field: str, value: Any) -> float:
    """``value`` as a finite float; raises naming ``field`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValidationError(field, f"must be a real number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise ValidationError(field, f"must be finite, got {value!r}")
    return out


def check_positive(field: str, value: Any, *, allow_zero: bool = False) -> float:
    """``value`` as a finite float > 0 (>= 0 with ``allow_zero``)."""
    out = check_finite(field, value)
    if out < 0 or (out == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValidationError(field, f"must be {bound}, got {value!r}")
    return out


def check_int(field: str, value: Any, *, minimum: int = 1) -> int:
    """``value`` as an int >= ``minimum`` (bools and non-integral floats rejected)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral | np.integer):
        raise ValidationError(field, f"must be an integer >= {minimum}, got {value!r}")
    out = int(value)
    if out < minimum:
        raise ValidationError(field, f"must be an integer >= {minimum}, got {value!r}")
    return out


def check_seed(field: str, value: Any) -> int:
    """A reproducible seed: a non-negative integer."""
    return check_int(field, value, minimum=0)


def check_bool(field: str, value: Any) -> bool:
    """``value`` as a bool (only True/False accepted, not truthy values)."""
    if not isinstance(value, bool | np.bool_):
        raise ValidationError(field, f"must be True or False, got {value!r}")
    return bool(value)


def check_choice(field: str, value: Any, choices: Iterable[str]) -> str:
    """``value`` if it is one of ``choices``."""
    choices = tuple(choices)
    if not isinstance(value, str) or value not in choices:
        raise ValidationError(field, f"must be one of {', '.join(choices)}; got {value!r}")
    return value
