"""Tests for renerf_jax.uncertainty.deformation (the trilinear deformation grid)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from tiny_scene import take, tiny_setup

from renerf_jax.nerf.model import render_rays
from renerf_jax.uncertainty import deformation


@pytest.fixture(scope='module')
def setup():
  return tiny_setup()


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
  got = deformation.trilinear(jnp.asarray(values), jnp.asarray(pts), lo, hi)
  np.testing.assert_allclose(got, pts @ a + b, atol=1e-5)


def test_trilinear_at_vertices_returns_table_rows():
  n = 2
  values = np.random.default_rng(1).normal(size=((n + 1)**3, 3)).astype(np.float32)
  i, j, k = np.meshgrid(*[np.arange(n + 1)] * 3, indexing='ij')
  ijk = np.stack([i, j, k], -1).reshape(-1, 3)
  pts = -1. + 2. * ijk / n  # Box [-1, 1]^3.
  got = deformation.trilinear(jnp.asarray(values), jnp.asarray(pts, jnp.float32), -1., 1.)
  rows = (ijk[:, 0] * (n + 1) + ijk[:, 1]) * (n + 1) + ijk[:, 2]
  np.testing.assert_allclose(got, values[rows], atol=1e-6)


def test_trilinear_clamps_points_outside_the_box():
  values = jnp.asarray(np.random.default_rng(2).normal(size=(27, 2)), jnp.float32)
  pts = jnp.array([[3., 0.2, -0.4], [-5., -7., 0.9], [0.1, 0.5, 40.]])
  got = deformation.trilinear(values, pts, -1., 1.)
  np.testing.assert_allclose(got, deformation.trilinear(values, jnp.clip(pts, -1., 1.), -1., 1.),
                             atol=1e-6)
  ids, w = deformation.trilinear_corners(pts, -1., 1., 2)
  assert np.all(np.asarray(ids) >= 0) and np.all(np.asarray(ids) < 27)
  np.testing.assert_allclose(np.asarray(w).sum(-1), 1., atol=1e-6)


def test_zero_deformation_is_the_identity(setup):
  config, params, pool = setup
  rays = take(pool['rays'], np.arange(0, 400, 25))
  offsets = jnp.zeros((deformation.grid_size(2), 3), jnp.float32)
  render = lambda w: jax.jit(lambda r: render_rays(config, params, r, jax.random.PRNGKey(0),
                                                   False, offsets=w))(rays)
  plain, warped = render(None), render(deformation.make_warp(offsets, -1., 1.))
  for lv_plain, lv_warped in zip(plain, warped):
    for key in lv_plain:
      np.testing.assert_array_equal(lv_plain[key], lv_warped[key], err_msg=key)
