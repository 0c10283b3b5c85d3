"""Extreme inputs: finite values, finite gradients and the expected limits.

Cases already covered elsewhere (not repeated here): densities 0 and 1e10 with gradients
(test_mip.test_volumetric_rendering_extremes), IPE with huge variances and its gradient
(test_mip.test_ipe_huge_variance_goes_to_zero_without_nan), SLERP between identical,
nearly identical, antipodal and half-turn rotations (test_poses.test_slerp_*), matrix to
quaternion at and near 180 degrees (test_poses ADVERSARIAL cases), Hessian diagonal with
unseen vertices (test_laplace.test_unseen_vertices_get_the_prior), thresholds mu = 0
and mu = inf (test_uncertainty.test_extreme_thresholds), all-masked batches
(test_training.test_masked_mse_all_masked_is_finite_zero_with_zero_gradient,
test_training.test_all_masked_batch_trains_without_nan,
test_renerf.test_all_masked_pseudo_views_still_train_on_real_views).
"""
import dataclasses
import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import REPO, tiny_config

from renerf_jax import cameras, renerf, round_driver
from renerf_jax.nerf import mip
from renerf_jax.datasets import load_scene, ray_pool
from renerf_jax.errors import ConfigError
from renerf_jax.nerf.fields import init_field_params
from renerf_jax.nerf.model import render_rays
from renerf_jax.pseudo_views import pseudo_view_poses
from renerf_jax.nerf import pools


def _all_finite(tree):
  return all(bool(np.all(np.isfinite(np.asarray(x)))) for x in jax.tree_util.tree_leaves(tree))


# ------------------------------------------------------------ interval lengths


@pytest.mark.parametrize('white_bkgd', [False, True])
@pytest.mark.parametrize('density', [0., 1e-3, 1., 1e10])
def test_zero_and_huge_interval_lengths_in_volume_rendering(density, white_bkgd):
  d = jnp.array([[0., 0., -1.]])
  rgb = jnp.array([[[0.2, 0.4, 0.6], [0.9, 0.1, 0.3], [0.5, 0.5, 0.5]]])
  dens = jnp.full((1, 3), density)

  def loss(dens, t_vals):
    out = mip.volumetric_rendering(rgb, dens, t_vals, d, white_bkgd)
    return out['rgb'].sum() + out['distance'].sum() + out['acc'].sum()

  bg = 1. if white_bkgd else 0.
  # Length 0 (near == far == 1): nothing is rendered, the distance is the far end.
  zero = jnp.ones((1, 4))
  out = mip.volumetric_rendering(rgb, dens, zero, d, white_bkgd)
  assert _all_finite(out)
  np.testing.assert_array_equal(out['weights'], 0.)
  np.testing.assert_array_equal(out['acc'], 0.)
  np.testing.assert_allclose(out['rgb'], bg)
  np.testing.assert_allclose(out['distance'], 1.)
  assert _all_finite(jax.grad(loss, argnums=(0, 1))(dens, zero))
  # Length 1e10: any positive density is opaque at the first sample; zero stays empty.
  huge = jnp.array([[0., 1e10, 2e10, 3e10]])
  out = mip.volumetric_rendering(rgb, dens, huge, d, white_bkgd)
  assert _all_finite(out)
  if density == 0.:
    np.testing.assert_array_equal(out['acc'], 0.)
    np.testing.assert_allclose(out['distance'], 3e10)
    np.testing.assert_allclose(out['rgb'], bg)
  else:
    np.testing.assert_allclose(out['weights'], [[1., 0., 0.]])
    np.testing.assert_allclose(out['rgb'], rgb[:, 0])
    np.testing.assert_allclose(out['distance'], 5e9, rtol=1e-6)
  assert _all_finite(jax.grad(loss, argnums=(0, 1))(dens, huge))


