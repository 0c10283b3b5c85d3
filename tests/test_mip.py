import jax
import jax.numpy as jnp
import numpy as np
import pytest

from renerf_jax.nerf import mip


def test_ipe_matches_monte_carlo_expectation_of_sin():
  rng = np.random.default_rng(0)
  mean = np.array([[0.3, -0.7, 1.1]], np.float32)
  var = np.array([[0.02, 0.3, 0.001]], np.float32)
  feats = np.asarray(mip.integrated_pos_enc(jnp.array(mean), jnp.array(var), 0, 3))
  x = mean + np.sqrt(var) * rng.normal(size=(400000, 3))
  expected = []
  for shift in (0., np.pi / 2):
    for k in range(3):
      expected.append(np.mean(np.sin(2.**k * x + shift), 0))
  expected = np.concatenate(expected)
  np.testing.assert_allclose(feats[0], expected, atol=5e-3)


def test_ipe_huge_variance_goes_to_zero_without_nan():
  f = lambda v: jnp.sum(mip.integrated_pos_enc(jnp.ones((2, 3)) * 1e6, v, 0, 16))
  v = jnp.full((2, 3), 1e30)
  assert np.allclose(mip.integrated_pos_enc(jnp.ones((2, 3)) * 1e6, v, 0, 16), 0.)
  g = jax.grad(f)(v)
  assert np.all(np.isfinite(g))


def test_conical_frustum_moments_match_monte_carlo():
  rng = np.random.default_rng(1)
  d = np.array([0., 0., -1.])
  t0, t1, r = 1.0, 1.6, 0.2
  mean, cov = mip.conical_frustum_to_gaussian(jnp.array(d), jnp.array([t0]), jnp.array([t1]),
                                              jnp.array([r]))
  # Uniform samples in the frustum: t with density ~ t^2, radius uniform in the disk.
  n = 400000
  u = rng.uniform(size=n)
  t = (t0**3 + u * (t1**3 - t0**3))**(1. / 3.)
  rad = t * r * np.sqrt(rng.uniform(size=n))
  phi = rng.uniform(0, 2 * np.pi, n)
  pts = np.stack([rad * np.cos(phi), rad * np.sin(phi), -t], -1)
  np.testing.assert_allclose(mean[0], pts.mean(0), atol=2e-3)
  np.testing.assert_allclose(cov[0], pts.var(0), rtol=3e-2, atol=1e-5)


def test_cylinder_moments():
  mean, cov = mip.cylinder_to_gaussian(jnp.array([1., 0., 0.]), jnp.array([2.]),
                                       jnp.array([4.]), jnp.array([0.5]))
  np.testing.assert_allclose(mean[0], [3., 0., 0.])
  np.testing.assert_allclose(cov[0], [4. / 12., 0.25**2 / 4. * 4., 0.0625], rtol=1e-6)


@pytest.mark.parametrize('ray_shape', ['cone', 'cylinder'])
def test_zero_length_intervals_and_near_equals_far_are_finite(ray_shape):
  o = jnp.zeros((2, 3))
  d = jnp.array([[0., 0., -1.], [0.5, 0., -1.]])
  radii = jnp.full((2, 1), 0.01)
  for near in (0., 1.):
    t_vals, (means, covs) = mip.sample_along_rays(
        jax.random.PRNGKey(0), o, d, radii, 8, jnp.full((2, 1), near), jnp.full((2, 1), near),
        True, False, ray_shape)
    assert np.all(np.isfinite(means)) and np.all(np.isfinite(covs))
    rgb = jnp.ones(means.shape)
    out = mip.volumetric_rendering(rgb, jnp.ones(means.shape[:-1]), t_vals, d, False)
    for v in out.values():
      assert np.all(np.isfinite(v))
    np.testing.assert_allclose(out['acc'], 0., atol=1e-6)


def test_volumetric_rendering_hand_computed():
  t_vals = jnp.array([[0., 1., 2., 3.]])
  d = jnp.array([[0., 0., -1.]])
  rgb = jnp.array([[[1., 0., 0.], [0., 1., 0.], [0., 0., 1.]]])
  density = jnp.array([[np.log(2.), 0., np.log(4.)]])  # alpha = 1/2, 0, 3/4.
  out = mip.volumetric_rendering(rgb, density, t_vals, d, white_bkgd=False)
  np.testing.assert_allclose(out['weights'][0], [0.5, 0., 0.375], rtol=1e-6)
  np.testing.assert_allclose(out['rgb'][0], [0.5, 0., 0.375], rtol=1e-6)
  np.testing.assert_allclose(out['acc'][0], 0.875, rtol=1e-6)
  np.testing.assert_allclose(out['distance'][0], (0.5 * 0.5 + 0.375 * 2.5) / 0.875,
                             rtol=1e-6)
  white = mip.volumetric_rendering(rgb, density, t_vals, d, white_bkgd=True)
  np.testing.assert_allclose(white['rgb'][0], np.array([0.5, 0., 0.375]) + 0.125, rtol=1e-6)


