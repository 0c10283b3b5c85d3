"""Shared helpers of the Gaussians' tests (test_gaussians_train, test_gaussians_strategy)."""
import jax.numpy as jnp
import numpy as np

from renerf_jax.gaussians import params as params_lib


def random_gaussians(n, capacity, seed=0):
  """n random visible active Gaussians in front of the identity-ish test camera."""
  rng = np.random.default_rng(seed)
  f = lambda x: jnp.asarray(x, jnp.float32)
  sh = 0.1 * rng.normal(size=(capacity, 16, 3))
  return params_lib.Gaussians(
      means=f(np.c_[rng.uniform(-0.5, 0.5, (capacity, 2)), rng.uniform(-4., -2.,
                                                                      capacity)]),
      log_scales=f(rng.uniform(-2.5, -1.5, (capacity, 3))),
      quats=f(rng.normal(size=(capacity, 4))),
      opacity_logits=f(rng.uniform(-1., 2., capacity)), sh=f(sh),
      active=jnp.arange(capacity) < n)
