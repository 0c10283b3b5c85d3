"""Tests for renerf_jax.nerf.fields.grid (multi-resolution grid field)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from renerf_jax import metrics
from renerf_jax.nerf import mip, training
from renerf_jax.configs import Config
from renerf_jax.datasets import load_scene, ray_pool
from renerf_jax.nerf.fields import init_field_params, make_field
from renerf_jax.nerf.fields import grid
from renerf_jax.nerf.fields.grid import GridField
from renerf_jax.nerf.model import render_rays

# A small grid: resolutions (4, 8, 16, 32); with 2^12 entries the first two levels are
# dense (125, 729 vertices) and the last two hashed (4913, 35937 > 4096).
SMALL = dict(num_levels=4, base_res=4, max_res=32, num_features=2, log2_hashmap_size=12,
             mlp_width=16)


def _init(field, key=0):
  means = jnp.zeros((1, 2, 3))
  return jax.jit(field.init)(jax.random.PRNGKey(key), means, jnp.full_like(means, 1e-4),
                             jnp.array([[0., 0., -1.]]))


def _encoder(field):
  """Jitted (params, means, covs[, feature_mask]) -> field.encode(...) (jit: eager flax
  dispatch compiles every op separately, which is slow)."""
  return jax.jit(lambda p, *args: field.apply(p, *args, method=GridField.encode))


def _with_table(params, table):
  return {'params': {**params['params'], 'table': jnp.asarray(table, jnp.float32)}}


def _vertices(res):
  """Integer vertices of a dense level in table order: [(res + 1)^3, 3] (x fastest)."""
  n = res + 1
  z, y, x = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing='ij')
  return np.stack([x.ravel(), y.ravel(), z.ravel()], -1)


def _np_hash(v, log2_size):
  """Reference spatial hash with Python integers."""
  p = grid.HASH_PRIMES
  return ((int(v[0]) * p[0]) ^ (int(v[1]) * p[1]) ^ (int(v[2]) * p[2])) & (2**log2_size - 1)


# ------------------------------------------------------------------ layout and hashing


def test_layout_of_default_config():
  c = Config()
  lay = grid.grid_layout(c.grid_levels, c.grid_base_res, c.grid_max_res,
                         c.grid_log2_hashmap_size)
  assert lay.resolutions == (16, 22, 30, 41, 56, 77, 106, 145, 199, 273, 374, 512)
  # (41 + 1)^3 = 74088 <= 2^17 = 131072 < (56 + 1)^3 = 185193.
  assert lay.hashed == (False,) * 4 + (True,) * 8
  assert lay.sizes[:4] == (17**3, 23**3, 31**3, 42**3)
  assert lay.sizes[4:] == (2**17,) * 8
  assert lay.offsets == tuple(int(o) for o in np.cumsum((0,) + lay.sizes[:-1]))
  assert lay.total == sum(lay.sizes)
  assert lay.num_dense == 4


@pytest.mark.parametrize('levels,base,top,log2', [(4, 4, 32, 12), (8, 16, 2048, 19),
                                                  (1, 8, 8, 6), (5, 2, 200, 10)])
def test_dense_or_hashed_follows_sizes(levels, base, top, log2):
  lay = grid.grid_layout(levels, base, top, log2)
  assert lay.resolutions[0] == base and lay.resolutions[-1] == top
  assert all(a <= b for a, b in zip(lay.resolutions, lay.resolutions[1:]))
  for res, hashed, size in zip(lay.resolutions, lay.hashed, lay.sizes):
    assert hashed == ((res + 1)**3 > 2**log2)
    assert size == (2**log2 if hashed else (res + 1)**3)


def test_hash_in_range_and_matches_reference():
  rng = np.random.default_rng(0)
  corners = rng.integers(0, 100_000, size=(2000, 3)).astype(np.int32)
  corners[:3] = [[0, 0, 0], [99_999, 99_999, 99_999], [512, 0, 513]]
  for log2 in (5, 12, 19):
    h = np.asarray(grid.hash_index(jnp.asarray(corners), log2))
    assert h.dtype == np.int32
    assert h.min() >= 0 and h.max() < 2**log2
    np.testing.assert_array_equal(h, [_np_hash(v, log2) for v in corners])
  # The hash spreads the vertices of a 16^3 block over a 2^12 table.
  block = jnp.asarray(_vertices(15), jnp.int32)
  assert len(np.unique(np.asarray(grid.hash_index(block, 12)))) > 0.5 * 2**12


def test_rows_stay_inside_their_level():
  lay = grid.grid_layout(**{k: SMALL[k] for k in ('num_levels', 'base_res', 'max_res',
                                                  'log2_hashmap_size')})
  x = jax.random.uniform(jax.random.PRNGKey(0), (500, 3))
  x = x.at[:8].set(jnp.asarray(grid.CORNERS, jnp.float32))  # The box's corners too.
  rows, weights = grid.grid_indices(x, lay, SMALL['log2_hashmap_size'])
  assert rows.shape == (500, 4, 8) and weights.shape == (500, 4, 8)
  rows = np.asarray(rows)
  for l, (off, size) in enumerate(zip(lay.offsets, lay.sizes)):
    assert rows[:, l].min() >= off and rows[:, l].max() < off + size
  np.testing.assert_allclose(np.asarray(weights).sum(-1), 1., atol=1e-5)
  assert np.asarray(weights).min() >= 0.


# ------------------------------------------------------------------ interpolation


def test_trilinear_reproduces_linear_function_on_dense_levels():
  field = GridField(num_levels=3, base_res=3, max_res=12, num_features=2,
                    log2_hashmap_size=12, mlp_width=8)
  lay = field.layout
  assert not any(lay.hashed)
  a = np.array([[0.7, -1.3, 2.1], [-0.4, 0.9, 0.25]])  # [F, 3]
  b = np.array([0.3, -0.8])
  table = np.zeros((lay.total, 2))
  for off, res in zip(lay.offsets, lay.resolutions):
    u = _vertices(res) / res  # Vertex positions in [0, 1]^3.
    table[off:off + (res + 1)**3] = u @ a.T + b
  params = _with_table(_init(field), table)
  means = jax.random.uniform(jax.random.PRNGKey(3), (64, 3), minval=-1., maxval=1.)
  feats = _encoder(field)(params, means, jnp.zeros_like(means))
  feats = np.asarray(feats).reshape(64, 3, 2)
  expected = (np.asarray(means) + 1.) / 2. @ a.T + b  # [64, F]
  for l in range(3):
    np.testing.assert_allclose(feats[:, l], expected, atol=1e-5)


def test_points_outside_the_box_are_clamped():
  field = GridField(**SMALL, bbox_lo=(0., 0., 0.), bbox_hi=(2., 4., 1.))
  params = _init(field)
  params = _with_table(params, jax.random.normal(jax.random.PRNGKey(1),
                                                 params['params']['table'].shape))
  inside = jnp.array([[2., 0., 0.5], [1., 4., 0.]])
  outside = jnp.array([[5., -3., 0.5], [1., 9., -2.]])
  encoder = _encoder(field)
  enc = lambda m: encoder(params, m, jnp.zeros_like(m))
  np.testing.assert_allclose(enc(outside), enc(inside), atol=1e-6)
  assert not np.allclose(enc(inside)[0], enc(inside)[1])


def test_gradient_reaches_only_the_8_corners_of_a_point():
  field = GridField(**SMALL)
  lay = field.layout
  params = _init(field)
  point = np.array([0.3137, -0.5521, 0.7093])  # In [-1, 1]^3, off any vertex.

  def enc_sum(table):
    feats = field.apply(_with_table(params, table), jnp.asarray(point)[None],
                        jnp.zeros((1, 3)), method=GridField.encode)
    return jnp.sum(feats.reshape(4, 2)[:, 0])

  g = np.asarray(jax.jit(jax.grad(enc_sum))(params['params']['table']))
  assert np.all(g[:, 1] == 0.)  # Feature 1 is untouched by a loss on feature 0.
  u = (point + 1.) / 2.
  expected = np.zeros(lay.total)
  for l, (res, hashed, off) in enumerate(zip(lay.resolutions, lay.hashed, lay.offsets)):
    cell = np.floor(u * res).astype(int)
    frac = u * res - cell
    for bits in grid.CORNERS:
      v = cell + bits
      w = np.prod(np.where(bits == 1, frac, 1. - frac))
      row = _np_hash(v, SMALL['log2_hashmap_size']) if hashed else (
          v[0] + (res + 1) * (v[1] + (res + 1) * v[2]))
      expected[off + row] += w
  assert np.count_nonzero(g[:, 0]) == np.count_nonzero(expected) == 4 * 8
  np.testing.assert_allclose(g[:, 0], expected, atol=1e-6)


# ------------------------------------------------------------------ the field


def test_field_shapes_and_finiteness():
  field = GridField(**SMALL, antialias=True)
  params = _init(field)
  key = jax.random.PRNGKey(2)
  means = 3. * jax.random.normal(key, (2, 5, 7, 3))  # Many points outside the box.
  covs = jnp.exp(jax.random.uniform(key, (2, 5, 7, 3), minval=-25., maxval=5.))
  viewdirs = jax.random.normal(key, (2, 5, 3))
  viewdirs = viewdirs / jnp.linalg.norm(viewdirs, axis=-1, keepdims=True)
  raw_rgb, raw_density = jax.jit(field.apply)(params, means, covs, viewdirs,
                                              jnp.array([1., 1., .5, 0.]))
  assert raw_rgb.shape == (2, 5, 7, 3) and raw_density.shape == (2, 5, 7)
  assert np.all(np.isfinite(raw_rgb)) and np.all(np.isfinite(raw_density))
  grads = jax.jit(jax.grad(
      lambda p: jnp.sum(field.apply(p, means, covs, viewdirs)[0]**2)))(params)
  assert all(np.all(np.isfinite(g)) for g in jax.tree_util.tree_leaves(grads))


def test_table_initialised_uniform_in_init_scale():
  field = GridField(**SMALL, init_scale=0.25)
  table = np.asarray(_init(field)['params']['table'])
  assert table.shape == (field.layout.total, 2)
  assert np.abs(table).max() <= 0.25 and np.abs(table).max() > 0.24
  assert abs(table.mean()) < 0.01 and abs(table.std() - 0.25 / np.sqrt(3.)) < 0.01


def test_feature_mask_switches_levels_off():
  field = GridField(**SMALL)
  params = _init(field)
  params = _with_table(params, jnp.ones_like(params['params']['table']))
  means = jax.random.uniform(jax.random.PRNGKey(0), (10, 3), minval=-1., maxval=1.)
  mask = mip.freq_band_mask(4, 0.3)  # Levels (1, 1, 0.2, 0).
  feats = _encoder(field)(params, means, jnp.zeros_like(means), mask)
  np.testing.assert_allclose(np.asarray(feats).reshape(10, 4, 2),
                             np.broadcast_to(np.repeat(mask, 2).reshape(4, 2), (10, 4, 2)),
                             atol=1e-6)
  with pytest.raises(ValueError, match='per-level feature_mask'):
    _encoder(field)(params, means, jnp.zeros_like(means), jnp.ones(96))


def test_antialias_weights_fall_with_resolution_and_size():
  res = (4, 16, 64, 256)
  tiny = grid.antialias_weights(jnp.full((3,), 1e-12), res, (-1.,) * 3, (1.,) * 3)
  np.testing.assert_allclose(tiny, 1., atol=1e-6)
  # std 1/64 of the box (in [0, 1] units): res 64 -> erf(1 / sqrt(8)) ~ 0.383.
  w = np.asarray(grid.antialias_weights(jnp.full((3,), (2. / 64.)**2), res,
                                        (-1.,) * 3, (1.,) * 3))
  assert np.all(np.diff(w) < 0.)
  np.testing.assert_allclose(w[2], 0.3829, atol=1e-3)
  assert w[0] > 0.99 and w[-1] < 0.1


def test_viewdirs_switch():
  means = jax.random.uniform(jax.random.PRNGKey(0), (1, 4, 3), minval=-1., maxval=1.)
  covs = jnp.full_like(means, 1e-4)
  d1, d2 = jnp.array([[0., 0., -1.]]), jnp.array([[0.6, 0., -0.8]])
  for use in (True, False):
    field = GridField(**SMALL, use_viewdirs=use)
    params = _init(field)
    apply = jax.jit(field.apply)
    rgb1, sig1 = apply(params, means, covs, d1)
    rgb2, sig2 = apply(params, means, covs, d2)
    np.testing.assert_array_equal(sig1, sig2)
    assert np.allclose(rgb1, rgb2) != use


def test_make_field_reads_the_config():
  c = Config(field='grid', grid_levels=6, grid_base_res=8, grid_max_res=64,
             grid_features=4, grid_log2_hashmap_size=14, grid_mlp_width=32,
             grid_init_scale=1e-3, deg_view=3, use_viewdirs=False)
  f = make_field(c)
  assert isinstance(f, GridField)
  assert (f.num_levels, f.base_res, f.max_res, f.num_features, f.log2_hashmap_size,
          f.mlp_width, f.init_scale, f.deg_view, f.use_viewdirs) == (
              6, 8, 64, 4, 14, 32, 1e-3, 3, False)
  params = jax.jit(lambda k: init_field_params(c, k))(jax.random.PRNGKey(0))
  assert params['params']['table'].shape == (f.layout.total, 4)


# ------------------------------------------------------------------ end to end

# Small, fast settings shared by the end-to-end tests.
E2E = dict(field='grid', dataset_loader='procedural', grid_levels=8, grid_base_res=8,
           grid_max_res=128, grid_log2_hashmap_size=15, grid_mlp_width=32,
           depth_tv_loss_mult=0., anneal_nearfar=False, num_samples=32)


@pytest.fixture(scope='module')
def scene():
  return load_scene(Config(**E2E))


def test_render_rays_with_grid_field(scene):
  config = Config(**E2E, num_levels=2)
  pool = ray_pool(scene, scene.train_idx[:1])
  rays = jax.tree_util.tree_map(lambda x: x[::97], pool['rays'])  # 32 rays.
  params = jax.jit(lambda k: init_field_params(config, k))(jax.random.PRNGKey(0))
  for train in (True, False):
    render = jax.jit(lambda p, r, k: render_rays(config, p, r, k, train=train))
    levels = render(params, rays, jax.random.PRNGKey(1))
    assert len(levels) == 2
    for out in levels:
      assert out['rgb'].shape == (32, 3) and out['weights'].shape == (32, 32)
      for k in ('rgb', 'distance', 'acc', 'weights'):
        assert np.all(np.isfinite(out[k])), k
      assert np.all(out['acc'] >= 0.) and np.all(out['acc'] <= 1. + 1e-5)


def test_training_fits_the_procedural_scene(scene):
  """A few hundred steps of train_step must beat the best constant colour by far.

  The best constant (the mean colour of the training views) gives ~13 dB on this scene;
  a model that learned nothing but the mean stays there. 20 dB is an MSE 5x below the
  colour variance of the views: it needs the grid to have learnt the textured
  geometry (this setup reaches ~26 dB in 250 steps).
  """
  steps = 250
  config = Config(**E2E, num_levels=1, batch_size=256, max_steps=steps, lr_init=1e-2,
                  lr_final=1e-3, lr_delay_steps=0)
  pools = {'real': ray_pool(scene, scene.train_idx)}
  gt = pools['real']['rgb']
  mean_psnr = float(metrics.mse_to_psnr(jnp.mean((gt - gt.mean(0))**2)))
  assert 11. < mean_psnr < 15.
  cam = training.Camera.of(scene)
  params = jax.jit(lambda k: init_field_params(config, k))(jax.random.PRNGKey(0))
  state = training.init_state(config, None, params)
  mses = []
  for step in range(steps):
    state, stats = training.train_step(config, cam, False, state, pools,
                                       jax.random.PRNGKey(step))
    if step >= steps - 25:
      mses.append(float(stats['mse']))
  assert int(state.nan_skips) == 0
  psnr = float(metrics.mse_to_psnr(np.mean(mses)))
  assert psnr > max(20., mean_psnr + 6.), (psnr, mean_psnr)
