"""The naive gradient: differentiate the renderer as it stands (forward mode, no change of variables).

Where the integrator calls it: one ``task.evaluate(task.dual_offset(), Identity())`` (θ0 = 0 as
``variable(0.0)``, or ``variables(k)`` for k parameters: one pass, k tangents): the
camera, emitter and bsdf transforms of :class:`~sphere3d.integrator.Identity` change
nothing, so the pixel integral and both strategies of the irradiance are
differentiated as they stand.
"""

from __future__ import annotations

from sphere3d.integrator import Identity
from sphere3d.methods._common import GRADIENT_METHODS
from sphere3d.tasks import ImageTask, PointTask, Tally


@GRADIENT_METHODS.register("naive")
def naive(task: ImageTask | PointTask) -> Tally:
    """Forward-mode derivative of the Monte Carlo estimator (Loubet et al. 2019, Sec. 3.1).

    θ, the parameter's offset, enters as ``variable(0.0)``; rays are traced detached
    and every hit is re-attached to the θ-dependent geometry (:mod:`sphere3d.tracing`), so the
    derivative includes the motion of shading points, normals, distances, the
    emitters' sampled points and the materials. Assumes the integrand is continuous
    in θ at every sample. Where visibility changes with θ — silhouettes seen by the
    camera, shadow boundaries, the horizon of the environment behind an occluder —
    the integrand has discontinuities that move, each sample's derivative misses
    them, and the estimate converges to the interior term alone: biased by minus the
    boundary term of the Leibniz rule (Loubet et al. 2019, Sec. 3.2). The value is unbiased.
    """
    return task.evaluate(task.dual_offset(), Identity())
