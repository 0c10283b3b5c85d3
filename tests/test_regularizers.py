import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from renerf_jax.nerf import regularizers, training
from renerf_jax.datasets import load_scene, ray_pool
from renerf_jax.nerf.pools import regularizer_poses
from renerf_jax.nerf import pools as nerf_pools
from conftest import tiny_config


@pytest.mark.parametrize('step,expected', [(0, (0.9999, 1.)), (256, (0.5, 1.)),
                                           (512, (0., 1.)), (10000, (0., 1.))])
def test_annealed_interval_ndc(step, expected):
  near, far = regularizers.annealed_near_far(step, jnp.zeros(1), jnp.ones(1), 512, 1e-4, 1.)
  np.testing.assert_allclose([near[0], far[0]], expected, atol=1e-6)


def test_annealed_interval_with_mid_point():
  # mid = 2 + 0.5 * (6 - 2) = 4; at step 256 (w = 0.5): [3, 5].
  near, far = regularizers.annealed_near_far(256, jnp.array([2.]), jnp.array([6.]), 512,
                                             1e-4, 0.5)
  np.testing.assert_allclose([near[0], far[0]], [3., 5.], rtol=1e-6)


def test_depth_tv_weight_schedule():
  w = lambda s: float(regularizers.depth_tv_weight(s, 400., 0.1, 512))
  assert w(0) == pytest.approx(400., rel=1e-5)
  assert w(256) == pytest.approx(np.sqrt(400. * 0.1), rel=1e-5)  # log-linear midpoint
  assert w(512) == pytest.approx(0.1, rel=1e-5)
  assert w(60000) == pytest.approx(0.1, rel=1e-5)


def test_depth_tv_constant_and_ramp():
  assert float(regularizers.depth_tv(jnp.full((3, 8, 8), 0.7))) == 0.
  ramp = jnp.broadcast_to(0.1 * jnp.arange(8.), (2, 8, 8))  # slope 0.1 along x only
  assert float(regularizers.depth_tv(ramp)) == pytest.approx(0.01, rel=1e-5)
  assert float(regularizers.depth_tv(jnp.swapaxes(ramp, 1, 2))) == pytest.approx(0.01,
                                                                                 rel=1e-5)


def test_occlusion_loss_only_front_samples():
  density = jnp.concatenate([jnp.full((4, 3), 2.), jnp.full((4, 5), 100.)], -1)
  assert float(regularizers.occlusion_loss(density, 3)) == pytest.approx(2.)


def test_patches_come_from_many_distinct_poses():
  config = tiny_config(use_ndc=False, n_random_poses=10000, batch_size_random=4096,
                       patch_size=8)
  scene = load_scene(config)
  poses = regularizer_poses(config, scene)
  assert poses.shape == (10000, 3, 4)
  assert len(np.unique(np.round(np.asarray(poses[:, :, 3]), 6), axis=0)) == 10000
  cam = training.Camera.of(scene)
  rays = training.random_patch_rays(poses, jax.random.PRNGKey(0), 64, 8, cam)
  assert rays.origins.shape == (64, 8, 8, 3)
  # Without NDC a patch's rays share their camera centre: 64 patches, ~64 poses.
  centres = np.round(np.asarray(rays.origins[:, 0, 0]), 6)
  assert len(np.unique(centres, axis=0)) >= 60
  np.testing.assert_allclose(rays.origins, np.broadcast_to(rays.origins[:, :1, :1],
                                                           rays.origins.shape))


def _lowered_flops(config, pools):
  scene = load_scene(config)
  cam = training.Camera.of(scene)
  state = training.init_state(config, jax.random.PRNGKey(0))
  fn = jax.jit(functools.partial(training.train_step.__wrapped__, config, cam, 0))
  lowered = fn.lower(state, pools, jax.random.PRNGKey(1))
  return lowered.compile().cost_analysis()['flops'], lowered.as_text()


def test_switched_off_regularisers_are_not_traced():
  on = tiny_config(depth_tv_loss_mult=0.1, occ_reg_mult=0.01, freq_reg=True)
  off = tiny_config(depth_tv_loss_mult=0., occ_reg_mult=0., freq_reg=False)
  scene = load_scene(on)
  pools = {'real': ray_pool(scene, scene.train_idx)}
  # Off: the step traces without any random poses at all (it would fail if it used them).
  flops_off, text_off = _lowered_flops(off, pools)
  pools_on = dict(pools, random_poses=regularizer_poses(on, scene))
  flops_on, text_on = _lowered_flops(on, pools_on)
  # 64 batch rays + 64 patch rays: the patch rendering adds a large share of the work
  # (the optimizer update and ray sampling are fixed costs of this tiny network).
  assert flops_on > 1.2 * flops_off
  assert len(text_on) > len(text_off)


