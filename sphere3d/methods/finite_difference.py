"""Central finite differences of whole renders, with common random numbers."""

from __future__ import annotations

from flatland.core.contract import Option
from flatland.core.validate import ValidationError, check_positive
from sphere3d.integrator import Identity
from sphere3d.methods._common import GRADIENT_METHODS
from sphere3d.tasks import ImageTask, PointTask, Tally


@GRADIENT_METHODS.register("finite_difference", Option("h", 1e-2, check_positive))
def finite_difference(task: ImageTask | PointTask, h: float) -> Tally:
    """``[Î(θ0 + h) - Î(θ0 - h)] / 2h`` per batch, the same samples at both ends.

    Three plain renders (θ0 for the value, θ0 ± h for the difference), each with the
    primary samples of the same seed, so the difference only sees the samples whose
    integrand changed: visibility flips within ``h |c'|`` of a moving edge, and the
    smooth change of everything else. Assumes nothing about continuity; biased by
    the truncation error ``h² I'''/6 + O(h⁴)`` (per pixel), with a variance that grows
    like 1/h at edges. Not part of the paper: the reference the other methods are
    checked against. For ``*.scale`` parameters θ0 - h must stay > 0.
    """
    theta0 = task.theta0
    param = task.param or ""
    if param.endswith(".scale") and theta0 - h <= 0.0:
        raise ValidationError("h", f"must be < the scale {theta0!r} (θ0 - h must stay > 0), got {h!r}")
    plus = task.evaluate(theta0 + h, Identity())
    minus = task.evaluate(theta0 - h, Identity())
    value = task.evaluate(theta0, Identity())
    # per-batch central difference: common random numbers cancel everything that did not move
    return Tally(value=value.value, derivative=(plus.value - minus.value) / (2.0 * h))
