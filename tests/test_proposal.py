"""The proposal sampler (fields/proposal.py): its histogram bound, its loss, its coverage."""
import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from dense_reference import reference_hessian_diagonals

from renerf_jax import cameras
from renerf_jax.nerf import model, training
from renerf_jax.configs import Config
from renerf_jax.datasets import load_scene
from renerf_jax.datasets.scene import ray_pool
from renerf_jax.errors import ConfigError
from renerf_jax.nerf.fields import init_field_params
from renerf_jax.nerf.fields.proposal import interlevel_loss, outer_weights
from renerf_jax.uncertainty import laplace


def _brute_outer(t, t_env, w_env):
  """Sum of w_env over the env intervals that overlap each [t_i, t_i+1]: an env interval
  that starts at t_i+1 counts, one that ends at t_i does not (mip-NeRF 360's ties)."""
  out = np.zeros(len(t) - 1)
  for i in range(len(t) - 1):
    for j in range(len(w_env)):
      if t_env[j] <= t[i + 1] and t_env[j + 1] > t[i]:
        out[i] += w_env[j]
  return out


def _histogram(rng, n):
  t = np.sort(rng.uniform(0., 1., n + 1))
  return t, rng.uniform(0., 1., n) * (rng.uniform(size=n) < 0.6)


def test_outer_weights_sum_the_overlapping_intervals():
  rng = np.random.default_rng(0)
  for n, m in [(8, 5), (5, 16), (12, 12)]:
    for _ in range(5):
      t, _ = _histogram(rng, n)
      t_env, w_env = _histogram(rng, m)
      got = np.asarray(outer_weights(jnp.asarray(t), jnp.asarray(t_env),
                                     jnp.asarray(w_env)))
      np.testing.assert_allclose(got, _brute_outer(t, t_env, w_env), atol=1e-6)
  # Shared edges, and intervals before, across and beyond the env's range.
  t_env, w_env = np.array([0., .5, 1.]), np.array([.3, .6])
  for t in (np.array([0., .25, .5, .75, 1.]), np.array([-1., -.5, .2, 1.5, 2.])):
    got = np.asarray(outer_weights(jnp.asarray(t), jnp.asarray(t_env), jnp.asarray(w_env)))
    np.testing.assert_allclose(got, _brute_outer(t, t_env, w_env), atol=1e-7)
  np.testing.assert_allclose(
      np.asarray(outer_weights(jnp.array([-1., -.5, .2, 1.5, 2.]), jnp.asarray(t_env),
                               jnp.asarray(w_env))), [0., .3, .9, 0.], atol=1e-7)


def test_outer_weights_of_a_histogram_bound_itself():
  rng = np.random.default_rng(1)
  t, w = _histogram(rng, 20)
  outer = np.asarray(outer_weights(jnp.asarray(t), jnp.asarray(t), jnp.asarray(w)))
  # Interval i of the same edges overlaps itself and touches the start of i + 1.
  np.testing.assert_allclose(outer, w + np.append(w[1:], 0.), atol=1e-6)
  assert float(interlevel_loss(jnp.asarray(t), jnp.asarray(w), jnp.asarray(t),
                               jnp.asarray(w))) < 1e-10


def test_interlevel_loss_penalises_missing_mass_and_trains_only_the_proposal():
  t = jnp.linspace(0., 1., 9)
  w = jnp.zeros(8).at[4].set(0.9)  # The scene field's surface in [0.5, 0.625].
  t_env = jnp.linspace(0., 1., 5)
  flat = jnp.full(4, 0.2)  # Puts only 0.2 on the interval holding the surface.
  loss, (g_w, g_env) = jax.value_and_grad(interlevel_loss, argnums=(1, 3))(t, w, t_env,
                                                                           flat)
  np.testing.assert_allclose(float(loss), (0.9 - 0.2)**2 / (0.9 + 1e-7), rtol=1e-5)
  assert np.all(np.asarray(g_w) == 0.)  # The scene field's weights are constants.
  assert float(g_env[2]) < 0. and np.all(np.asarray(g_env)[[0, 1, 3]] == 0.)
  peaked = flat.at[2].set(0.95)
  assert float(interlevel_loss(t, w, t_env, peaked)) < 1e-10