@pytest.mark.parametrize('field', ['mlp', 'grid'])
def test_freenerf_regularisers_train_on_both_fields(field):
  config = tiny_config(field=field, freq_reg=True, occ_reg_mult=0.01, occ_reg_range=4,
                       depth_tv_loss_mult=0., grid_levels=4, grid_base_res=4, grid_max_res=16,
                       grid_log2_hashmap_size=10, grid_mlp_width=16)
  scene = load_scene(config)
  pools = {'real': ray_pool(scene, scene.train_idx)}
  state = training.init_state(config, jax.random.PRNGKey(0))
  cam = training.Camera.of(scene)
  for i in range(2):
    state, stats = training.train_step(config, cam, False, state, pools, jax.random.PRNGKey(i))
  assert bool(stats['finite']) and float(stats['occ']) >= 0.


def test_near_camera_weight_counts_weight_within_the_radius_only():
  """The penalty is the mean over rays of the weight at midpoints within the radius of
  any centre: by hand on two rays; 0 with radius 0, no centre near, or zero weights."""
  origins = jnp.array([[0., 0., 0.], [0., 0., 0.]])
  dirs = jnp.array([[0., 0., 1.], [2., 0., 0.]])  # unnormalised: distance = 2 t on ray 2
  t = jnp.tile(jnp.array([[0., 1., 2., 3.]]), (2, 1))  # midpoints 0.5, 1.5, 2.5
  w = jnp.array([[0.2, 0.3, 0.5], [0.1, 0.6, 0.3]])
  centres = jnp.array([[0., 0., 1.4], [10., 10., 10.]])
  # Ray 1: midpoint 1.5 is 0.1 from the first centre (weight 0.3). Ray 2's points
  # (1, 0, 0), (3, 0, 0), (5, 0, 0) are >= 1.7 from it: 0.
  got = regularizers.near_camera_weight(origins, dirs, t, w, centres, 0.5)
  np.testing.assert_allclose(float(got), 0.3 / 2, rtol=1e-6)
  # A radius of 1.2 also takes ray 1's 0.5 (0.9 away) and 2.5 (1.1 away).
  np.testing.assert_allclose(float(regularizers.near_camera_weight(
      origins, dirs, t, w, centres, 1.2)), 1.0 / 2, rtol=1e-6)
  assert float(regularizers.near_camera_weight(origins, dirs, t, w, centres, 0.)) == 0.
  assert float(regularizers.near_camera_weight(origins, dirs, t, w, centres[1:], 0.5)) == 0.
  assert float(regularizers.near_camera_weight(origins, dirs, t, 0. * w, centres, 9.)) == 0.
  # Zero-length intervals and huge coordinates stay finite.
  flat_t = jnp.zeros((2, 4))
  huge = regularizers.near_camera_weight(origins * 1e30, dirs, flat_t, w, centres, 0.5)
  assert np.isfinite(float(huge))


def test_near_camera_loss_in_training_reaches_the_loss_and_trains():
  """Off: no statistic and no pool. On: the loss grows by mult x the statistic, and a few
  steps train with finite losses; NDC configs refuse it in one line."""
  import dataclasses  # pylint: disable=g-import-not-at-top
  from renerf_jax.configs import Config  # pylint: disable=g-import-not-at-top
  from renerf_jax.errors import ConfigError  # pylint: disable=g-import-not-at-top
  config = tiny_config(use_ndc=False, near=0.05, far=6., depth_tv_loss_mult=0.,
                       anneal_nearfar=False, max_steps=6)
  scene = load_scene(config)
  assert 'camera_centres' not in nerf_pools.make_pools(config, scene, None)
  # The embedded scene starts its rays 1.2 from the camera: a radius of 1.6 reaches them.
  on_cfg = dataclasses.replace(config, near_camera_loss_mult=2., near_camera_radius=1.6)
  pools = nerf_pools.make_pools(on_cfg, scene, None)
  np.testing.assert_allclose(pools['camera_centres'],
                             scene.poses[scene.train_idx][:, :3, 3], atol=1e-6)
  cam = training.Camera.of(scene)
  batch = training.sample_from_pool(pools['real'], jax.random.PRNGKey(1), config.batch_size)
  params = training.init_state(config, jax.random.PRNGKey(0)).params
  key = jax.random.PRNGKey(5)
  off, stats_off = training.loss_fn(params, config, cam, batch, None, 10., key)
  on, stats_on = training.loss_fn(params, on_cfg, cam, batch, None, 10., key,
                                  pools['camera_centres'])
  assert 'near_camera' not in stats_off and float(stats_on['near_camera']) > 0.
  np.testing.assert_allclose(float(on), float(off) + 2. * float(stats_on['near_camera']),
                             rtol=1e-5)
  result = training.train_model(on_cfg, scene, None, pools, show_progress=False)
  assert int(result.state.step) == 6 and int(result.state.nan_skips) == 0
  with pytest.raises(ConfigError, match='needs use_ndc = False'):
    Config(near_camera_loss_mult=1.)
