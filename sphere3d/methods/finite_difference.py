"""Central finite differences of whole renders, with common random numbers.

Where the integrator calls it: three ``task.evaluate`` calls with
:class:`~sphere3d.integrator.Identity` at the plain-float offsets θ = 0, +h and -h;
no transform is involved, the method combines the three tallies (the value from θ = 0,
the derivative as the central difference per batch). For k parameters 2k + 1 calls: the value at
θ = 0, then each parameter's pair at ±h alone.

The batches are independent, but at a pixel a discontinuity moves across a batch's difference is
nonzero only for the few samples in the strip it sweeps between ±h (about 2h |v| pixels wide): a
sum of rare events, far from normal, so per pixel the standard error from 16 batches misses more
often than Student's t says (tests/sphere3d/test_standard_errors.py test06); sums over regions of
pixels, with many such samples, are closer to normal.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from flatland.core import progress
from flatland.core.contract import Option
from flatland.core.translation import central_difference
from flatland.core.validate import ValidationError, check_positive
from sphere3d.integrator import Identity
from sphere3d.methods._common import GRADIENT_METHODS
from sphere3d.tasks import ImageTask, PointTask, Tally


@GRADIENT_METHODS.register("finite_difference", Option("h", 1e-2, check_positive))
def finite_difference(task: ImageTask | PointTask, h: float) -> Tally:
    r"""$[Î(h) - Î(-h)] / 2h$ per batch (θ is the parameter's offset), the same samples at both ends.

    Three plain renders (θ = 0 for the value, ±h for the difference), each with the
    primary samples of the same seed, so the difference only sees the samples whose
    integrand changed: visibility flips within $h |c'|$ of a moving edge, and the
    smooth change of everything else. Assumes nothing about continuity; biased by
    the truncation error $h^2 I'''/6 + O(h^4)$ (per pixel), with a variance that grows
    like $1/h$ at edges. Not part of the paper: the reference the other methods are
    checked against. For ``*.scale`` parameters (scale by 1 + θ) h must be < 1.

    For k parameters (a tuple ``task.param``) 2k + 1 renders: the value at θ = 0, then each
    parameter's pair at ±h alone (the others at 0). Unlike the other methods it shares nothing
    between the parameters but that value render and the samples; each parameter's derivative is
    exactly its own call's.

    The default h = 1e-2 is ten times flatland's: the step trades the truncation bias
    (O(1) in pixels whose I(θ) has a kink within h) against a variance that grows
    like $1/h$, and the ``shadow`` image has 4096 pixels here and 64 in flatland, at
    about the same cost per sample, so each pixel gets far fewer samples for the same
    time and the noise term dominates: the standard error at an edge grows like
    $1/\sqrt{h}$ per sample, the truncation bias like $h^2$. Embree's float32 tracing is not what limits h:
    it places an edge to about 1e-7
    of the scene's size, far inside the band $h |c'|$ that even h = 1e-3 sees.
    """
    for name in task.parameters():
        if name.endswith(".scale") and h >= 1.0:
            where = "" if task.k is None else f" ({name!r})"
            raise ValidationError(
                "h", f"must be < 1 for a scale parameter{where} (the scale 1 - h must stay > 0), got {h!r}"
            )
    progress.expect(1 + 2 * len(task.parameters()))  # every render: the bar's total counts them all
    value = task.evaluate(0.0, Identity())  # first: a scene refused at θ0 is reported without the offset
    alone = [task] if task.k is None else [replace(task, param=p) for p in task.parameters()]
    # per-batch central difference: common random numbers cancel everything that did not move
    derivatives = [
        central_difference(lambda theta, one=one: one.evaluate(theta, Identity()).value, 0.0, h)
        for one in alone
    ]
    return Tally(value=value.value, derivative=derivatives[0] if task.k is None else np.stack(derivatives))
