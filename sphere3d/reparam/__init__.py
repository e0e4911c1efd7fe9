"""The parts of the ``reparam`` method (:mod:`sphere3d.methods.reparam`): the estimator as published and
its extensions, one module each.

:mod:`~sphere3d.reparam.paper` is Loubet et al. 2019, Sec. 4.1-4.3 as published (the probe rule,
``PaperTransforms``); :mod:`~sphere3d.reparam.default` is the default variant, the paper's estimator
with the extensions: probes on a ring and bisection to the silhouette
(:mod:`~sphere3d.reparam.probes`, :mod:`~sphere3d.reparam.bisection`), the snap onto an edge and the
turn about it (:mod:`~sphere3d.reparam.snaps`), the per-sample film kernel
(:mod:`~sphere3d.reparam.film_kernel`), T-junctions (:mod:`~sphere3d.reparam.junctions`), the emitter
rotation that follows the shadow edge (:mod:`~sphere3d.reparam.emitter_probes`) and its cull
(:mod:`~sphere3d.reparam.penumbra`). The theory page *extensions* derives each.
"""
