"""The ``boundary`` method's pieces (edge sampling, Li et al. 2018): the mesh edges where integrands
jump (:mod:`~sphere3d.boundary.edges`), the boundary terms of the pixel integrals
(:mod:`~sphere3d.boundary.camera`), of the shading integrals (:mod:`~sphere3d.boundary.shading`) and of
the emitters' own edges (:mod:`~sphere3d.boundary.emitters`), and the method's transforms
(:mod:`~sphere3d.boundary.transforms`)."""
