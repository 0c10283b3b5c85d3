"""Tests for renerf_jax.uncertainty.signals."""
import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest
from tiny_scene import LAM, take, tiny_setup

from renerf_jax.uncertainty import laplace
from renerf_jax.uncertainty import masks as unc
from renerf_jax.uncertainty import signals as us
from renerf_jax.uncertainty.deformation import grid_size, trilinear


@pytest.fixture(scope='module')
def setup():
  config, params, pool = tiny_setup()
  config = dataclasses.replace(config, deform_log2_res=1, hessian_rays=24,
                               hessian_lambda=LAM, hessian_chunk=8, render_chunk=64)
  return config, params, pool


S = 8
EXTREMES = {  # weights [S], acc
    'zero': (np.zeros(S), 0.),
    'one_hot_first': (np.eye(S)[0], 1.),
    'one_hot_last': (np.eye(S)[-1], 1.),
    'half': (np.full(S, 0.5 / S), 0.5),
    'tiny': (np.full(S, 1e-30), 8e-30),
    'over_one': (np.full(S, 1.01 / S), 1.01),
}


def _batch():
  w = jnp.asarray(np.stack([v[0] for v in EXTREMES.values()]), jnp.float32)
  acc = jnp.asarray([v[1] for v in EXTREMES.values()], jnp.float32)
  t_vals = jnp.broadcast_to(jnp.linspace(0., 1., S + 1), (w.shape[0], S + 1))
  return w, acc, t_vals


def test_hessian_free_signals_on_extreme_weights():
  w, acc, t_vals = _batch()
  ent, var, oma = us.weight_entropy(w), us.depth_variance(w, t_vals), us.one_minus_acc(acc)
  for x in (ent, var, oma):
    assert x.shape == (len(EXTREMES),) and bool(jnp.all(jnp.isfinite(x)))
    assert bool(jnp.all(x >= 0.))
  names = list(EXTREMES)
  i0, i1, il = names.index('zero'), names.index('one_hot_first'), names.index('one_hot_last')
  np.testing.assert_allclose(ent[i1], 0., atol=1e-7)
  np.testing.assert_allclose(ent[il], 0., atol=1e-7)
  np.testing.assert_allclose(ent[i0], np.log(S), rtol=1e-6)  # all-zero: uniform
  np.testing.assert_allclose(ent[names.index('half')], np.log(S), rtol=1e-6)
  np.testing.assert_allclose(var[i1], 0., atol=1e-7)
  np.testing.assert_allclose(var[il], 0., atol=1e-7)
  mids = (np.arange(S) + 0.5) / S
  np.testing.assert_allclose(var[i0], np.var(mids), rtol=1e-5)
  np.testing.assert_allclose(oma, [1., 0., 0., 0.5, 1., 0.], atol=1e-6)
  # One sample holding all the weight.
  assert float(us.weight_entropy(jnp.ones((1, 1)))[0]) == 0.
  assert float(us.depth_variance(jnp.ones((1, 1)), jnp.array([[0., 1.]]))[0]) == 0.


def test_bayes_rays_rendering_bounds():
  assert float(us.bayes_rays_normalise(us.BR_LOG10_MIN)) == 0.
  assert float(us.bayes_rays_normalise(us.BR_LOG10_MAX)) == 1.
  w, acc, _ = _batch()
  for var in (1e-40, 1e-6, 1., 1e20, np.inf):
    u = us.bayes_rays_render(w, acc, jnp.full(w.shape, var, jnp.float32))
    assert bool(jnp.all(jnp.isfinite(u))) and bool(jnp.all(u >= 0.))
    assert bool(jnp.all(u <= 1.))
  one_hot = w[1:2], acc[1:2]
  huge = us.bayes_rays_render(*one_hot, jnp.full((1, S), 1e20))
  tiny = us.bayes_rays_render(*one_hot, jnp.full((1, S), 1e-20))
  np.testing.assert_allclose([huge[0], tiny[0]], [1., 0.], atol=1e-6)
  # Empty space is certain: acc = 0 gives the low end whatever the variance.
  empty = us.bayes_rays_render(jnp.zeros((1, S)), jnp.zeros(1), jnp.full((1, S), 1e20))
  np.testing.assert_allclose(empty, [0.], atol=1e-7)
  # log10 std = 1 everywhere (var = 100) on a fully opaque ray: (1 + 3) / 9.
  mid = us.bayes_rays_render(*one_hot, jnp.full((1, S), 100.))
  np.testing.assert_allclose(mid, [4. / 9.], rtol=1e-6)