@pytest.mark.parametrize('ray_shape', ['cone', 'cylinder'])
def test_huge_intervals_give_vanishing_ipe_features_not_nan(ray_shape):
  """A 1e10-long segment is a Gaussian of variance ~1e19: its IPE features are 0.

  Before the fix the cone's variance overflowed float32 (h^4 (12 mu^2 - h^2)): 0 for
  segments from ~4e6 long on, NaN for ~6e9.
  """
  o = jnp.zeros((1, 3))
  d = jnp.array([[0.3, 0., -1.]])
  r = jnp.full((1, 1), 1e-3)

  def feats(t_vals):
    means, covs = mip.cast_rays(t_vals, o, d, r, ray_shape)
    return mip.integrated_pos_enc(means, covs, 0, 16), covs

  for t_end in (1e8, 1e10):
    t_vals = jnp.array([[0., t_end, 2. * t_end]])
    f, covs = feats(t_vals)
    assert _all_finite((f, covs))
    # The variance along the ray of the segment [0, t1]: 3/80 t1^2 for the cone (uniform
    # in volume), t1^2 / 12 for the cylinder.
    assert float(covs[0, 0, 2]) > 0.03 * t_end**2
    # Features of the coordinates along the ray (x, z) vanish. Across it (y) the cone's
    # radius grows with t, so its y features vanish too; the cylinder keeps its radius.
    f = np.asarray(f).reshape(2, 2, 16, 3)  # [segment, sin/cos, band, coordinate]
    np.testing.assert_allclose(f[..., 0::2], 0., atol=1e-6)
    if ray_shape == 'cone':
      np.testing.assert_allclose(f, 0., atol=1e-6)
    g = jax.grad(lambda t: jnp.sum(feats(t)[0]))(t_vals)
    assert _all_finite(g)


# ------------------------------------------------------------ near == far, full model


@pytest.mark.parametrize('ray_shape', ['cone', 'cylinder'])
def test_near_equals_far_through_the_model_is_finite_with_gradients(ray_shape):
  config = tiny_config(ray_shape=ray_shape)
  scene = load_scene(config)
  pool = ray_pool(scene, scene.train_idx)
  rays = jax.tree_util.tree_map(lambda x: x[:16], pool['rays'])
  params = init_field_params(config, jax.random.PRNGKey(0))
  target = pool['rgb'][:16]

  @jax.jit
  def loss_and_grad(params, rays):
    def loss(params):
      levels = render_rays(config, params, rays, jax.random.PRNGKey(1), train=True)
      return sum(jnp.mean((lv['rgb'] - target)**2) + jnp.mean(lv['distance'])
                 for lv in levels), levels
    return jax.value_and_grad(loss, has_aux=True)(params)

  for t in (0., 0.5):
    flat = rays.replace(near=jnp.full_like(rays.near, t), far=jnp.full_like(rays.far, t))
    (value, levels), grads = loss_and_grad(params, flat)
    assert np.isfinite(float(value)) and _all_finite(levels) and _all_finite(grads)
    for lv in levels:  # An empty interval renders nothing, at distance near == far.
      np.testing.assert_array_equal(lv['acc'], 0.)
      np.testing.assert_array_equal(lv['rgb'], 0.)
      np.testing.assert_allclose(lv['distance'], t)


# ------------------------------------------------------------ NDC, rays parallel to the image plane


