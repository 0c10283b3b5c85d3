"""The NeRF backbone: a RegNeRF-style mip-NeRF as pure jitted functions.

backbone.py is what the round driver sees (backbones.Backbone); inside:
mip.py (frustum Gaussians, IPE, sampling, volume rendering), contraction.py (unbounded
scenes), fields/ (MLP and grid fields, the proposal grid), model.py (the coarse-to-fine
or proposal renderer), rendering.py (images in chunks), regularizers.py, training.py
(the jitted step and its loop on fit.fit), pools.py (training rays), synthesis.py
(pseudo-views and their masks), evaluation.py (test views).
"""
