"""The estimator contract shared by flatland and sphere3d: named results and method tables.

How to add an estimator
-----------------------
(A textbook estimator; for an image gradient method, a module of
``<package>/methods/`` called with a job or task, see the guide
``docs/guides/add_image_method.md``.)

1. Write one module ``flatland/textbook/<name>.py`` (100-300 lines) with one
   public function ``<name>(problem, theta, n, seed, **options) -> Estimate``. Its
   numpydoc docstring cites the paper's section (e.g. "Loubet et al. 2019,
   Sec. 4.2"), states what the estimator assumes and where it is biased.
2. Draw random numbers only from :func:`flatland.core.rng.stream` with the shared
   stream names (``"samples"`` for the primary samples, a new name for anything
   extra), so that methods given the same seed see the same primary samples.
3. Make theta a :class:`~flatland.core.dual.Dual` with ``variable(theta)`` and
   write the estimator as plain numpy on Duals; the derivative is the tangent.
   Keep derivations on the line that uses them, e.g.
   ``# discontinuity term: (f(c-) - f(c+)) * dc/dtheta   (Leibniz rule, theory/leibniz)``.
4. Return an :class:`Estimate` with per-sample (or per-batch) standard errors:
   summarize i.i.d. per-sample contributions with :func:`flatland.core.stats.summarize`.
5. Register it in the package's :class:`MethodTable` with an :class:`Option` per
   keyword, each with a validator that names the option in its error.
6. Test it: against closed forms within ``z * stderr`` (state the quantile, fix the
   seed); if it is biased, a test that measures the bias and compares it with the
   predicted one. Add it to the contract test that runs over both packages.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flatland.core.image import Options, check_finite_result, summarize_batches
from flatland.core.stats import LEVEL, Interval, normal_quantile, z_score
from flatland.core.validate import ValidationError, check_choice

__all__ = ["METHOD_ORDER", "Estimate", "MethodTable", "Option"]

METHOD_ORDER = ("naive", "finite_difference", "boundary", "reparam")
"""The order both packages (and the textbook estimators) list their methods in: the baseline, the
classic check, the Leibniz rule's jump term, then the paper's reparameterization. A method not named
here follows them in registration order."""


@dataclass(frozen=True)
class Estimate:
    """A Monte Carlo estimate of an integral and of its derivative with respect to theta.

    Attributes
    ----------
    value, derivative : float
        Estimates of I(theta) and dI/dtheta.
    value_stderr, derivative_stderr : float
        Their standard errors (from i.i.d. samples or independent batches).
    n : int
        Number of samples that went into the estimate.
    method : str
        Name of the estimator that produced it.
    options : Mapping
        The options it ran with (read-only).
    """

    value: float
    derivative: float
    value_stderr: float
    derivative_stderr: float
    n: int
    method: str = ""
    options: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "options", Options(self.options))

    @classmethod
    def from_batches(
        cls,
        values: Any,
        derivatives: Any,
        n: int,
        method: str = "",
        options: Mapping[str, Any] | None = None,
    ) -> Estimate:
        """The estimate from per-batch estimates (1D arrays, one entry per independent batch)."""
        check_finite_result("per-batch values", np.ravel(values))
        check_finite_result(f"per-batch derivatives ({method})", np.ravel(derivatives))
        v, d = summarize_batches(np.ravel(values)), summarize_batches(np.ravel(derivatives))
        return cls(float(v.mean), float(d.mean), float(v.stderr), float(d.stderr), n, method, options or {})

    def _mean_stderr(self, of: str) -> tuple[float, float]:
        if check_choice("of", of, ("value", "derivative")) == "value":
            return self.value, self.value_stderr
        return self.derivative, self.derivative_stderr

    def interval(self, level: float = LEVEL, of: str = "derivative") -> Interval:
        """Normal confidence interval for ``of`` ("value" or "derivative")."""
        mean, se = self._mean_stderr(of)
        z = normal_quantile(level)
        return Interval(mean - z * se, mean + z * se, level)

    def z_score(self, reference: float, of: str = "derivative") -> float:
        """Distance to ``reference`` in standard errors of ``of`` ("value" or "derivative")."""
        mean, se = self._mean_stderr(of)
        return z_score(mean, reference, se)  # zero spread: rounding-level differences are no error


@dataclass(frozen=True)
class Option:
    """A keyword option of a method: its default and a validator that names it in errors.

    ``default_text`` says what the default means where the value alone does not (None chosen per
    variant, say); the command line's ``--help`` shows it, else the default itself.
    """

    name: str
    default: Any
    check: Callable[[str, Any], Any]
    default_text: str = ""

    def validate(self, value: Any) -> Any:
        """The checked value (``None`` passes through when it is the default)."""
        if value is None and self.default is None:
            return None
        return self.check(self.name, value)


@dataclass(frozen=True)
class Method:
    """A registered estimator: its function and its options."""

    name: str
    func: Callable[..., Any]
    options: Mapping[str, Option]


class MethodTable(Mapping[str, Method]):
    """Methods of one package by name, with option validation: a read-only mapping name -> :class:`Method`.

    ``"boundary" in table``, ``list(table)`` (the names in :data:`METHOD_ORDER`, then any
    other in registration order, also :attr:`names`), ``table["reparam"]`` (KeyError if
    unknown) and ``table.get(name)`` behave as for any mapping; :meth:`lookup` is the
    validating lookup (one :class:`ValidationError` naming ``method`` and the choices).
    ``table.run("reparam", problem, theta, kappa=100.0)`` checks the method name and
    every option (unknown ones included) and calls the estimator with the defaults
    filled in. Methods are added only through :meth:`register` (and removed by
    :meth:`unregister`), never by item assignment.
    """

    def __init__(self, kind: str, order: Sequence[str] = METHOD_ORDER) -> None:
        self.kind = kind
        self.order = tuple(order)
        self._methods: dict[str, Method] = {}

    def __getitem__(self, name: str) -> Method:
        return self._methods[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self.names)

    def __len__(self) -> int:
        return len(self._methods)

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and name in self._methods

    def __repr__(self) -> str:
        return f"MethodTable({self.kind!r}: {', '.join(self.names)})"

    def register(self, name: str, *options: Option) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
        """Decorator registering ``func`` as method ``name`` with ``options``."""

        def decorate(func: Callable[..., Any]) -> Callable[..., Any]:
            self._methods[name] = Method(name, func, {o.name: o for o in options})
            return func

        return decorate

    def unregister(self, name: str) -> None:
        """Remove method ``name`` (KeyError if it is not registered: a programming error, not bad input)."""
        if name not in self._methods:
            raise KeyError(f"{self.kind} {name!r} is not registered")
        del self._methods[name]

    @contextmanager
    def registered(
        self, name: str, func: Callable[..., Any], *options: Option
    ) -> Iterator[Callable[..., Any]]:
        """Register ``func`` as method ``name`` for the duration of a ``with`` block, then remove it.

        For tests and examples that plug a method into the package's own table without
        leaving it there. A name already registered is refused (ValueError), so an
        existing method is never shadowed and then lost on exit.
        """
        if name in self._methods:
            raise ValueError(f"{self.kind} {name!r} is already registered")
        self.register(name, *options)(func)
        try:
            yield func
        finally:
            self.unregister(name)

    @property
    def names(self) -> tuple[str, ...]:
        """Registered method names: those of ``order`` first, in that order, then the others as registered."""
        first = [n for n in self.order if n in self._methods]
        return (*first, *(n for n in self._methods if n not in first))

    def lookup(self, name: Any) -> Method:
        """The method called ``name``; a ValidationError naming ``method`` and the choices if unknown."""
        if not isinstance(name, str) or name not in self._methods:
            raise ValidationError(
                "method", f"unknown {self.kind} {name!r}; choose from {', '.join(self.names)}"
            )
        return self._methods[name]

    def resolve_options(self, name: str, options: Mapping[str, Any]) -> dict[str, Any]:
        """All options of ``name`` with defaults filled in, each validated."""
        method = self.lookup(name)
        unknown = sorted(set(options) - set(method.options))
        if unknown:
            known = ", ".join(method.options) or "none"
            raise ValidationError(unknown[0], f"is not an option of method {name!r} (options: {known})")
        return {k: o.validate(options.get(k, o.default)) for k, o in method.options.items()}

    def run(self, name: str, *args: Any, **options: Any) -> Any:
        """Validate and call method ``name``."""
        method = self.lookup(name)
        return method.func(*args, **self.resolve_options(name, options))