def test_volumetric_rendering_extremes():
  t_vals = jnp.array([[0., 1e-10, 1., 1e10]])
  d = jnp.array([[0., 0., -1.]])
  rgb = jnp.full((1, 3, 3), 0.5)

  def loss(density):
    out = mip.volumetric_rendering(rgb, density, t_vals, d, False)
    return out['rgb'].sum() + out['distance'].sum() + out['acc'].sum()

  for dens in (jnp.zeros((1, 3)), jnp.full((1, 3), 1e10)):
    out = mip.volumetric_rendering(rgb, dens, t_vals, d, False)
    for v in out.values():
      assert np.all(np.isfinite(v))
    assert np.all(np.isfinite(jax.grad(loss)(dens)))
  # Zero density: nothing rendered, distance at the far end.
  out = mip.volumetric_rendering(rgb, jnp.zeros((1, 3)), t_vals, d, False)
  np.testing.assert_allclose(out['acc'], 0.)
  np.testing.assert_allclose(out['distance'], 1e10)
  # Huge density: the 1e-10-long first interval takes alpha = 1 - e^-1, the next one
  # absorbs the rest.
  out = mip.volumetric_rendering(rgb, jnp.full((1, 3), 1e10), t_vals, d, False)
  np.testing.assert_allclose(out['acc'], 1., rtol=1e-6)
  np.testing.assert_allclose(out['weights'][0], [1. - np.exp(-1.), np.exp(-1.), 0.],
                             rtol=1e-5, atol=1e-7)


def test_piecewise_constant_pdf_sampling():
  bins = jnp.broadcast_to(jnp.linspace(0., 1., 5), (3, 5))
  weights = jnp.array([[0., 0., 1., 0.], [0., 0., 0., 0.], [1., 1., 1., 1.]])
  for randomized in (False, True):
    s = np.asarray(mip.sorted_piecewise_constant_pdf(jax.random.PRNGKey(0), bins, weights,
                                                     64, randomized))
    assert np.all(np.diff(s, axis=-1) >= 0)
    assert np.all((s[0] >= 0.5) & (s[0] <= 0.75))  # all mass in the third bin
    assert np.all((s >= 0.) & (s <= 1.))
    # Zero weights and uniform weights both give ~uniform samples.
    np.testing.assert_allclose(np.mean(s[1]), 0.5, atol=0.03)
    np.testing.assert_allclose(np.mean(s[2]), 0.5, atol=0.03)


def test_resample_blur_and_padding():
  key = jax.random.PRNGKey(0)
  t_vals = jnp.broadcast_to(jnp.linspace(0., 1., 9), (2, 9))
  weights = jnp.zeros((2, 8)).at[:, 3].set(1.)
  o, d, r = jnp.zeros((2, 3)), jnp.array([[0., 0., -1.]] * 2), jnp.full((2, 1), 0.01)
  new_t, (means, _) = mip.resample_along_rays(key, o, d, r, t_vals, weights, False, 'cone',
                                              True, 0.01)
  assert new_t.shape == (2, 9) and means.shape == (2, 8, 3)
  new_t = np.asarray(new_t)
  assert np.all(np.diff(new_t, axis=-1) >= 0)
  # The 2-tap max + blur spreads mass over bins 2..4 = [0.25, 0.625]; padding keeps a
  # little mass everywhere.
  inside = (new_t >= 0.25) & (new_t <= 0.625)
  assert inside.mean() > 0.7


def test_freq_band_mask():
  np.testing.assert_allclose(mip.freq_band_mask(4, 0.), [1., 0., 0., 0.])
  np.testing.assert_allclose(mip.freq_band_mask(4, 0.5), [1., 1., 1., 0.])
  np.testing.assert_allclose(mip.freq_band_mask(4, 1.), [1., 1., 1., 1.])
  m = mip.ipe_feature_mask(jnp.array([1., 0.5]))
  np.testing.assert_allclose(m, [1, 1, 1, .5, .5, .5] * 2)
