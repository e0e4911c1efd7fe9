"""The ``reparam`` method's pieces (Loubet et al. 2019, Sec. 4): the estimator as published
(:mod:`~sphere3d.reparam.paper`), the default variant (:mod:`~sphere3d.reparam.default`) and one module
per extension it adds (probes, bisection, snaps, junctions, the film kernel, the emitter probes and
their penumbra cull)."""
