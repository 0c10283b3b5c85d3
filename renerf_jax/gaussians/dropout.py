"""DropGaussian (Park et al., CVPR 2025): random Gaussian dropout in training.

Each training step leaves every Gaussian out of the render with probability p and
multiplies the opacity of the others by 1 / (1 - p), as inverted dropout does (the
expected opacity is unchanged; the rasteriser's alpha clamp at 0.99 still applies). The
Gaussians left in see larger gradients, which the paper finds regularises sparse views.
p rises linearly over the run, from 0 to Config.gs_drop_rate at max_steps (the reference
code: 0.2 x iteration / 10k over its 10k iterations). Renders outside training never
drop.
"""
import jax
import jax.numpy as jnp


def drop_rate_at(iteration, config):
  """The drop probability at a 1-based iteration: gs_drop_rate x iteration / max_steps,
  at most gs_drop_rate (Python number or traced array)."""
  return config.gs_drop_rate * jnp.minimum(iteration / config.max_steps, 1.)


def opacity_scale(key, n, rate):
  """Per-Gaussian opacity factors of one step.

  Args:
    key: PRNG key. n: number of Gaussian slots. rate: drop probability in [0, 1).

  Returns:
    [n] float32: 0 for a dropped Gaussian (probability `rate`), 1 / (1 - rate) for a
    kept one; all ones at rate 0.
  """
  rate = jnp.asarray(rate, jnp.float32)
  keep = jax.random.uniform(key, (n,)) >= rate
  return jnp.where(keep, 1. / (1. - rate), 0.).astype(jnp.float32)