def test_ndc_rays_parallel_to_the_image_plane_limit_and_gradients():
  f, h, w = 10., 20., 20.
  o = jnp.zeros((5, 3))
  # |d_z| < 1e-6 is clamped to 1e-6 of its sign; 0 counts as forward (-1e-6).
  d = jnp.array([[1., 0., 0.], [1., 0., -1e-12], [1., 0., 1e-12], [0., 1., -1e-9],
                 [1., 0., -2e-6]])
  o_ndc, d_ndc = cameras.convert_to_ndc(o, d, f, h, w)
  assert _all_finite((o_ndc, d_ndc))
  # Still an NDC ray from the near plane (z = -1) to infinity (z = 1).
  np.testing.assert_allclose(o_ndc[:, 2], -1., atol=1e-6)
  np.testing.assert_allclose(o_ndc[:, 2] + d_ndc[:, 2], 1., atol=1e-6)
  # The limit: the ray meets z = -1 at x = d_x / |d_z|, projected to 2 f / w * x; in
  # front of the camera for d_z < 0, behind it (x -> -inf) for d_z > 0.
  big = 2. * f / w / 1e-6
  np.testing.assert_allclose(o_ndc[:, 0], [big, big, -big, 0., big / 2.], rtol=1e-5)
  np.testing.assert_allclose(o_ndc[3, 1], 2. * f / h / 1e-6, rtol=1e-5)
  np.testing.assert_array_equal(o_ndc[0], o_ndc[1])  # d_z = 0 is the limit d_z -> 0-
  np.testing.assert_array_equal(d_ndc[0], d_ndc[1])
  grads = jax.grad(lambda o, d: jnp.sum(jnp.concatenate(cameras.convert_to_ndc(
      o, d, f, h, w))), argnums=(0, 1))(o, d)
  assert _all_finite(grads)


def test_ndc_camera_looking_sideways_renders_finite_with_gradients():
  """A camera whose centre row is parallel to the NDC image plane (world d_z = 0)."""
  config = tiny_config()
  c2w = np.array([[0., 0., 1., 0.1], [1., 0., 0., 0.], [0., 1., 0., 0.]], np.float32)
  rays = cameras.image_rays(c2w, 5, 6, 5., use_ndc=True, near=0., far=1.)
  rays = jax.tree_util.tree_map(lambda x: x.reshape((-1,) + x.shape[2:]), rays)
  world_dz = np.asarray(rays.viewdirs[:, 2])
  assert np.sum(world_dz == 0.) == 6  # The centre row.
  assert _all_finite(rays) and np.all(np.asarray(rays.radii) >= 0.)
  params = init_field_params(config, jax.random.PRNGKey(0))

  def loss(params):
    levels = render_rays(config, params, rays, jax.random.PRNGKey(1), train=True)
    return sum(jnp.mean(lv['rgb']**2) for lv in levels), levels

  (value, levels), grads = jax.jit(jax.value_and_grad(loss, has_aux=True))(params)
  assert np.isfinite(float(value)) and _all_finite(levels) and _all_finite(grads)


# ------------------------------------------------------------ a single training view


def test_single_training_view_with_interpolation_is_one_config_error(tmp_path):
  config = tiny_config(n_input_views=1, num_rounds=1)
  scene = load_scene(config)
  assert len(scene.train_idx) == 1
  for targets in ('interp', 'interp+test'):
    with pytest.raises(ConfigError, match='at least 2 training views') as e:
      round_driver.run_rounds(dataclasses.replace(config, pseudo_targets=targets), scene,
                              str(tmp_path / 'run'), show_progress=False)
    assert '\n' not in str(e.value) and "pseudo_targets='test'" in str(e.value)
  # So is every other pseudo-view setting round 1 could not use.
  with pytest.raises(ConfigError, match='interp_factors'):
    round_driver.run_rounds(
        dataclasses.replace(config, n_input_views=2, interp_factors='0.5,2'),
        load_scene(dataclasses.replace(config, n_input_views=2)), str(tmp_path / 'run'),
        show_progress=False)
  assert not os.path.exists(tmp_path / 'run')  # Raised before anything was written.
  # The documented fallbacks are accepted: test poses as pseudo-views, or no rounds.
  renerf.check_rounds_config(dataclasses.replace(config, pseudo_targets='test'), scene)
  renerf.check_rounds_config(dataclasses.replace(config, num_rounds=0), scene)
  poses, meta = pseudo_view_poses(dataclasses.replace(config, pseudo_targets='test'), scene)
  assert poses.shape == (len(scene.test_idx), 3, 4) and meta[0]['kind'] == 'test'


