"""The parts of flatland's ``reparam`` method (:mod:`flatland.methods.reparam`): the probe heuristic
(:mod:`~flatland.reparam.probes`, Loubet et al. 2019, Sec. 4.3) and the transforms of the pixel and
shading integrals (:mod:`~flatland.reparam.default`), the same shape as :mod:`sphere3d.reparam`.
"""
