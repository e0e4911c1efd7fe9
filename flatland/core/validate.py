"""Input validation shared by both packages: one clear error naming the field and value.

Every public entry point checks its arguments with these helpers, so a bad value is
reported where it enters (``n must be an integer >= 1, got 0``) instead of surfacing
as a NaN three modules later. The errors are :class:`ValueError` subclasses; the
command-line interfaces turn them into one line on stderr and exit status 2.

JSON files (scenes, study configurations) are read by :func:`read_json`, the one
loader of both packages: a missing or unreadable file, malformed JSON and nesting
deeper than :data:`MAX_JSON_DEPTH` all become one :class:`ValidationError`.
"""

from __future__ import annotations

import json
import math
import numbers
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from importlib.resources.abc import Traversable

__all__ = [
    "MAX_JSON_DEPTH",
    "ValidationError",
    "check_bool",
    "check_choice",
    "check_depth",
    "check_finite",
    "check_int",
    "check_positive",
    "check_seed",
    "read_json",
]

MAX_JSON_DEPTH = 64
"""Deepest nesting of objects and lists accepted in a scene or study configuration.

The formats need at most 5 levels (a mesh's vertex rows inside a shape inside the
shape list); 64 leaves room and stays far below Python's recursion limit (1000),
which the json parser and ``repr`` of a bad value would otherwise run into."""


_SCALARS = (str, int, float, type(None))
"""JSON's scalar types (bool is an int), skipped by :func:`check_depth` before the slower ABC test."""


class ValidationError(ValueError):
    """A bad input value; ``field`` names it (a dotted path for scene files)."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}" if field else message)
        self.field = field
        self.message = message

    def __reduce__(self) -> tuple[type, tuple[str, str]]:
        # rebuilt from (field, message) when pickled to or from a worker process
        return type(self), (self.field, self.message)


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


def check_depth(field: str, data: Any, limit: int = MAX_JSON_DEPTH) -> Any:
    """``data`` if its dicts, lists and tuples nest at most ``limit`` levels deep.

    A scalar has depth 0, ``[]`` depth 1, ``[[1]]`` depth 2. The walk goes level by
    level (no recursion), each distinct container once per level, and stops at the
    first level past ``limit``: any depth, a container holding itself and shared
    sub-lists are refused or passed in at most ``limit`` sweeps.

    Raises
    ------
    ValidationError
        ``<field>: JSON nested deeper than <limit> levels``.
    """
    containers = Mapping | list | tuple
    level = [data] if isinstance(data, containers) else []
    depth = 0
    while level:
        depth += 1
        if depth > limit:
            raise ValidationError(field, f"JSON nested deeper than {limit} levels")
        below: list[Any] = []
        for node in level:
            children = node.values() if isinstance(node, Mapping) else node
            below += [c for c in children if not isinstance(c, _SCALARS) and isinstance(c, containers)]
        level = list({id(c): c for c in below}.values())  # a container shared n times: walked once
    return data


def read_json(path: str | os.PathLike | Traversable, what: str = "JSON") -> Any:
    """The content of the JSON file ``path``, checked by :func:`check_depth`.

    The one JSON loader of both packages (scenes and study configurations). Every
    failure is one :class:`ValidationError` whose field is ``<what> file '<path>'``:
    a missing or unreadable file, text that is not UTF-8, malformed JSON (with its
    line and column) and nesting deeper than :data:`MAX_JSON_DEPTH`.
    """
    field = f"{what} file {str(path)!r}"
    source = Path(path) if isinstance(path, str | os.PathLike) else path
    try:
        text = source.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ValidationError(field, "no such file") from None
    except OSError as e:  # a folder, no permission
        raise ValidationError(field, f"cannot be read: {e.strerror or e}") from None
    except UnicodeDecodeError as e:
        raise ValidationError(field, f"is not UTF-8 text (byte {e.start})") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise ValidationError(field, f"invalid JSON: {e.msg} (line {e.lineno}, column {e.colno})") from None
    except RecursionError:  # the C parser recurses once per level, up to the interpreter's limit
        raise ValidationError(field, f"JSON nested deeper than {MAX_JSON_DEPTH} levels") from None
    except ValueError as e:  # not a JSONDecodeError, e.g. an integer of more than 4300 digits
        raise ValidationError(field, f"invalid JSON: {e}") from None
    return check_depth(field, data)
