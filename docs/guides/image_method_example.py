"""Richardson-extrapolated finite differences of whole images, in flatland and in sphere3d.

The worked example of the guide "How to add an image gradient method". One method
per package, both called ``richardson``: the central differences of the package's
``finite_difference`` method at steps h and h/2, combined so that their h² error
cancels. Each is registered in a method table of its own, so importing this module
leaves the packages' tables unchanged; a real new method registers in
``flatland.methods.GRADIENT_METHODS`` (a module of ``flatland/methods/``) or in
``sphere3d.methods.GRADIENT_METHODS`` (a module of ``sphere3d/methods/``) instead.
``tests/test_docs.py`` plugs both into the real tables for the duration of a test
(:meth:`flatland.core.contract.MethodTable.registered`) and renders with them.
"""

from __future__ import annotations

from flatland import methods as flatland_methods
from flatland import tasks as flatland_tasks
from flatland.core.contract import MethodTable, Option
from flatland.core.validate import check_positive
from sphere3d import methods as sphere3d_methods
from sphere3d.tasks import ImageTask, PointTask, Tally

__all__ = [
    "FLATLAND_EXAMPLE_METHODS",
    "SPHERE3D_EXAMPLE_METHODS",
    "richardson_flatland",
    "richardson_sphere3d",
]

FLATLAND_EXAMPLE_METHODS = MethodTable("example gradient method")
"""The guide's own flatland table (a new flatland method uses ``flatland.methods.GRADIENT_METHODS``)."""

SPHERE3D_EXAMPLE_METHODS = MethodTable("example gradient method")
"""The guide's own sphere3d table (a new sphere3d method uses ``sphere3d.methods.GRADIENT_METHODS``)."""


@FLATLAND_EXAMPLE_METHODS.register("richardson", Option("h", 1e-3, check_positive))
def richardson_flatland(
    task: flatland_tasks.ImageTask | flatland_tasks.PointTask, h: float
) -> flatland_tasks.Tally:
    """``[4 D(h/2) - D(h)] / 3`` per pixel and batch, D(s) the central difference with step s.

    Richardson extrapolation of the ``finite_difference`` method (not part of the
    paper). Where a pixel's I(θ) is smooth, ``E[D(s)] = I'(θ0) + s² I'''(θ0) / 6 +
    O(s⁴)``, so the combination cancels the s² term and is biased by O(h⁴) only. It
    costs two ``finite_difference`` runs (six primal renders, every one from the same
    primary samples). At a lone edge moving at speed v through samples of density ρ,
    a sample within h v / 2 of it contributes ``(4 J/h - J/2h) / 3 = 7J / 6h`` and one
    in the next h v / 2 ``-J / 6h`` (J the jump): the mean is ρ v J, the exact jump
    term, and the second moment ``ρ v J² · 50 / 36h`` is 50/36 ≈ 1.4 times that of
    D(h/2) alone, the price of the smaller bias. Where I(θ) has a kink within h of
    θ0, D(h) and D(h/2) both have an O(1) error and so does the combination.
    The value is the naive value, bit for bit. ``h`` must be < 1 for a ``*.scale``
    parameter (checked by ``finite_difference``, the error names ``h``).
    """
    central = flatland_methods.GRADIENT_METHODS.get("finite_difference").func
    wide, narrow = central(task, h), central(task, 0.5 * h)
    # E[D(s)] = I' + s² I'''/6 + O(s⁴): (4 D(h/2) - D(h)) / 3 = I' + O(h⁴)   (Richardson, per batch)
    return flatland_tasks.Tally(narrow.value, (4.0 * narrow.derivative - wide.derivative) / 3.0)


@SPHERE3D_EXAMPLE_METHODS.register("richardson", Option("h", 1e-2, check_positive))
def richardson_sphere3d(task: ImageTask | PointTask, h: float) -> Tally:
    """``[4 D(h/2) - D(h)] / 3`` per pixel and batch on the sphere; see :func:`richardson_flatland`.

    The same extrapolation of sphere3d's ``finite_difference`` (default step 1e-2, as
    there), for an image (:class:`~sphere3d.tasks.ImageTask`) or the irradiance at a
    point (:class:`~sphere3d.tasks.PointTask`) alike: the method only calls
    ``finite_difference``, which calls ``task.evaluate``.
    """
    central = sphere3d_methods.GRADIENT_METHODS.get("finite_difference").func
    wide, narrow = central(task, h), central(task, 0.5 * h)
    # E[D(s)] = I' + s² I'''/6 + O(s⁴): (4 D(h/2) - D(h)) / 3 = I' + O(h⁴)   (Richardson, per batch)
    return Tally(value=narrow.value, derivative=(4.0 * narrow.derivative - wide.derivative) / 3.0)
