"""mip-NeRF 360's distortion loss (regularizers.distortion_loss) and its use in the step."""
import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from renerf_jax.nerf import regularizers, training
from renerf_jax.configs import Config
from renerf_jax.datasets import load_scene, ray_pool
from renerf_jax.errors import ConfigError
from renerf_jax.nerf.model import render_rays
from renerf_jax.nerf.pools import regularizer_poses
from conftest import tiny_config


def _brute(s, w):
  """The double sum of the definition, in float64."""
  s, w = np.asarray(s, np.float64), np.asarray(w, np.float64)
  m = 0.5 * (s[1:] + s[:-1])
  inter = np.sum(w[:, None] * w[None, :] * np.abs(m[:, None] - m[None, :]))
  return inter + np.sum(w**2 * (s[1:] - s[:-1])) / 3.


def test_distortion_matches_the_double_sum():
  rng = np.random.default_rng(0)
  for n in (1, 2, 7, 48):
    s = np.sort(rng.uniform(0., 1., (5, n + 1)), axis=-1)
    w = rng.uniform(0., 1., (5, n)) * (rng.uniform(size=(5, n)) < 0.7) / n
    got = np.asarray(regularizers.distortion_loss(jnp.asarray(s, jnp.float32),
                                                  jnp.asarray(w, jnp.float32)))
    np.testing.assert_allclose(got, [_brute(a, b) for a, b in zip(s, w)], rtol=1e-5,
                               atol=1e-7)


def test_distortion_values_on_extreme_rays():
  s = jnp.linspace(0., 1., 5)
  loss = lambda s, w: float(regularizers.distortion_loss(s, w))
  assert loss(s, jnp.zeros(4)) == 0.  # Nothing rendered.
  # All the weight in one interval: only its own spread, w^2 * width / 3.
  assert loss(s, jnp.array([0., 0., 1., 0.])) == pytest.approx(0.25 / 3., rel=1e-6)
  # Two spikes 0.5 apart: 2 * 0.5 * 0.5 * 0.5 + 2 * 0.25 * 0.25 / 3.
  assert loss(s, jnp.array([.5, 0., .5, 0.])) == pytest.approx(0.25 + 0.125 / 3.,
                                                               rel=1e-6)
  # Zero-length intervals (all edges equal) and huge weights stay finite.
  flat = jnp.full(5, 0.3)
  for w in (jnp.ones(4), jnp.full(4, 1e15)):
    val, grad = jax.value_and_grad(regularizers.distortion_loss, argnums=(0, 1))(flat, w)
    assert val == 0. and all(np.all(np.isfinite(np.asarray(g))) for g in grad)


def test_descent_on_the_distortion_concentrates_the_weights():
  s = jnp.linspace(0., 1., 17)
  logits = jnp.asarray(np.random.default_rng(1).normal(size=16), jnp.float32)
  loss = lambda z: regularizers.distortion_loss(s, 0.9 * jax.nn.softmax(z))
  start = float(loss(logits))
  for _ in range(300):
    logits = logits - 20. * jax.grad(loss)(logits)
  w = 0.9 * jax.nn.softmax(logits)
  assert float(loss(logits)) < 0.3 * start
  assert float(jnp.max(w)) > 0.6  # Most of the mass ends up in one interval.


def test_ray_distortion_is_scale_free_and_handles_near_equal_far():
  rng = np.random.default_rng(2)
  t = jnp.asarray(np.sort(rng.uniform(2., 6., (4, 9)), axis=-1), jnp.float32)
  w = jnp.asarray(rng.uniform(0., .2, (4, 8)), jnp.float32)
  near, far = jnp.full((4, 1), 2.), jnp.full((4, 1), 6.)
  a = float(regularizers.ray_distortion(t, w, near, far))
  b = float(regularizers.ray_distortion(10. * t, w, 10. * near, 10. * far))
  assert a == pytest.approx(b, rel=1e-5) and a > 0.
  same = jnp.full((4, 9), 3.)
  val = regularizers.ray_distortion(same, w, jnp.full((4,), 3.), jnp.full((4,), 3.))
  assert np.isfinite(float(val))


def test_distortion_is_validated():
  with pytest.raises(ConfigError, match='distortion_loss_mult'):
    Config(distortion_loss_mult=-1.)


@pytest.mark.parametrize('sampler', ['coarse_fine', 'proposal'])
def test_loss_adds_the_weighted_distortion_of_batch_and_patches(sampler):
  """Off: no term and no statistic. On: the loss grows by mult x the ray-weighted mean
  distortion of the last level over the batch and the random-pose patches."""
  config = tiny_config(field='grid', grid_levels=4, grid_base_res=4, grid_max_res=16,
                       grid_log2_hashmap_size=10, grid_mlp_width=16, num_levels=2,
                       sampler=sampler, proposal_levels=2, proposal_max_res=16,
                       proposal_log2_hashmap_size=10, depth_tv_loss_mult=0.1,
                       anneal_nearfar=False)
  scene = load_scene(config)
  cam = training.Camera.of(scene)
  batch = training.sample_from_pool(ray_pool(scene, scene.train_idx),
                                    jax.random.PRNGKey(1), config.batch_size)
  patches = training.random_patch_rays(regularizer_poses(config, scene),
                                       jax.random.PRNGKey(0), 4, config.patch_size, cam)
  params = training.init_state(config, jax.random.PRNGKey(0)).params
  key = jax.random.PRNGKey(5)
  off, stats_off = training.loss_fn(params, config, cam, batch, patches, 10., key)
  assert 'distortion' not in stats_off
  on_cfg = dataclasses.replace(config, distortion_loss_mult=0.5)
  on, stats_on = training.loss_fn(params, on_cfg, cam, batch, patches, 10., key)
  dist = float(stats_on['distortion'])
  assert dist > 0.
  np.testing.assert_allclose(float(on), float(off) + 0.5 * dist, rtol=1e-5)
  # The same renders by hand (loss_fn's keys): the ray-weighted mean of both parts.
  k_main, k_patch = jax.random.split(key)
  flat = jax.tree_util.tree_map(lambda x: x.reshape((-1,) + x.shape[3:]), patches)
  parts = [(render_rays(config, params, batch['rays'], k_main, train=True)[-1],
            batch['rays']), (render_rays(config, params, flat, k_patch, train=True)[-1], flat)]
  means = [float(regularizers.ray_distortion(lv['t_vals'], lv['weights'], r.near, r.far))
           for lv, r in parts]
  n_b, n_p = config.batch_size, flat.near.shape[0]
  assert means[0] != pytest.approx(means[1], rel=1e-3)
  np.testing.assert_allclose(dist, (n_b * means[0] + n_p * means[1]) / (n_b + n_p),
                             rtol=1e-5)