def test_single_training_view_cli_exits_2_with_one_error_line(tmp_path):
  env = dict(os.environ, PYTHONPATH=str(REPO))
  res = subprocess.run(
      [sys.executable, 'train.py', '--gin_configs=gin_configs/demo_llff.gin',
       f'--run_dir={tmp_path}/run', '--gin_bindings=Config.n_input_views=1',
       '--gin_bindings=Config.procedural_size=(32, 40)'],
      cwd=REPO, env=env, capture_output=True, text=True, timeout=300, check=False)
  assert res.returncode == 2, res.stderr[-2000:]
  assert res.stderr.strip().count('\n') == 0, res.stderr
  assert res.stderr.startswith('error: ') and 'n_input_views' in res.stderr
  assert not os.path.exists(tmp_path / 'run')


def test_single_training_view_fallback_trains_finite():
  config = tiny_config(n_input_views=1, num_rounds=1, pseudo_targets='test', max_steps=8,
                       pseudo_until_frac=1., eval_every=0, lpips_nets=())
  scene = load_scene(config)
  state = renerf.run_rounds(config, scene)  # in memory
  assert [m['round'] for m in state.metrics] == [0, 1]
  for m in state.metrics:
    assert np.isfinite(m['psnr']) and m['nan_skips'] == 0
  assert state.pseudo.images.shape[0] == len(scene.test_idx) and _all_finite(state.params)


# ------------------------------------------------------------ two identical cameras


def _identical_cameras_scene(config):
  """The embedded scene with its two training views replaced by one view, twice."""
  scene = load_scene(config)
  i = int(scene.train_idx[0])
  return dataclasses.replace(scene, train_idx=np.array([i, i]))


@pytest.mark.parametrize('sequencing', ['ordered', 'position', 'rotation'])
def test_two_identical_cameras_give_valid_interpolated_poses(sequencing):
  config = tiny_config(n_input_views=2, sequencing=sequencing)
  scene = _identical_cameras_scene(config)
  poses, meta = pseudo_view_poses(config, scene)
  assert poses.shape == (6, 3, 4) and len(meta) == 6 and _all_finite(poses)
  cam = scene.poses[scene.train_idx[0]]
  np.testing.assert_allclose(poses, np.broadcast_to(cam, poses.shape), atol=1e-6)
  rot = poses[:, :, :3].astype(np.float64)
  np.testing.assert_allclose(rot @ np.swapaxes(rot, 1, 2), np.broadcast_to(np.eye(3), rot.shape),
                             atol=1e-5)
  np.testing.assert_allclose(np.linalg.det(rot), 1., atol=1e-5)


def test_two_identical_cameras_train_finite_through_a_round():
  # Depth TV stays on: its random poses come from the degenerate (one-point) camera box.
  config = tiny_config(n_input_views=2, num_rounds=1, max_steps=8, pseudo_until_frac=1.,
                       eval_every=4, lpips_nets=())
  scene = _identical_cameras_scene(config)
  poses = pools.regularizer_poses(config, scene)
  assert _all_finite(poses)
  np.testing.assert_allclose(np.linalg.det(np.asarray(poses[:, :, :3], np.float64)), 1.,
                             atol=1e-5)
  # Round 1 only (a freshly initialised model stands in for the baseline B): pseudo-views
  # rendered at the interpolated poses, then D trained on real + pseudo rays.
  base = renerf.RoundState(params=init_field_params(config, jax.random.PRNGKey(0)),
                           pseudo=None, round_index=0)
  state = renerf.round_step(config, scene, base)
  assert state.round_index == 1
  log = state.curves[-1]
  assert len(log) == 2 and all(r['pseudo_rays'] > 0 and np.isfinite(r['loss']) for r in log)
  m = state.metrics[-1]
  assert np.isfinite(m['psnr']) and m['nan_skips'] == 0
  assert state.pseudo.images.shape[0] == 6 and _all_finite(state.pseudo.images)
  assert _all_finite(state.params)
