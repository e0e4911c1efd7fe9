"""A method's evaluation points for a set of samples, and their per-sample estimate: :class:`Members`.

A method's change of variables (:class:`flatland.integrator.Transforms`) returns, per sample, one
evaluation point or a pair sharing one transform, with kernel weights (value 1, Loubet et al. 2019,
Sec. 4.2); :func:`combine` turns the members' estimates into one per sample, a pair with the
paired-sample control variate (theory/kernels). Re-exported by :mod:`flatland.integrator`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from flatland.core.dual import detach
from flatland.core.translation import paired_combine

__all__ = ["Members", "combine"]


@dataclass(frozen=True)
class Members:
    """Evaluation points for a set of samples: ``points`` (n, m), ``weights`` (n, m) or None.

    m = 1 for a single evaluation per sample, m = 2 for a pair sharing one transform
    that :func:`combine` merges with the paired-sample control variate (theory/kernels). ``density``
    (film only) replaces the pixel filter as the density of the sample the members
    were drawn around, when that is not the film sample itself.
    """

    points: Any
    weights: Any = None
    paired: bool = False
    density: np.ndarray | None = None

    def flat(self) -> tuple[Any, np.ndarray]:
        """All evaluation points as one flat array, and the index of each one's sample."""
        n, m = np.shape(detach(self.points))
        return self.points.reshape(-1), np.repeat(np.arange(n), m)

    def reduce(self, e_flat: Any) -> Any:
        """Per-sample estimates from the members' estimates ``e_flat`` (in :meth:`flat` order)."""
        e = e_flat.reshape(np.shape(detach(self.points)))
        if self.weights is not None:
            e = e * self.weights
        return combine(e, self.weights, self.paired)


def combine(e: Any, w: Any, paired: bool) -> Any:
    """Per-sample estimate from member estimates ``e`` (n, m) carrying weights ``w`` (value 1).

    Paired (theory/kernels): 0.5 (e0 - e1/w1 (w0 - detach w0)) + 0.5 (e1 - e0/w0 (w1 - detach w1)):
    each weight's derivative has zero mean given the pair's kernel centre and is
    independent of the other member, so it serves as the other's control variate.
    """
    if not paired:
        return e[:, 0]
    return paired_combine(e[:, 0], e[:, 1], w[:, 0], w[:, 1])
