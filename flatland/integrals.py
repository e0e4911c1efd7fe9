"""Textbook 1D integrals with closed-form values, derivatives and discontinuities.

Each integrand f(x, θ) lives on a domain (the real line or the circle S¹), comes
with a θ-independent proposal density to sample x from, the closed forms I(θ) and
dI/dθ, and the list of its discontinuities: where f jumps (a :class:`Dual` whose
tangent is dc/dθ) and by how much ($f(c^-) - f(c^+)$). Moving integration limits
are written as indicator discontinuities of an integrand on the whole domain, so
the Leibniz rule (theory/leibniz) reads

    $dI/dθ = ∫ ∂f/∂θ dx + Σ_i [f(c_i^-) - f(c_i^+)] c_i'(θ)$.

``f`` accepts a Dual ``x`` (a reparameterized sample) and a Dual ``θ``: indicators
are evaluated on values (their derivative is zero wherever it exists) and the
smooth factors carry the tangent, exactly what automatic differentiation of the
estimator sees (Loubet et al. 2019, Sec. 3).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from scipy import special

from flatland.core.dual import Dual, detach, variable
from flatland.core.validate import ValidationError, check_choice, check_finite
from flatland.sampling import (
    TWO_PI,
    log_pdf_gaussian,
    log_pdf_von_mises,
    pdf_gaussian,
    pdf_uniform_circle,
    sample_gaussian,
    sample_uniform_circle,
    sample_von_mises,
    wrap_angle,
)

__all__ = [
    "INTEGRALS",
    "Arc",
    "ArcStretch",
    "Circle",
    "Discontinuity",
    "Integrand",
    "LeibnizSeed",
    "Line",
    "SmoothBump",
    "Step",
    "TwoSteps",
    "get_integral",
]


# ------------------------------------------------------------------ domains
class Line:
    """The real line. Its convolution kernel is the Gaussian of variance $1/κ$."""

    name = "line"

    @staticmethod
    def distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """$|a - b|$."""
        return np.abs(a - b)

    @staticmethod
    def sample_kernel(u: np.ndarray, center: np.ndarray, kappa: float) -> np.ndarray:
        """Kernel sample around ``center``: $N(center, 1/κ)$."""
        return sample_gaussian(u, 0.0, 1.0 / np.sqrt(kappa)) + center

    @staticmethod
    def log_kernel(x: Any, center: np.ndarray, kappa: float) -> Any:
        r"""$\log k(x, center)$, the log density of $N(center, 1/κ)$ at ``x`` (a Dual welcome)."""
        return log_pdf_gaussian(x, center, 1.0 / np.sqrt(kappa))


class Circle:
    """The circle S¹ (angles in radians). Its kernel is the von Mises density (Sec. 4.2)."""

    name = "circle"

    @staticmethod
    def distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Arc distance between angles, in [0, π]."""
        return np.abs(wrap_angle(a - b))

    @staticmethod
    def sample_kernel(u: np.ndarray, center: np.ndarray, kappa: float) -> np.ndarray:
        """Kernel sample around ``center``: von Mises(center, κ)."""
        return sample_von_mises(u, center, kappa)

    @staticmethod
    def log_kernel(x: Any, center: np.ndarray, kappa: float) -> Any:
        r"""$\log k(x, center)$, the log von Mises density at ``x`` (a Dual welcome)."""
        return log_pdf_von_mises(x, center, kappa)


@dataclass(frozen=True)
class Discontinuity:
    """A point where f jumps: location c(θ) as a Dual (tangent dc/dθ) and jump $f(c^-) - f(c^+)$."""

    location: Dual
    jump: float


def _std_normal_pdf(x: Any) -> Any:
    return np.exp(-0.5 * x * x) / np.sqrt(TWO_PI)


def _std_normal_cdf(x: Any) -> Any:
    return special.ndtr(x)


def _on_arc(phi: Any, start: Any, end: Any) -> np.ndarray:
    """Indicator of φ in the arc from ``start`` counter-clockwise to ``end`` (values only)."""
    width = detach(end) - detach(start)
    return np.remainder(detach(phi) - detach(start), TWO_PI) < width


