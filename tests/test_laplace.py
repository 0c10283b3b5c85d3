"""Tests for renerf_jax.uncertainty.laplace (the Laplace / Gauss-Newton Hessian diagonal)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from dense_reference import (gn_hessian_diagonal, reference_hessian_diagonals,
                             true_hessian_diagonal)
from tiny_scene import LAM, take, tiny_setup

from renerf_jax.nerf.model import render_rays
from renerf_jax.uncertainty import laplace
from renerf_jax.uncertainty import masks as uncertainty_masks
from renerf_jax.uncertainty.deformation import trilinear_corners


@pytest.fixture(scope='module')
def setup():
  return tiny_setup()


def test_kahan_keeps_small_terms():
  def body(_, carry):
    return laplace.kahan_add(carry[0], carry[1], jnp.float32(1e-8))
  total, comp = jax.jit(lambda: jax.lax.fori_loop(
      0, 10000, body, (jnp.float32(1.), jnp.float32(0.))))()
  naive = jax.jit(lambda: jax.lax.fori_loop(0, 10000, lambda _, s: s + jnp.float32(1e-8),
                                            jnp.float32(1.)))()
  assert float(naive) == 1.  # float32 drops every term on its own...
  np.testing.assert_allclose(float(total - comp), 1.0001, rtol=1e-6)  # ... Kahan does not.


HESSIAN_RAYS = [5, 70, 140, 210, 333, 420, 500]  # 7 rays: 2 chunks of 4, one ray padded.


@pytest.mark.parametrize('num,chunk,want', [(8883, 8192, 4442), (7, 4, 4), (6, 4, 3),
                                            (5, 100, 5), (1, 1, 1), (1024, 1024, 1024),
                                            (1025, 1024, 513)])
def test_balanced_chunk_covers_the_rays_in_fewest_even_chunks(num, chunk, want):
  c = laplace.balanced_chunk(num, chunk)
  assert c == want
  chunks = -(-num // c)
  assert chunks == -(-num // min(chunk, num))  # As few chunks as the cap allows...
  assert chunks * c - num < chunks  # ... with less than one padded ray per chunk.


def test_per_ray_sums_match_a_dense_per_ray_jacobian():
  # Rays as lines through a 4^3 grid: consecutive samples share cells and vertices, so
  # a vertex's contributions must be summed within the ray before squaring.
  key = jax.random.split(jax.random.PRNGKey(3), 4)
  levels, b, s, n = 2, 5, 9, 4
  o = jax.random.uniform(key[0], (b, 3), minval=-1., maxval=1.)
  d = jax.random.normal(key[1], (b, 3))
  t = jnp.sort(jax.random.uniform(key[2], (levels, b, s)), axis=-1)
  means = o[None, :, None] + t[..., None] * d[None, :, None]  # Some leave the box.
  sens = jax.random.normal(key[3], (3, levels, b, s, 3))
  ids, sq = laplace.per_ray_vertex_jtj(sens, means, -1., 1., n)
  got = np.zeros(((n + 1)**3, 3))
  np.add.at(got, np.asarray(ids), np.asarray(sq, np.float64))
  cid, w = (np.asarray(x) for x in trilinear_corners(means, -1., 1., n))
  want = np.zeros_like(got)
  for lv in range(levels):
    for r in range(b):
      jac = np.zeros((3, (n + 1)**3, 3))  # [channel, vertex, axis] of this ray and level
      for i in range(s):
        for c in range(8):
          jac[:, cid[lv, r, i, c], :] += w[lv, r, i, c] * np.asarray(sens[:, lv, r, i, :])
      want += np.sum(jac**2, axis=0)
  assert np.sum(want > 0) > 50
  np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * want.max())


def test_sparse_kahan_add_touches_only_ids_and_sums_repeats():
  total = jnp.array([[1.], [2.], [3.], [4.]], jnp.float32)
  comp = jnp.zeros_like(total)
  scratch = jnp.zeros_like(total)
  ids = jnp.array([2, 0, 2, 2, 0], jnp.int32)  # Repeats, unordered; rows 1 and 3 untouched.
  vals = jnp.array([[1e-8], [0.5], [1e-8], [1e-8], [0.25]], jnp.float32)
  t, c, scratch = laplace.sparse_kahan_add(total, comp, scratch, ids, vals)
  np.testing.assert_array_equal(np.asarray(scratch), 0.)  # Ready for the next chunk.
  np.testing.assert_allclose(np.asarray(t - c)[:, 0], [1.75, 2., 3. + 3e-8, 4.], rtol=1e-7)
  np.testing.assert_array_equal(np.asarray(t)[[1, 3]], [[2.], [4.]])
  # Kahan across calls: 10^4 terms of 1e-8 onto 1.0 are not lost.
  step = jax.jit(laplace.sparse_kahan_add)
  one = (jnp.ones((2, 1)), jnp.zeros((2, 1)), jnp.zeros((2, 1)))
  ids, vals = jnp.array([1], jnp.int32), jnp.full((1, 1), 1e-8, jnp.float32)
  for _ in range(10000):
    one = step(*one, ids, vals)
  assert float(one[0][1, 0] - one[1][1, 0]) == pytest.approx(1.0001, rel=1e-6)
  assert float(one[0][0, 0]) == 1.


def test_forward_mode_reference_diagonals_equal_jax_hessian_on_a_closed_form():
  """The reference's two diagonals against jax.hessian of a small nonlinear map (cheap
  here; on the renderer, jax.hessian's graph is what crashed XLA, issue 38)."""
  a = jax.random.normal(jax.random.PRNGKey(0), (2, 4, 3, 5))

  def fn(theta):  # [5] -> [levels 2, R 4, 3], with cross terms between coordinates.
    return jnp.sin(a @ theta) * jnp.exp(0.3 * (a**2) @ theta) + (a @ theta)**3

  theta0 = jnp.array([0.1, -0.2, 0.3, 0.05, -0.4])
  target = fn(theta0) + 0.5
  loss = lambda th, tgt: jnp.sum((fn(th) - tgt)**2) / 4.
  gn = np.asarray(gn_hessian_diagonal(fn, theta0))
  np.testing.assert_allclose(gn, np.diag(jax.hessian(loss)(theta0, fn(theta0))),
                             rtol=1e-4)
  true = np.asarray(true_hessian_diagonal(fn, theta0, target))
  want = np.diag(jax.hessian(loss)(theta0, target))
  np.testing.assert_allclose(true, want, rtol=1e-4)
  assert np.max(np.abs(true - gn)) > 1e-2 * np.max(gn)  # The residual term is there.


