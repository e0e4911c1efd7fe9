"""flatland's reparameterization (Loubet et al. 2019, Sec. 4): the probe rules that choose what a
translation follows (:mod:`flatland.reparam.probes`) and the ``reparam`` method's changes of
variables (:mod:`flatland.reparam.default`)."""
