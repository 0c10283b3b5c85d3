"""renerf-jax: Re-Nerfing (few-shot novel view synthesis improved by novel view
synthesis itself) over a NeRF and a 3D Gaussian Splatting backbone.

Importing the package turns XLA:CPU's YNNPACK fusions off for this process and the
processes it starts (xla_cpu.avoid_ynn_fusions), unless XLA_FLAGS already chooses them.
"""
from renerf_jax import xla_cpu

xla_cpu.avoid_ynn_fusions()
