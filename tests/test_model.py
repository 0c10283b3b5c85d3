"""Tests of model.py helpers (render_rays itself is covered by test_training / test_grid)."""
import jax
import jax.numpy as jnp
import numpy as np

from renerf_jax.model import materialize


def test_materialize_is_the_identity_on_extreme_values():
  x = jnp.array([[jnp.nan, 1.], [jnp.inf, -jnp.inf], [0., -0.], [3e38, 1e-45]])
  y = jax.jit(materialize)(x)
  np.testing.assert_array_equal(np.asarray(y), np.asarray(x))  # NaN in the first entry too
  tree = (jnp.ones((2, 3)), jnp.arange(4.))
  out = jax.jit(materialize)(tree)
  for a, b in zip(out, tree):
    np.testing.assert_array_equal(a, b)
  empty = jnp.zeros((0, 3))
  assert materialize(empty).shape == (0, 3)


def test_materialize_passes_gradients_and_vmaps():
  x = jnp.array([1., -2., 3.])
  g = jax.grad(lambda v: jnp.sum(materialize(v)**2))(x)
  np.testing.assert_allclose(g, 2. * x)
  batched = jax.vmap(materialize)(jnp.array([[jnp.nan, 1.], [2., 3.]]))
  np.testing.assert_array_equal(batched, np.array([[np.nan, 1.], [2., 3.]]))


def test_materialize_is_a_conditional_in_the_compiled_step():
  # The point of the helper: a boundary XLA keeps (an optimization_barrier is dropped).
  f = jax.jit(lambda v: materialize(v * 2.) + 1.)
  hlo = f.lower(jnp.ones((8, 3))).compile().as_text()
  assert 'conditional' in hlo