def test_hessian_diagonal_matches_the_dense_reference(setup):
  config, params, pool = setup
  rays = take(pool['rays'], HESSIAN_RAYS)
  h = np.asarray(laplace.hessian_diagonal(config, params, rays, -1., 1., 1, LAM, chunk=4))
  ref = np.asarray(reference_hessian_diagonals(config, params, rays, -1., 1., 1)['gn'])
  assert h.shape == (27, 3)
  assert np.sum(ref > 1e-2 * ref.max()) > 20  # Many vertices seen: a non-trivial check.
  np.testing.assert_allclose(h, ref + 2. * LAM, rtol=1e-4, atol=1e-6 * ref.max())


def test_reference_true_hessian_is_gn_at_zero_residual_only(setup):
  config, params, pool = setup
  rays = take(pool['rays'], HESSIAN_RAYS)
  rgb0 = jnp.stack([lv['rgb'] for lv in jax.jit(
      lambda r: render_rays(config, params, r, jax.random.PRNGKey(0), False))(rays)])
  ref = reference_hessian_diagonals(config, params, rays, -1., 1., 1, gt_rgb=rgb0)
  np.testing.assert_allclose(ref['true'], ref['gn'], rtol=1e-4, atol=1e-6 * ref['gn'].max())
  off = reference_hessian_diagonals(config, params, rays, -1., 1., 1,
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
  h = np.asarray(laplace.hessian_diagonal(config, params, rays, lo, hi, 1, LAM, chunk=4))
  ijk = np.stack(np.meshgrid(*[np.arange(3)] * 3, indexing='ij'), -1).reshape(-1, 3)
  unseen = (ijk[:, 0] == 2) | (ijk[:, 1] == 2)
  np.testing.assert_allclose(h[unseen], 2. * LAM, rtol=1e-6)
  np.testing.assert_allclose(1. / h[unseen], 1. / (2. * LAM), rtol=1e-6)  # Sigma per axis.
  assert np.max(h[~unseen]) > 10. * LAM
  sigma = np.asarray(laplace.vertex_sigma(jnp.asarray(h)))
  np.testing.assert_allclose(sigma[unseen], laplace.prior_sigma(LAM), rtol=1e-6)
  assert np.all(sigma[~unseen] <= laplace.prior_sigma(LAM) * (1. + 1e-6))


def test_zero_sensitivity_gives_the_prior_without_nan(setup):
  config, params, pool = setup
  flat = jax.tree_util.tree_map(jnp.zeros_like, params)  # Constant field: dx rgb = 0.
  rays = take(pool['rays'], np.arange(3, 600, 120))
  h = np.asarray(laplace.hessian_diagonal(config, flat, rays, -1., 1., 1, LAM, chunk=4))
  assert np.all(np.isfinite(h))
  np.testing.assert_array_equal(h, np.float32(2. * LAM))
  sigma = laplace.vertex_sigma(jnp.asarray(h))
  u, rgb = uncertainty_masks.render_uncertainty(config, flat, sigma, rays, -1., 1., chunk=4,
                                                u_bg=laplace.prior_sigma(LAM))
  assert u.shape == (5,) and rgb.shape == (5, 3)
  assert np.all(np.isfinite(u))
  np.testing.assert_allclose(u, laplace.prior_sigma(LAM), rtol=1e-5)


def test_vertex_sigma_pass_is_hessian_diagonal_then_vertex_sigma(setup):
  config, params, pool = setup
  config = dataclasses.replace(config, deform_log2_res=1, hessian_lambda=LAM)
  rays = take(pool['rays'], HESSIAN_RAYS)
  sigma, seconds = laplace.vertex_sigma_pass(config, params, rays, -1., 1., 4)
  h = laplace.hessian_diagonal(config, params, rays, -1., 1., 1, LAM, chunk=4)
  np.testing.assert_array_equal(sigma, laplace.vertex_sigma(h))
  assert sigma.shape == (27,) and seconds > 0.
