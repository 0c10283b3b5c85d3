"""DropGaussian (gaussians/dropout.py, Config.gs_drop_rate): the schedule, the factors,
the render and gradients of a step that drops, and training with it."""
import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from conftest import tiny_config
from gaussian_helpers import random_gaussians
from renerf_jax.configs import Config
from renerf_jax.errors import ConfigError
from renerf_jax.gaussians import dropout
from renerf_jax.gaussians import training as gtrain

_POSE = jnp.asarray(np.eye(4)[:3], jnp.float32)
_CAM = gtrain.Camera(24, 32, 30.)
_N = 18
_CFG = tiny_config(backbone='gaussians', procedural_size=(24, 32), max_steps=24,
                   print_every=1, checkpoint_every=1000, eval_every=1000,
                   gs_capacity=512, gs_init_points=256, gs_tile_cap=512,
                   gs_densify_from_frac=0.25, gs_densify_until_frac=0.8,
                   gs_densify_every_frac=0.25, gs_opacity_reset_every_frac=1.,
                   gs_lr_sh_dc=0.03, gs_lr_means_init=1e-2, gs_lr_means_final=1e-3)
_loss_and_grads = jax.jit(gtrain.loss_and_grads, static_argnums=(0, 1))


def test_the_drop_rate_rises_linearly_to_the_config_value():
  cfg = Config(backbone='gaussians', gs_drop_rate=0.2, max_steps=10000)
  rates = [float(dropout.drop_rate_at(i, cfg)) for i in (0, 1, 2500, 5000, 10000, 20000)]
  np.testing.assert_allclose(rates, [0., 2e-5, 0.05, 0.1, 0.2, 0.2], rtol=1e-6)
  assert float(dropout.drop_rate_at(5000, Config(backbone='gaussians', max_steps=10000))) == 0.
  for bad in (-0.1, 1., 1.5):
    with pytest.raises(ConfigError, match='gs_drop_rate'):
      Config(backbone='gaussians', gs_drop_rate=bad)


def test_factors_drop_at_the_rate_and_keep_the_expected_opacity():
  n = 200_000
  ones = dropout.opacity_scale(jax.random.PRNGKey(0), n, 0.)
  assert ones.dtype == jnp.float32 and np.all(np.asarray(ones) == 1.)
  for rate in (0.05, 0.3, 0.9, 0.999):
    s = np.asarray(dropout.opacity_scale(jax.random.PRNGKey(1), n, rate))
    dropped = np.mean(s == 0.)
    assert abs(dropped - rate) < 5. * np.sqrt(rate * (1. - rate) / n), (rate, dropped)
    np.testing.assert_allclose(s[s > 0.], 1. / (1. - np.float32(rate)), rtol=1e-6)
    assert np.all(np.isfinite(s))
    assert abs(s.mean() - 1.) < 6. * np.sqrt(rate / ((1. - rate) * n))  # Unbiased.
  a, b = (dropout.opacity_scale(jax.random.PRNGKey(k), 1000, 0.5) for k in (2, 3))
  assert not np.array_equal(a, b)  # A fresh draw per key.


def test_a_dropped_gaussian_is_out_of_the_image_and_gets_no_gradient():
  g = random_gaussians(_N, _N)
  img = jnp.full((24, 32, 3), 0.3, jnp.float32)
  mask = jnp.ones((24, 32), jnp.float32)
  f = lambda gg, scale=None: _loss_and_grads(_CFG, _CAM, gg, img, _POSE, mask, 3, scale)
  plain = f(g)
  ones = f(g, jnp.ones(_N, jnp.float32))
  np.testing.assert_array_equal(plain[2]['rgb'], ones[2]['rgb'])
  assert float(plain[0]) == float(ones[0])
  keep = np.arange(_N) % 3 != 0
  dropped = f(g, jnp.asarray(keep, jnp.float32))
  without = f(g.replace(active=jnp.asarray(keep)))
  np.testing.assert_allclose(dropped[2]['rgb'], without[2]['rgb'], atol=1e-6)
  assert np.abs(np.asarray(dropped[2]['rgb'] - plain[2]['rgb'])).max() > 1e-3
  for x in jax.tree_util.tree_leaves(dropped[3]):
    x = np.asarray(x)
    assert np.all(x[~keep] == 0.)
  assert np.abs(np.asarray(dropped[3]['sh_dc'])[keep]).max() > 0.
  # A kept Gaussian's opacity is multiplied: factor c = a Gaussian of opacity c x o
  # (opacities up to 0.69 here, so c x o stays below 1).
  c = 1.25
  g = g.replace(opacity_logits=jnp.minimum(g.opacity_logits, 0.8))
  o = jax.nn.sigmoid(g.opacity_logits)
  scaled = f(g, jnp.full(_N, c, jnp.float32))
  as_logit = f(g.replace(opacity_logits=jnp.log(c * o) - jnp.log1p(-c * o)))
  np.testing.assert_allclose(scaled[2]['rgb'], as_logit[2]['rgb'], atol=2e-5)


def test_training_with_dropout_draws_per_step_and_renders_without_it(tmp_path):
  scene = gtrain_scene()
  cfg = dataclasses.replace(_CFG, gs_drop_rate=0.5)
  runs = {c.gs_drop_rate: gtrain.train_gaussians(c, scene, str(tmp_path / str(i)), None,
                                                 show_progress=False)
          for i, c in enumerate((_CFG, cfg))}
  off, on = runs[0.].state, runs[0.5].state
  assert int(on.step) == cfg.max_steps and int(on.nan_skips) == 0
  assert not np.array_equal(np.asarray(off.params.means), np.asarray(on.params.means))
  # Renders outside training are deterministic: no dropout.
  poses = scene.poses[scene.train_idx]
  a = gtrain.render_views(cfg, scene, on.params, poses)['rgb']
  b = gtrain.render_views(cfg, scene, on.params, poses)['rgb']
  np.testing.assert_array_equal(a, b)
  assert np.all(np.isfinite(a))
  # Resumed from the checkpoint at the end, the run trains nothing more.
  again = gtrain.train_gaussians(cfg, scene, str(tmp_path / '1'), None,
                                 show_progress=False).state
  np.testing.assert_array_equal(np.asarray(on.params.means), np.asarray(again.params.means))


def gtrain_scene():
  from renerf_jax.datasets import load_scene  # pylint: disable=g-import-not-at-top
  return load_scene(_CFG)