# --------------------------------------------------------------- integrands
class Integrand(ABC):
    """A textbook integrand f(x, θ) with closed forms (see the module docstring)."""

    name: ClassVar[str]
    title: ClassVar[str]
    domain: ClassVar[type[Line] | type[Circle]]
    theta_range: ClassVar[tuple[float, float]]
    default_theta: ClassVar[float]

    @abstractmethod
    def f(self, x: Any, theta: Any) -> Any:
        """The integrand; ``x`` and ``theta`` may be Duals."""

    @abstractmethod
    def sample(self, u: np.ndarray) -> np.ndarray:
        """Proposal samples (θ-independent) from uniforms ``u``."""

    @abstractmethod
    def pdf(self, x: np.ndarray) -> np.ndarray:
        """Proposal density of :meth:`sample`."""

    @abstractmethod
    def discontinuities(self, theta: Dual) -> tuple[Discontinuity, ...]:
        """Where f jumps, at the parameter ``theta`` (a Dual)."""

    @abstractmethod
    def value(self, theta: float) -> float:
        """Closed-form I(θ) (elementwise for an array of θ)."""

    @abstractmethod
    def derivative(self, theta: float) -> float:
        """Closed-form dI/dθ (elementwise for an array of θ)."""

    def check_theta(self, theta: Any, field: str = "theta") -> float:
        """``theta`` as a float inside :attr:`theta_range`; ValueError naming ``field`` otherwise."""
        t = check_finite(field, theta)
        lo, hi = self.theta_range
        if not lo <= t <= hi:
            raise ValidationError(field, f"must lie in [{lo}, {hi}] for {self.name!r}, got {t!r}")
        return t

    def discontinuity_term(self, theta: float) -> float:
        """$Σ_i [f(c_i^-) - f(c_i^+)] c_i'(θ)$: what naive differentiation drops (theory/leibniz)."""
        return float(sum(d.jump * float(d.location.tangent) for d in self.discontinuities(variable(theta))))

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


class _GaussianProposal:
    """Mixin: proposal N(proposal_mean, proposal_std²) on the line."""

    proposal_mean: ClassVar[float] = 0.0
    proposal_std: ClassVar[float] = 1.5

    def sample(self, u: np.ndarray) -> np.ndarray:
        return sample_gaussian(u, self.proposal_mean, self.proposal_std)

    def pdf(self, x: np.ndarray) -> np.ndarray:
        return pdf_gaussian(x, self.proposal_mean, self.proposal_std)


class _UniformCircleProposal:
    """Mixin: uniform proposal on the circle."""

    def sample(self, u: np.ndarray) -> np.ndarray:
        return sample_uniform_circle(u)

    def pdf(self, x: np.ndarray) -> np.ndarray:
        return pdf_uniform_circle(x)


class LeibnizSeed(_GaussianProposal, Integrand):
    """The seed example: $f = 1$ for $x > 2θ$, 0 below, integrated over $[0, 4θ]$; $I = 2θ$, $dI/dθ = 2$.

    On the whole line $f = 1_{2θ < x < 4θ}$. Interior term 0, moving limit $1·4$, moving
    step $(0 - 1)·2$: $dI/dθ = 2$ (Leibniz rule, theory/leibniz). Two discontinuities moving at different
    speeds, so one translation per sample cannot follow both.
    """

    name = "leibniz_seed"
    title = "∫₀^{4θ} 1[x > 2θ] dx"
    domain = Line
    theta_range = (0.25, 2.0)
    default_theta = 1.0
    proposal_mean = 3.0
    proposal_std = 2.5

    def f(self, x: Any, theta: Any) -> Any:
        inside = (detach(x) > 2.0 * detach(theta)) & (detach(x) < 4.0 * detach(theta))
        return np.where(inside, 1.0, 0.0)  # locally constant: zero derivative wherever it exists

    def discontinuities(self, theta: Dual) -> tuple[Discontinuity, ...]:
        return (Discontinuity(2.0 * theta, 0.0 - 1.0), Discontinuity(4.0 * theta, 1.0 - 0.0))

    def value(self, theta: float) -> float:
        return 2.0 * theta

    def derivative(self, theta: float) -> float:
        return 2.0 + 0.0 * theta


class Step(_GaussianProposal, Integrand):
    """The paper's example (Loubet et al. 2019, Sec. 3.2): $f = 1_{x > θ} K(x)$, K the standard normal
    density.

    $I = 1 - Φ(θ)$, $dI/dθ = -K(θ)$; naive differentiation returns 0.
    """

    name = "step"
    title = "1[x > θ] K(x)"
    domain = Line
    theta_range = (-3.0, 3.0)
    default_theta = 0.5

    def f(self, x: Any, theta: Any) -> Any:
        return np.where(detach(x) > detach(theta), _std_normal_pdf(x), 0.0)

    def discontinuities(self, theta: Dual) -> tuple[Discontinuity, ...]:
        # f(θ⁻) - f(θ⁺) = 0 - K(θ)
        return (Discontinuity(theta, -float(_std_normal_pdf(detach(theta)))),)

    def value(self, theta: float) -> float:
        return 1.0 - _std_normal_cdf(theta)

    def derivative(self, theta: float) -> float:
        return -_std_normal_pdf(theta)