def test_interlevel_loss_on_extreme_histograms():
  t = jnp.array([0., 0.5, 0.5, 0.5, 1.])  # Zero-length intervals.
  zeros = jnp.zeros(4)
  for w, w_env in [(zeros, zeros), (jnp.array([0., 1., 0., 0.]), zeros),
                   (zeros, jnp.array([0., 1e30, 0., 0.]))]:
    loss, grad = jax.value_and_grad(interlevel_loss, argnums=3)(t, w, t, w_env)
    assert np.isfinite(float(loss)) and np.all(np.isfinite(np.asarray(grad)))
  # Repeated edges never give negative outer weights.
  outer = np.asarray(outer_weights(t, t, jnp.array([1., 1e30, 1e30, 1.])))
  assert np.all(outer >= 0.)


def test_sampler_is_validated():
  with pytest.raises(ConfigError, match='Config.sampler'):
    Config(sampler='nerfacto')
  with pytest.raises(ConfigError, match='num_levels = 2'):
    Config(sampler='proposal', num_levels=3)
  with pytest.raises(ConfigError, match='stop_level_grad'):
    Config(sampler='proposal', stop_level_grad=False)
  with pytest.raises(ConfigError, match='proposal_samples'):
    Config(sampler='proposal', proposal_samples=1)


def test_level_samples_and_labels():
  base = Config(num_samples=48)
  assert model.level_samples(base) == (48, 48) and model.samples_label(base) == '2x48'
  assert model.colour_levels(base) == 2
  prop = Config(num_samples=48, sampler='proposal', proposal_samples=64)
  assert model.level_samples(prop) == (64, 48) and model.samples_label(prop) == '64p+48'
  assert model.colour_levels(prop) == 1


def test_default_sampler_keeps_the_field_parameters():
  """Without the proposal the parameters are the field's own init from the same key."""
  from renerf_jax.nerf.fields import make_field  # pylint: disable=g-import-not-at-top
  config = Config(field='grid', grid_levels=4, grid_max_res=32, grid_log2_hashmap_size=12)
  key = jax.random.PRNGKey(3)
  means = jnp.zeros((1, 2, 3))
  ref = make_field(config).init(key, means, jnp.ones_like(means) * 1e-2,
                                jnp.zeros((1, 3)).at[:, 2].set(-1.))
  got = init_field_params(config, key)
  assert set(got) == {'params'}
  for a, b in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(ref)):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
  prop = init_field_params(dataclasses.replace(config, sampler='proposal'), key)
  assert set(prop) == {'params', 'proposal'} and 'table' in prop['proposal']


# ------------------------------------------------------ coverage on the procedural scene

COVER = dict(field='grid', dataset_loader='procedural', grid_levels=8, grid_base_res=8,
             grid_max_res=128, grid_log2_hashmap_size=15, grid_mlp_width=32,
             depth_tv_loss_mult=0., anneal_nearfar=False, sampler='proposal',
             num_levels=2, num_samples=8, proposal_samples=64, proposal_levels=4,
             proposal_max_res=64, n_input_views=14, batch_size=512, lr_init=1e-2, lr_final=1e-3,
             lr_delay_steps=0, density_activation='exp', grad_max_norm=0.,
             grad_max_val=0., adam_eps=1e-15)


def exact_ndc_t(scene, view):
  """NDC ray parameter of the exact surface (the scene's z-depth) of every pixel."""
  h, w = scene.height, scene.width
  pix_y, pix_x = np.meshgrid(np.arange(h, dtype=np.float32),
                             np.arange(w, dtype=np.float32), indexing='ij')
  c2w = jnp.asarray(scene.poses[view])
  dirs = jnp.einsum('ij,...j->...i', c2w[:3, :3],
                    cameras.pixel_directions(pix_x, pix_y, scene.focal, h, w))
  origins = jnp.broadcast_to(c2w[:3, 3], dirs.shape)
  points = origins + jnp.asarray(scene.depths[view])[..., None] * dirs
  o_ndc, d_ndc = cameras.convert_to_ndc(origins, dirs, scene.focal, h, w)
  z_ndc = 1. + 2. / points[..., 2]
  return np.asarray((z_ndc - o_ndc[..., 2]) / d_ndc[..., 2]).reshape(-1)


@pytest.fixture(scope='module')
def trained():
  """A proposal-sampler model trained on the procedural scene's training views."""
  steps = 800
  config = Config(**COVER, max_steps=steps)
  scene = load_scene(config)
  pools = {'real': ray_pool(scene, scene.train_idx)}
  cam = training.Camera.of(scene)
  params = jax.jit(lambda k: init_field_params(config, k))(jax.random.PRNGKey(0))
  state = training.init_state(config, None, params)
  for step in range(steps):
    state, stats = training.train_step(config, cam, False, state, pools,
                                       jax.random.PRNGKey(step))
  assert int(state.nan_skips) == 0 and 'interlevel' in stats
  return config, scene, state.params


