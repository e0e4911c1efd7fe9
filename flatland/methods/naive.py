"""The naive image gradient: forward-mode AD of the renderer's estimator as it stands.

Where the integrator calls it: one ``task.evaluate(task.dual_offset(), Identity())`` (θ0 = 0 as
``variable(0.0)``, or for k parameters ``variables(k)``: one pass, k tangents):
the :class:`~flatland.integrator.Identity` transforms change nothing, so every step
(film samples, radiance, shading by MIS, per-pixel sums) is differentiated as it stands.

Loubet et al. 2019, Sec. 3.1-3.2. The baseline that is wrong wherever visibility
makes an integrand jump at a point that moves with θ.
"""

from __future__ import annotations

from flatland.integrator import Identity
from flatland.methods._common import GRADIENT_METHODS
from flatland.tasks import ImageTask, PointTask, Tally

__all__ = ["naive"]


@GRADIENT_METHODS.register("naive")
def naive(task: ImageTask | PointTask) -> Tally:
    r"""Differentiate every pixel and shading estimate with θ a forward-mode Dual.

    The film samples $t \sim k_j$ and the direction samples φ (cosine and emitter
    sampling at θ0) are θ-free; the rays are traced detached and their hits
    re-attached to the θ-dependent geometry, so every smooth dependence is
    differentiated exactly: hit points sliding along moving surfaces, normals,
    cosines, emission fades, albedo and emission parameters, the moving camera.

    Assumes each integrand is continuous in θ at every sample (Loubet et al. 2019, Sec. 3.1). Biased
    wherever it is not: a film sample whose ray changes primitive as θ moves, or a
    direction sample whose ray passes a moving occluder or emitter edge, contributes
    a derivative of zero instead of its share of the jump. The estimate converges to
    the interior term of the Leibniz rule alone and misses
    $Σ_c k_j(c) [L(c^-) - L(c^+)] c'(θ)$ over the silhouettes seen from the camera and
    $(ρ/2) Σ_c [f(c^-) - f(c^+)] c'(θ)$ over those seen from each shading point
    (Leibniz rule, theory/leibniz; Loubet et al. 2019, Sec. 3.2); the boundary method adds
    exactly these terms. The value estimate is unbiased and, for the same seed, identical to
    the other methods'.
    """
    return task.evaluate(task.dual_offset(), Identity())
