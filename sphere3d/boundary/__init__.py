"""The parts of the ``boundary`` method (:mod:`sphere3d.methods.boundary`): edge sampling (Li et al. 2018).

:mod:`~sphere3d.boundary.edges` finds the mesh edges where the integrands can jump;
:mod:`~sphere3d.boundary.camera` and :mod:`~sphere3d.boundary.shading` estimate the boundary terms of
the pixel and shading integrals; :mod:`~sphere3d.boundary.transforms` hands them to the integrator
through its ``pixel_extra`` and ``shading_extra`` hooks. :mod:`~sphere3d.boundary.emitters` is the
boundary term of the emitters' own edges under a rotated emitter strategy, which the default
variant of ``reparam`` adds.
"""
