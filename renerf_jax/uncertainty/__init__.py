"""Uncertainty of a trained NeRF and the pseudo-view masks of Re-Nerfing, one concept a module.

  deformation  the Bayes' Rays deformation grid: x-major vertex table, clamped trilinear
               interpolation (offsets that move samples, per-vertex sigma over space).
  laplace      the Laplace (Gauss-Newton) Hessian diagonal of a trained NeRF w.r.t. the
               deformation grid, and the per-vertex sigma it gives.
  signals      per-pixel U variants from one render: Laplace, Bayes' Rays as released,
               weight entropy, depth variance, 1 - acc (and acc, a region selector).
  quality      how well a U ranks a model's per-pixel error: sparsification curves,
               AUSE, AURG, mask lift (pure numpy).
  masks        rendered U along pseudo-view rays, the threshold mu (mask_threshold, the
               one rule of every backbone), masks and compute_masks (Re-Nerfing's step).

This file imports none of them (so importing one never imports the rest, and no import
circle can form); import the one needed, e.g. `from renerf_jax.uncertainty import masks`.
"""