class TwoSteps(_GaussianProposal, Integrand):
    """Two steps moving at different speeds: $f = 1_{θ < x < 2θ} K(x)$.

    $I = Φ(2θ) - Φ(θ)$, $dI/dθ = 2K(2θ) - K(θ)$. One translation cannot follow both
    ends (Loubet et al. 2019, Sec. 4.2): the case for convolution kernels.
    """

    name = "two_steps"
    title = "1[θ < x < 2θ] K(x)"
    domain = Line
    theta_range = (0.1, 2.5)
    default_theta = 1.0

    def f(self, x: Any, theta: Any) -> Any:
        xv, tv = detach(x), detach(theta)
        return np.where((xv > tv) & (xv < 2.0 * tv), _std_normal_pdf(x), 0.0)

    def discontinuities(self, theta: Dual) -> tuple[Discontinuity, ...]:
        t = float(detach(theta))
        return (
            Discontinuity(theta, -float(_std_normal_pdf(t))),
            Discontinuity(2.0 * theta, float(_std_normal_pdf(2.0 * t))),
        )

    def value(self, theta: float) -> float:
        return _std_normal_cdf(2.0 * theta) - _std_normal_cdf(theta)

    def derivative(self, theta: float) -> float:
        return 2.0 * _std_normal_pdf(2.0 * theta) - _std_normal_pdf(theta)


class SmoothBump(_GaussianProposal, Integrand):
    """A smooth integrand: $f = K(x - θ) (1 + x^2)$; $I = 2 + θ^2$, $dI/dθ = 2θ$. Naive AD is right here."""

    name = "smooth"
    title = "K(x − θ)(1 + x²)"
    domain = Line
    theta_range = (-2.0, 2.0)
    default_theta = 0.7
    proposal_std = 2.0

    def f(self, x: Any, theta: Any) -> Any:
        return _std_normal_pdf(x - theta) * (1.0 + x * x)

    def discontinuities(self, theta: Dual) -> tuple[Discontinuity, ...]:
        return ()

    def value(self, theta: float) -> float:
        return 2.0 + theta * theta

    def derivative(self, theta: float) -> float:
        return 2.0 * theta


class Arc(_UniformCircleProposal, Integrand):
    r"""An arc indicator on S¹ times a smooth function: $f = 1_{φ ∈ [θ, θ + w]} (1 + a \cos φ)$.

    The angular domain flatland renders on. $I = w + a (\sin(θ + w) - \sin θ)$,
    $dI/dθ = a (\cos(θ + w) - \cos θ)$. Both ends move at speed 1: one rotation
    (a translation of the angle) follows both.
    """

    name = "arc"
    title = "1[θ < φ < θ + w](1 + a cos φ)"
    domain = Circle
    theta_range = (-np.pi, np.pi)
    default_theta = 0.3
    width = np.pi / 2
    a = 0.5

    def f(self, x: Any, theta: Any) -> Any:
        return np.where(_on_arc(x, theta, detach(theta) + self.width), 1.0 + self.a * np.cos(x), 0.0)

    def discontinuities(self, theta: Dual) -> tuple[Discontinuity, ...]:
        t = float(detach(theta))
        g = lambda p: 1.0 + self.a * np.cos(p)  # noqa: E731
        return (Discontinuity(theta, -g(t)), Discontinuity(theta + self.width, g(t + self.width)))

    def value(self, theta: float) -> float:
        return self.width + self.a * (np.sin(theta + self.width) - np.sin(theta))

    def derivative(self, theta: float) -> float:
        return self.a * (np.cos(theta + self.width) - np.cos(theta))


class ArcStretch(_UniformCircleProposal, Integrand):
    r"""An arc whose ends move at different speeds: $f = 1_{φ ∈ [θ, 2θ]} (1 + a \cos φ)$.

    $I = θ + a (\sin 2θ - \sin θ)$, $dI/dθ = 1 + a (2 \cos 2θ - \cos θ)$: the circle's
    version of :class:`TwoSteps`.
    """

    name = "arc_stretch"
    title = "1[θ < φ < 2θ](1 + a cos φ)"
    domain = Circle
    theta_range = (0.1, 3.0)
    default_theta = 1.0
    a = 0.5

    def f(self, x: Any, theta: Any) -> Any:
        return np.where(_on_arc(x, theta, 2.0 * detach(theta)), 1.0 + self.a * np.cos(x), 0.0)

    def discontinuities(self, theta: Dual) -> tuple[Discontinuity, ...]:
        t = float(detach(theta))
        g = lambda p: 1.0 + self.a * np.cos(p)  # noqa: E731
        return (Discontinuity(theta, -g(t)), Discontinuity(2.0 * theta, g(2.0 * t)))

    def value(self, theta: float) -> float:
        return theta + self.a * (np.sin(2.0 * theta) - np.sin(theta))

    def derivative(self, theta: float) -> float:
        return 1.0 + self.a * (2.0 * np.cos(2.0 * theta) - np.cos(theta))


INTEGRALS: dict[str, Integrand] = {
    cls.name: cls() for cls in (LeibnizSeed, Step, TwoSteps, SmoothBump, Arc, ArcStretch)
}
"""The textbook integrals by name."""


def get_integral(name: Any) -> Integrand:
    """The textbook integral called ``name`` (or ``name`` itself if it is an Integrand)."""
    if isinstance(name, Integrand):
        return name
    return INTEGRALS[check_choice("integrand", name, INTEGRALS)]