def test_proposal_samples_cover_the_surface_the_dense_sampler_finds(trained):
  """The 8 fine samples a ray gets from the proposal land on the exact surface.

  A dense sampler (512 uniform samples of the same scene field, no proposal) finds the
  surface near the exact depth; on the rays where it does, the fine samples the
  proposal places must have one within `tol` of that depth. 8 uniform samples cannot:
  their spacing is 1/8, so only about 2 tol / (1/8) of the rays have one that close.
  """
  config, scene, params = trained
  view = int(scene.train_idx[0])
  rays = ray_pool(scene, [view])['rays']
  t_exact = exact_ndc_t(scene, view)
  dense = Config(**dict(COVER, sampler='coarse_fine', num_levels=1, num_samples=512))
  dense_depth = np.asarray(jax.jit(lambda p, r: model.render_rays(
      dense, p, r, jax.random.PRNGKey(0), train=False)[-1]['distance'])(
          {'params': params['params']}, rays))
  tol = 0.02
  found = np.abs(dense_depth - t_exact) < tol
  assert found.mean() > 0.5, found.mean()  # The field has learnt the geometry.
  levels = jax.jit(lambda p, r: model.render_rays(config, p, r, jax.random.PRNGKey(0),
                                                  train=False))(params, rays)
  assert 'rgb' not in levels[0] and levels[0]['weights'].shape[-1] == 64
  t_fine = np.asarray(levels[-1]['t_vals'])
  mids = 0.5 * (t_fine[:, 1:] + t_fine[:, :-1])
  near_surface = np.min(np.abs(mids - t_exact[:, None]), axis=-1) < tol
  covered = near_surface[found].mean()
  uniform = np.linspace(0., 1., 9)
  uniform_mids = 0.5 * (uniform[1:] + uniform[:-1])
  uniform_cover = (np.min(np.abs(uniform_mids - t_exact[:, None]), -1) < tol)[found].mean()
  assert covered > 0.95 and uniform_cover < 0.5, (covered, uniform_cover)
  # And the fine level's depth is the dense sampler's.
  fine_depth = np.asarray(levels[-1]['distance'])
  assert np.mean(np.abs(fine_depth - dense_depth)[found] < tol) > 0.9


def test_proposal_params_train_and_laplace_sees_only_the_fine_level(trained):
  """The proposal table moved away from its init; the Hessian pass over the fine level
  alone (the one colour level) equals the dense forward-mode reference."""
  config, scene, params = trained
  init = init_field_params(config, jax.random.PRNGKey(0))
  moved = np.abs(np.asarray(params['proposal']['table'])
                 - np.asarray(init['proposal']['table'])).max()
  assert moved > 1e-2
  # 64 rays: on the 3^3 grid they see 30-40 of the 81 entries whatever the CPU (16 rays
  # saw 9-13 depending on the trained model, which differs with XLA's instruction set
  # and thread count).
  rays = jax.tree_util.tree_map(lambda x: x[::48], ray_pool(scene, [0])['rays'])
  sens, means = laplace.sample_sensitivities(config, params, rays,
                                             jnp.ones(rays.origins.shape[0]))
  assert sens.shape == (3, 1, rays.origins.shape[0], 8, 3) and means.shape[0] == 1
  lam = 1e-4
  h = np.asarray(laplace.hessian_diagonal(config, params, rays, -1., 1., 1, lam, chunk=8))
  ref = np.asarray(reference_hessian_diagonals(config, params, rays, -1., 1., 1)['gn'])
  assert np.sum(ref > 1e-2 * ref.max()) > 20  # Many vertices seen: a non-trivial check.
  np.testing.assert_allclose(h, ref + 2. * lam, rtol=1e-3, atol=1e-5 * ref.max())


def test_clipping_leaves_the_proposal_out_of_the_scene_fields_norm():
  """A huge proposal gradient must not shrink the scene field's clipped step (Adam's
  eps would turn that shrinkage into a near-zero update)."""
  config = Config(sampler='proposal', grad_max_norm=0.1, grad_max_val=0.,
                  lr_delay_steps=0)
  opt = training.make_optimizer(config)
  params = {'params': {'a': jnp.ones(3)}, 'proposal': {'b': jnp.ones(2)}}
  field_step = lambda g_prop: np.asarray(opt.update(
      {'params': {'a': jnp.ones(3)}, 'proposal': {'b': jnp.full(2, g_prop)}},
      opt.init(params), params)[0]['params']['a'])
  np.testing.assert_allclose(field_step(1e12), field_step(0.), rtol=1e-6)
  assert np.all(np.abs(field_step(0.)) > 0.5 * config.lr_init)
