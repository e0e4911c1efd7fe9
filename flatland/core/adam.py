r"""Adam, the adaptive first-order optimiser of Kingma and Ba (2015), on numpy arrays, with box bounds.

For a stochastic gradient $g_t$ of the loss at step $t = 1, 2, …$ and the parameters $θ_{t-1}$:

    $m_t = β_1 m_{t-1} + (1 - β_1) g_t$,    $v_t = β_2 v_{t-1} + (1 - β_2) g_t^2$    (elementwise),

    $\hat m_t = m_t / (1 - β_1^t)$,    $\hat v_t = v_t / (1 - β_2^t)$    (bias correction: $m_0 = v_0 = 0$),

    $θ_t = \mathrm{clip}(θ_{t-1} - η_t \hat m_t / (\sqrt{\hat v_t} + ε), l, u)$.

The bias correction undoes the moments' start at zero: with a constant gradient g, $\hat m_t = g$ and
$\hat v_t = g^2$ exactly, so the first step is $η_1 g / (|g| + ε)$, about $η_1$ per parameter whatever
the gradient's scale. A step is therefore measured in the parameter's own units: η is how far a
parameter may move per step, which makes one η serve parameters whose gradients differ by orders of
magnitude (a position and an albedo). The bounds are a projection (projected Adam): the step is taken,
then each parameter is clipped to $[l_i, u_i]$; the moments keep the unclipped gradients. A parameter
whose gradient is exactly 0 at every step never moves ($\hat m_t = 0$).

The step size $η_t$ is the caller's (:func:`flatland.core.optimize.descend` shrinks it geometrically).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["AdamState", "adam_step"]

BETA1, BETA2, EPS = 0.9, 0.999, 1e-8
"""Kingma and Ba's defaults: the decay rates of the first and second moments and the denominator's ε."""


@dataclass(frozen=True)
class AdamState:
    """The optimiser after ``t`` steps: parameters ``theta``, moments ``m`` and ``v`` (arrays of k)."""

    theta: np.ndarray
    m: np.ndarray
    v: np.ndarray
    t: int = 0

    @classmethod
    def start(cls, theta0: np.ndarray) -> AdamState:
        """The state before the first step: $θ_0$, $m_0 = v_0 = 0$."""
        theta = np.array(theta0, dtype=np.float64)
        return cls(theta, np.zeros_like(theta), np.zeros_like(theta), 0)


def adam_step(
    state: AdamState,
    gradient: np.ndarray,
    lr: float | np.ndarray,
    lower: float | np.ndarray = -np.inf,
    upper: float | np.ndarray = np.inf,
    beta1: float = BETA1,
    beta2: float = BETA2,
    eps: float = EPS,
) -> AdamState:
    """One Adam step (the module docstring's equations) with step size ``lr`` (per parameter or one for
    all) and the projection onto $[l, u]$."""
    g = np.asarray(gradient, dtype=np.float64)
    t = state.t + 1
    m = beta1 * state.m + (1.0 - beta1) * g
    v = beta2 * state.v + (1.0 - beta2) * g * g
    m_hat = m / (1.0 - beta1**t)
    v_hat = v / (1.0 - beta2**t)
    theta = np.clip(state.theta - lr * m_hat / (np.sqrt(v_hat) + eps), lower, upper)
    return AdamState(theta, m, v, t)