def test_squared_weight_interpolation():
  rng = np.random.default_rng(0)
  points = jnp.asarray(rng.uniform(-1.3, 1.3, (50, 3)), jnp.float32)
  const = jnp.full((grid_size(2),), 3.7, jnp.float32)
  np.testing.assert_allclose(us.squared_weight_interp(const, points, -1., 1.), 3.7,
                             rtol=1e-6)
  var = jnp.asarray(rng.uniform(0.1, 5., grid_size(2)), jnp.float32)
  got = us.squared_weight_interp(var, points, -1., 1.)
  assert bool(jnp.all(got >= var.min() - 1e-6)) and bool(jnp.all(got <= var.max() + 1e-6))
  # At a vertex it is the vertex's value (one corner holds all the weight).
  vertex = jnp.array([[-1., -0.5, 0.5]])
  np.testing.assert_allclose(us.squared_weight_interp(var, vertex, -1., 1.),
                             trilinear(var[:, None], vertex, -1., 1.)[..., 0], rtol=1e-6)


def test_tables_reuse_laplace(setup):
  config, params, pool = setup
  tables, info = us.hessian_tables(config, params, pool['rays'], -1., 1.)
  assert info['hessian_rays'] == {'subsample': 24, 'all_rays': pool['rays'].origins.shape[0]}
  assert info['hessian_seconds']['all_rays'] > 0.
  sub = laplace.subsample_rays(pool['rays'], 24, config.seed)
  sigma, _ = laplace.vertex_sigma_pass(config, params, sub, -1., 1., 8)
  np.testing.assert_array_equal(tables.sigmas['laplace'], sigma)
  h = laplace.hessian_diagonal(config, params, pool['rays'], -1., 1., 1, LAM, chunk=8)
  jtj_sum = np.sum((np.asarray(h, np.float64) - 2. * LAM) / 2., axis=-1)
  np.testing.assert_allclose(1. / np.asarray(tables.variances['bayes_rays'], np.float64),
                             jtj_sum + 1e-4 / 8., rtol=1e-4)
  assert tables.u_bg == laplace.prior_sigma(LAM)


def test_render_signals_matches_compute_masks(setup):
  config, params, pool = setup
  rays = take(pool['rays'], np.arange(1, 600, 7))  # 86 pixels
  masks = unc.compute_masks(config, params, pool['rays'], rays, -1., 1., hessian_chunk=8)
  tables, _ = us.hessian_tables(config, params, pool['rays'], -1., 1.)
  grid = take(pool['rays'], np.arange(86).reshape(2, 43))  # leading shape [2, 43]
  for r, shape in ((rays, (86,)), (grid, (2, 43))):
    out = us.render_signals(config, params, r, -1., 1., tables)
    for name in us.VARIANTS + ('distance', 'acc'):
      assert out[name].shape == shape and np.all(np.isfinite(out[name])), name
    assert out['rgb'].shape == shape + (3,)
  out = us.render_signals(config, params, rays, -1., 1., tables)
  np.testing.assert_allclose(out['laplace'], masks.uncertainty, rtol=1e-5)
  np.testing.assert_allclose(out['rgb'], masks.rgb, atol=1e-5)
  for name in ('bayes_rays', 'bayes_rays_subsample'):
    assert np.all(out[name] >= 0.) and np.all(out[name] <= 1.)
  assert np.ptp(out['laplace_all_rays']) > 0.
