"""Tests for renerf_jax.uncertainty.masks (rendered uncertainty, thresholds, masks)."""

import dataclasses

import numpy as np
import pytest
from tiny_scene import LAM, take, tiny_setup

from renerf_jax.configs import Config
from renerf_jax.nerf.rendering import render_flat
from renerf_jax.uncertainty import laplace
from renerf_jax.uncertainty import masks as unc


@pytest.fixture(scope='module')
def setup():
  return tiny_setup()


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


def test_mask_threshold_is_the_absolute_mu_or_the_keep_fraction_one():
  """The one rule of compute_masks and backbones.synthesize_by_rendering."""
  u = np.random.default_rng(7).lognormal(size=(2, 9, 11)).astype(np.float32)
  absolute = Config(mask_threshold=0.7, mask_keep_frac=0.3)
  assert unc.mask_threshold(absolute, u) == 0.7
  assert isinstance(unc.mask_threshold(absolute, u), float)
  for keep_frac in (0., 0.3, 1.):
    cfg = Config(mask_threshold=-1., mask_keep_frac=keep_frac)
    mu = unc.mask_threshold(cfg, u)
    assert isinstance(mu, float)
    assert mu == unc.threshold_for_keep_fraction(u, keep_frac)


def test_compute_masks_end_to_end(setup):
  config, params, pool = setup
  config = dataclasses.replace(config, deform_log2_res=1, hessian_rays=24,
                               hessian_lambda=LAM, mask_keep_frac=0.5, render_chunk=64)
  pseudo = take(pool['rays'], np.arange(1, 600, 7))  # 86 pixels.
  res = unc.compute_masks(config, params, pool['rays'], pseudo, -1., 1., hessian_chunk=8)
  u, mask, mu = res.uncertainty, res.mask, res.mu
  assert u.shape == mask.shape == (86,)
  assert np.all(np.isfinite(u)) and np.all(u > 0.) and np.all(u <= laplace.prior_sigma(LAM))
  assert 0.5 <= mask.mean() <= 0.5 + 1. / 86
  np.testing.assert_array_equal(mask, (u <= mu).astype(np.float32))
  assert np.ptp(u) > 0.  # Pixels differ in uncertainty.
  # The colours of the same pass are the plain renderer's: masked pseudo-views need one
  # render, not two.
  plain = render_flat(config, params, pseudo, chunk=32)['rgb']
  assert res.rgb.shape == (86, 3) and res.hessian_seconds > 0.
  np.testing.assert_allclose(res.rgb, plain, atol=1e-5)


def test_compute_masks_takes_the_hessian_pass_from_sigma_fn(setup):
  config, params, pool = setup
  config = dataclasses.replace(config, deform_log2_res=1, hessian_rays=24,
                               hessian_lambda=LAM, mask_keep_frac=0.5, render_chunk=64)
  pseudo = take(pool['rays'], np.arange(1, 600, 7))
  plain = unc.compute_masks(config, params, pool['rays'], pseudo, -1., 1., hessian_chunk=8)
  assert plain.hessian_seconds > 0. and plain.render_seconds > 0.
  calls = []

  def sigma_fn(cfg, prm, train, lo, hi, chunk, show_progress):
    calls.append((train.origins.shape, chunk, show_progress))
    sigma, _ = laplace.vertex_sigma_pass(cfg, prm, train, lo, hi, chunk, show_progress)
    return sigma, 12.5

  res = unc.compute_masks(config, params, pool['rays'], pseudo, -1., 1., hessian_chunk=8,
                          sigma_fn=sigma_fn)
  assert calls == [((24, 3), 8, False)]
  assert res.hessian_seconds == 12.5  # the seconds sigma_fn reports, not its wall time
  np.testing.assert_array_equal(res.uncertainty, plain.uncertainty)
  np.testing.assert_array_equal(res.mask, plain.mask)
  np.testing.assert_array_equal(res.rgb, plain.rgb)


@pytest.mark.parametrize('signal', ['one_minus_acc', 'depth_variance', 'weight_entropy',
                                    'acc'])
def test_hessian_free_masks_skip_the_hessian_pass(setup, signal, monkeypatch):
  config, params, pool = setup
  config = dataclasses.replace(config, mask_signal=signal, mask_keep_frac=0.7,
                               render_chunk=64)
  monkeypatch.setattr(laplace, 'hessian_diagonal',
                      lambda *a, **k: pytest.fail('Hessian pass with a Hessian-free signal'))
  pseudo = take(pool['rays'], np.arange(0, 600, 3))
  res = unc.compute_masks(config, params, pool['rays'], pseudo, -1., 1.,
                          sigma_fn=lambda *a: pytest.fail('sigma_fn called'))
  assert res.hessian_seconds == 0. and res.render_seconds > 0.
  # U is the signal of one plain render, the colours are that render's.
  plain = render_flat(config, params, pseudo)
  np.testing.assert_allclose(res.rgb, plain['rgb'], atol=1e-6)
  if signal == 'one_minus_acc':
    np.testing.assert_allclose(res.uncertainty, np.clip(1. - plain['acc'], 0., 1.), atol=1e-6)
  if signal == 'acc':
    np.testing.assert_allclose(res.uncertainty, np.clip(plain['acc'], 0., 1.), atol=1e-6)
  assert np.all(np.isfinite(res.uncertainty)) and np.all(res.uncertainty >= 0.)
  assert res.mask.mean() == pytest.approx(0.7, abs=0.05)
  np.testing.assert_array_equal(res.mask, (res.uncertainty <= res.mu).astype(np.float32))


def test_acc_and_one_minus_acc_at_one_half_split_object_and_background(setup):
  # Issue 49 item 5: 'acc' at mask_threshold 0.5 keeps the pixels B renders empty,
  # 'one_minus_acc' at 0.5 the opaque ones; together they cover every pixel once (both
  # keep a pixel only at acc == 0.5 exactly).
  config, params, pool = setup
  pseudo = take(pool['rays'], np.arange(0, 600, 3))
  res = {s: unc.compute_masks(dataclasses.replace(config, mask_signal=s, mask_threshold=.5,
                                                  render_chunk=64),
                              params, pool['rays'], pseudo, -1., 1.)
         for s in ('acc', 'one_minus_acc')}
  acc = np.asarray(render_flat(config, params, pseudo)['acc'])
  assert 0. < acc.min() < .5 < acc.max()  # both regions are there to split
  np.testing.assert_array_equal(res['acc'].mask, (acc <= .5).astype(np.float32))
  np.testing.assert_array_equal(res['one_minus_acc'].mask, (acc >= .5).astype(np.float32))
  assert np.all(res['acc'].mask + res['one_minus_acc'].mask >= 1.)


def test_unknown_mask_signal_is_one_config_error():
  from renerf_jax.configs import load_config  # pylint: disable=g-import-not-at-top
  from renerf_jax.errors import ConfigError  # pylint: disable=g-import-not-at-top
  with pytest.raises(ConfigError, match="mask_signal='entropy'"):
    load_config([], ["Config.mask_signal = 'entropy'"])
