"""Tests for renerf_jax.uncertainty (deformation grid, Laplace Hessian, masks)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from renerf_jax import memo
from renerf_jax import uncertainty as unc
from renerf_jax.configs import Config
from renerf_jax.datasets import load_scene, ray_pool
from renerf_jax.fields import init_field_params
from renerf_jax.model import render_rays
from renerf_jax.rendering import render_flat

LAM = 1e-4
TINY = Config(dataset_loader='procedural', num_samples=8, net_depth=2, net_width=32,
              net_width_viewdirs=16, max_deg_point=4, deg_view=2, density_noise=0.,
              randomized=False, procedural_size=(12, 16), procedural_views=9)


@pytest.fixture(scope='module')
def setup():
  """Tiny config, random-init params and the flat training ray pool of the toy scene."""
  scene = load_scene(TINY)
  pool = ray_pool(scene, scene.train_idx)
  params = init_field_params(TINY, jax.random.PRNGKey(0))
  return TINY, params, pool


def take(rays, idx):
  return jax.tree_util.tree_map(lambda x: x[np.asarray(idx)], rays)


# ----------------------------------------------------------------- trilinear


def test_trilinear_exact_on_linear_function():
  n = 4
  lo, hi = np.array([-1., 0., 2.], np.float32), np.array([1., 3., 2.5], np.float32)
  rng = np.random.default_rng(0)
  a, b = rng.normal(size=(3, 2)).astype(np.float32), rng.normal(size=2).astype(np.float32)
  g = np.linspace(0., 1., n + 1)
  ii, jj, kk = np.meshgrid(g, g, g, indexing='ij')  # x-major flattening.
  verts = lo + (hi - lo) * np.stack([ii, jj, kk], -1).reshape(-1, 3)
  values = verts @ a + b
  pts = lo + (hi - lo) * rng.uniform(size=(50, 3)).astype(np.float32)
  got = unc.trilinear(jnp.asarray(values), jnp.asarray(pts), lo, hi)
  np.testing.assert_allclose(got, pts @ a + b, atol=1e-5)


def test_trilinear_at_vertices_returns_table_rows():
  n = 2
  values = np.random.default_rng(1).normal(size=((n + 1)**3, 3)).astype(np.float32)
  i, j, k = np.meshgrid(*[np.arange(n + 1)] * 3, indexing='ij')
  ijk = np.stack([i, j, k], -1).reshape(-1, 3)
  pts = -1. + 2. * ijk / n  # Box [-1, 1]^3.
  got = unc.trilinear(jnp.asarray(values), jnp.asarray(pts, jnp.float32), -1., 1.)
  rows = (ijk[:, 0] * (n + 1) + ijk[:, 1]) * (n + 1) + ijk[:, 2]
  np.testing.assert_allclose(got, values[rows], atol=1e-6)


def test_trilinear_clamps_points_outside_the_box():
  values = jnp.asarray(np.random.default_rng(2).normal(size=(27, 2)), jnp.float32)
  pts = jnp.array([[3., 0.2, -0.4], [-5., -7., 0.9], [0.1, 0.5, 40.]])
  got = unc.trilinear(values, pts, -1., 1.)
  np.testing.assert_allclose(got, unc.trilinear(values, jnp.clip(pts, -1., 1.), -1., 1.),
                             atol=1e-6)
  ids, w = unc.trilinear_corners(pts, -1., 1., 2)
  assert np.all(np.asarray(ids) >= 0) and np.all(np.asarray(ids) < 27)
  np.testing.assert_allclose(np.asarray(w).sum(-1), 1., atol=1e-6)


def test_zero_deformation_is_the_identity(setup):
  config, params, pool = setup
  rays = take(pool['rays'], np.arange(0, 400, 25))
  offsets = jnp.zeros((unc.grid_size(2), 3), jnp.float32)
  render = lambda w: jax.jit(lambda r: render_rays(config, params, r, jax.random.PRNGKey(0),
                                                   False, warp=w))(rays)
  plain, warped = render(None), render(unc.make_warp(offsets, -1., 1.))
  for lv_plain, lv_warped in zip(plain, warped):
    for key in lv_plain:
      np.testing.assert_array_equal(lv_plain[key], lv_warped[key], err_msg=key)


# ----------------------------------------------------------------- Hessian


def test_kahan_keeps_small_terms():
  def body(_, carry):
    return unc.kahan_add(carry[0], carry[1], jnp.float32(1e-8))
  total, comp = jax.jit(lambda: jax.lax.fori_loop(
      0, 10000, body, (jnp.float32(1.), jnp.float32(0.))))()
  naive = jax.jit(lambda: jax.lax.fori_loop(0, 10000, lambda _, s: s + jnp.float32(1e-8),
                                            jnp.float32(1.)))()
  assert float(naive) == 1.  # float32 drops every term on its own...
  np.testing.assert_allclose(float(total - comp), 1.0001, rtol=1e-6)  # ... Kahan does not.


HESSIAN_RAYS = [5, 70, 140, 210, 333, 500]  # 6 rays; with chunk 4 one chunk is padded.


def test_hessian_diagonal_matches_jax_hessian(setup):
  config, params, pool = setup
  rays = take(pool['rays'], HESSIAN_RAYS)
  h = np.asarray(unc.hessian_diagonal(config, params, rays, -1., 1., 1, LAM, chunk=4))
  ref = np.asarray(unc.reference_hessian_diagonals(config, params, rays, -1., 1., 1)['gn'])
  assert h.shape == (27, 3)
  assert np.sum(ref > 1e-2 * ref.max()) > 20  # Many vertices seen: a non-trivial check.
  np.testing.assert_allclose(h, ref + 2. * LAM, rtol=1e-4, atol=1e-6 * ref.max())


def test_reference_true_hessian_is_gn_at_zero_residual_only(setup):
  config, params, pool = setup
  rays = take(pool['rays'], HESSIAN_RAYS)
  rgb0 = jnp.stack([lv['rgb'] for lv in jax.jit(
      lambda r: render_rays(config, params, r, jax.random.PRNGKey(0), False))(rays)])
  ref = unc.reference_hessian_diagonals(config, params, rays, -1., 1., 1, gt_rgb=rgb0)
  np.testing.assert_allclose(ref['true'], ref['gn'], rtol=1e-4, atol=1e-6 * ref['gn'].max())
  off = unc.reference_hessian_diagonals(config, params, rays, -1., 1., 1,
                                        gt_rgb=rgb0 + 0.3)['true']
  assert np.max(np.abs(off - ref['gn'])) > 1e-2 * np.max(ref['gn'])


def test_unseen_vertices_get_the_prior(setup):
  config, params, pool = setup
  rays = take(pool['rays'], np.arange(3, 600, 120))
  # NDC samples lie on o + t d, t in [0, 1]; the box reaches x, y = 7 with cells of 4,
  # so the vertices at x = 7 or y = 7 are never a sample's corner.
  ends = np.concatenate([rays.origins, rays.origins + rays.directions])
  assert ends[:, :2].max() < 3.
  lo, hi = np.array([-1., -1., -1.]), np.array([7., 7., 1.])
  h = np.asarray(unc.hessian_diagonal(config, params, rays, lo, hi, 1, LAM, chunk=4))
  ijk = np.stack(np.meshgrid(*[np.arange(3)] * 3, indexing='ij'), -1).reshape(-1, 3)
  unseen = (ijk[:, 0] == 2) | (ijk[:, 1] == 2)
  np.testing.assert_allclose(h[unseen], 2. * LAM, rtol=1e-6)
  np.testing.assert_allclose(1. / h[unseen], 1. / (2. * LAM), rtol=1e-6)  # Sigma per axis.
  assert np.max(h[~unseen]) > 10. * LAM
  sigma = np.asarray(unc.vertex_sigma(jnp.asarray(h)))
  np.testing.assert_allclose(sigma[unseen], unc.prior_sigma(LAM), rtol=1e-6)
  assert np.all(sigma[~unseen] <= unc.prior_sigma(LAM) * (1. + 1e-6))


def test_zero_sensitivity_gives_the_prior_without_nan(setup):
  config, params, pool = setup
  flat = jax.tree_util.tree_map(jnp.zeros_like, params)  # Constant field: dx rgb = 0.
  rays = take(pool['rays'], np.arange(3, 600, 120))
  h = np.asarray(unc.hessian_diagonal(config, flat, rays, -1., 1., 1, LAM, chunk=4))
  assert np.all(np.isfinite(h))
  np.testing.assert_array_equal(h, np.float32(2. * LAM))
  sigma = unc.vertex_sigma(jnp.asarray(h))
  u, rgb = unc.render_uncertainty(config, flat, sigma, rays, -1., 1., chunk=4,
                                  u_bg=unc.prior_sigma(LAM))
  assert u.shape == (5,) and rgb.shape == (5, 3)
  assert np.all(np.isfinite(u))
  np.testing.assert_allclose(u, unc.prior_sigma(LAM), rtol=1e-5)


# ----------------------------------------------------------------- thresholds, masks


def test_masks_follow_the_threshold():
  u = np.random.default_rng(3).lognormal(size=1000).astype(np.float32)
  for mu in np.quantile(u, [0.1, 0.5, 0.9]):
    mask = np.asarray(unc.masks_from_uncertainty(u, mu))
    assert set(np.unique(mask)) <= {0., 1.}
    np.testing.assert_array_equal(mask, (u <= mu).astype(np.float32))


@pytest.mark.parametrize('keep_frac', [0.1, 0.333, 0.5, 0.8, 0.999])
def test_threshold_hits_the_keep_fraction(keep_frac):
  u = np.random.default_rng(4).lognormal(size=997).astype(np.float32)
  mu = unc.threshold_for_keep_fraction(u, keep_frac)
  kept = float(np.mean(np.asarray(unc.masks_from_uncertainty(u, mu))))
  assert keep_frac <= kept <= keep_frac + 1. / u.size


def test_threshold_with_ties_keeps_at_least_the_target():
  u = np.round(np.random.default_rng(5).uniform(size=500), 1).astype(np.float32) + 0.1
  mu = unc.threshold_for_keep_fraction(u, 0.5)
  assert np.mean(u <= mu) >= 0.5
  assert np.mean(u < mu) < 0.5  # mu is the tied value itself, not the next one up.


def test_extreme_thresholds():
  u = np.random.default_rng(6).uniform(0.01, 2., size=300).astype(np.float32)
  assert np.all(np.asarray(unc.masks_from_uncertainty(u, 0.)) == 0.)
  assert np.all(np.asarray(unc.masks_from_uncertainty(u, np.inf)) == 1.)
  mu0, mu1 = unc.threshold_for_keep_fraction(u, 0.), unc.threshold_for_keep_fraction(u, 1.)
  assert np.isfinite(mu0) and np.isfinite(mu1)
  assert np.all(np.asarray(unc.masks_from_uncertainty(u, mu0)) == 0.)
  assert np.all(np.asarray(unc.masks_from_uncertainty(u, mu1)) == 1.)


def test_compute_masks_end_to_end(setup):
  config, params, pool = setup
  config = dataclasses.replace(config, deform_log2_res=1, hessian_rays=24,
                               hessian_lambda=LAM, mask_keep_frac=0.5, render_chunk=64)
  pseudo = take(pool['rays'], np.arange(1, 600, 7))  # 86 pixels.
  res = unc.compute_masks(config, params, pool['rays'], pseudo, -1., 1., hessian_chunk=8)
  u, mask, mu = res.uncertainty, res.mask, res.mu
  assert u.shape == mask.shape == (86,)
  assert np.all(np.isfinite(u)) and np.all(u > 0.) and np.all(u <= unc.prior_sigma(LAM))
  assert 0.5 <= mask.mean() <= 0.5 + 1. / 86
  np.testing.assert_array_equal(mask, (u <= mu).astype(np.float32))
  assert np.ptp(u) > 0.  # Pixels differ in uncertainty.
  # The colours of the same pass are the plain renderer's: masked pseudo-views need one
  # render, not two.
  plain = render_flat(config, params, pseudo, chunk=32)['rgb']
  assert res.rgb.shape == (86, 3) and res.hessian_seconds > 0.
  np.testing.assert_allclose(res.rgb, plain, atol=1e-5)


def test_hessian_pass_is_shared_only_when_nothing_it_depends_on_differs(setup, monkeypatch):
  config, params, pool = setup
  config = dataclasses.replace(config, deform_log2_res=1, hessian_rays=24,
                               hessian_lambda=LAM, mask_keep_frac=0.5, render_chunk=64)
  calls = []
  real = unc.hessian_diagonal
  monkeypatch.setattr(unc, 'hessian_diagonal', lambda *a, **k: calls.append(1) or real(*a, **k))
  monkeypatch.setattr(unc, '_HESSIAN_CACHE', memo.LruCache(max_items=unc.HESSIAN_CACHE_SIZE))
  pseudo = take(pool['rays'], np.arange(1, 600, 7))
  first = unc.compute_masks(config, params, pool['rays'], pseudo, -1., 1., hessian_chunk=8)
  # Another view-selection variant of the same baseline: other pseudo-views and keep
  # fraction, same Hessian.
  other = dataclasses.replace(config, interp_factors='2x', mask_keep_frac=0.7)
  second = unc.compute_masks(other, params, pool['rays'], take(pool['rays'], np.arange(50)),
                             -1., 1., hessian_chunk=8)
  assert len(calls) == 1 and second.hessian_cached and not first.hessian_cached
  assert second.hessian_seconds == first.hessian_seconds
  again = unc.compute_masks(config, params, pool['rays'], pseudo, -1., 1., hessian_chunk=8)
  np.testing.assert_array_equal(again.uncertainty, first.uncertainty)
  np.testing.assert_array_equal(again.mask, first.mask)
  # Anything the pass depends on triggers a new one: params, lambda, the rays (seed).
  moved = jax.tree_util.tree_map(lambda x: x * 1.01, params)
  unc.compute_masks(config, moved, pool['rays'], pseudo, -1., 1., hessian_chunk=8)
  unc.compute_masks(dataclasses.replace(config, hessian_lambda=2 * LAM), params,
                    pool['rays'], pseudo, -1., 1., hessian_chunk=8)
  unc.compute_masks(dataclasses.replace(config, seed=3), params, pool['rays'], pseudo,
                    -1., 1., hessian_chunk=8)
  assert len(calls) == 4
  # Bounded: the oldest entries go.
  assert len(unc._HESSIAN_CACHE) == unc.HESSIAN_CACHE_SIZE
