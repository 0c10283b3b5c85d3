"""Tests for renerf_jax.metrics (PSNR, SSIM vs. skimage, LPIPS references)."""

from pathlib import Path

import imageio.v3 as iio
import jax
import numpy as np
import pytest
from skimage.metrics import structural_similarity

from renerf_jax import metrics

DATA = Path(__file__).resolve().parents[1].parent / 'shared' / 'data'
LPIPS_DIR = DATA / 'lpips_reference'

# Reference distances from lpips_reference/README.md ([-1, 1] inputs, v0.1).
LPIPS_REFERENCE = {
    'alex': (0.7219, 0.1376),
    'vgg': (0.5686, 0.4217),
}


def _load(name):
  """Reads ex_<name>.png as float64 [H, W, 3] in [0, 1]."""
  path = LPIPS_DIR / f'ex_{name}.png'
  if not path.exists():
    pytest.skip(f'missing reference data {path}')
  return iio.imread(path)[..., :3].astype(np.float64) / 255.


def _skimage_ssim(a, b):
  return structural_similarity(
      a, b, data_range=1.0, channel_axis=-1, gaussian_weights=True, sigma=1.5,
      use_sample_covariance=False)


def test_psnr_constant_offset():
  rng = np.random.default_rng(0)
  img = rng.uniform(0.1, 0.8, size=(2, 16, 12, 3))
  for delta in (0.01, 0.1):
    expected = -10. * np.log10(delta**2)
    np.testing.assert_allclose(metrics.psnr(img, img + delta),
                               [expected, expected], rtol=1e-5)
  np.testing.assert_allclose(metrics.mse_to_psnr(1e-3), 30., rtol=1e-6)
  np.testing.assert_allclose(metrics.psnr_to_mse(30.), 1e-3, rtol=1e-6)


def test_ssim_matches_skimage_random():
  rng = np.random.default_rng(1)
  a = rng.uniform(size=(48, 64, 3))
  b = np.clip(a + 0.15 * rng.normal(size=a.shape), 0., 1.)
  ssim = jax.jit(metrics.ssim)
  for x, y in ((a, b), (a, rng.uniform(size=a.shape))):
    np.testing.assert_allclose(float(ssim(x, y)), _skimage_ssim(x, y),
                               atol=1e-4)


@pytest.mark.parametrize('other', ['p0', 'p1'])
def test_ssim_matches_skimage_natural(other):
  ref, img = _load('ref'), _load(other)
  ssim = jax.jit(metrics.ssim)
  np.testing.assert_allclose(float(ssim(ref, img)), _skimage_ssim(ref, img),
                             atol=1e-4)
  # Non-square crop: checks the border handling ('valid' == skimage's crop).
  ref_c, img_c = ref[3:43, 7:57], img[3:43, 7:57]
  assert ref_c.shape == (40, 50, 3)
  np.testing.assert_allclose(float(ssim(ref_c, img_c)),
                             _skimage_ssim(ref_c, img_c), atol=1e-4)


def test_ssim_map_shape_and_identity():
  rng = np.random.default_rng(2)
  x = rng.uniform(size=(40, 50, 3))
  assert metrics.ssim_map(x, x).shape == (30, 40, 3)
  np.testing.assert_allclose(float(metrics.ssim(x, x)), 1., atol=1e-6)
  assert float(metrics.ssim(x, 1. - x)) < 0.


def test_gaussian_kernel_is_normalised():
  taps = metrics.gaussian_kernel_1d()
  assert taps.shape == (11,)
  np.testing.assert_allclose(taps.sum(), 1., rtol=1e-6)
  np.testing.assert_allclose(taps, taps[::-1])


@pytest.mark.parametrize('net', ['alex', 'vgg'])
def test_lpips_reference_distances(net):
  ref, p0, p1 = _load('ref'), _load('p0'), _load('p1')
  lpips = metrics.LPIPS(net)
  d0, d1 = lpips(p0, ref), lpips(p1, ref)
  assert isinstance(d0, float)
  np.testing.assert_allclose([d0, d1], LPIPS_REFERENCE[net], atol=1e-3)
  # Batched path gives the same values.
  batch = lpips.distances(np.stack([p0, p1]), np.stack([ref, ref]))
  np.testing.assert_allclose(np.asarray(batch), [d0, d1], atol=1e-5)


def test_lpips_identity_and_monotone_in_noise():
  ref = _load('ref')
  lpips = metrics.LPIPS('alex')
  assert abs(lpips(ref, ref)) < 1e-6
  noise = np.random.default_rng(3).normal(size=ref.shape)
  dists = [lpips(ref, np.clip(ref + s * noise, 0., 1.))
           for s in (0.02, 0.05, 0.1, 0.2, 0.4)]
  assert all(d0 < d1 for d0, d1 in zip(dists[:-1], dists[1:])), dists
  assert dists[0] > 0.


def test_lpips_rejects_unknown_net():
  with pytest.raises(ValueError):
    metrics.LPIPS('squeeze-me')


def test_avg_err_known_values():
  # RegNeRF's average error is the geometric mean of MSE = 10^(-PSNR/10),
  # sqrt(1 - SSIM) and LPIPS; values worked out by hand:
  # psnr 20 -> mse 0.01, ssim 0.96 -> 0.2, lpips 0.5: cbrt(0.001) = 0.1.
  np.testing.assert_allclose(metrics.avg_err(20., 0.96, 0.5), 0.1, rtol=1e-9)
  # psnr 50 -> mse 1e-5: cbrt(1e-6) = 0.01; lpips 4: cbrt(0.008) = 0.2;
  # psnr 0 -> mse 1, ssim 0.75 -> 0.5, lpips 0.016: cbrt(0.008) = 0.2.
  np.testing.assert_allclose(metrics.avg_err(50., 0.96, 0.5), 0.01, rtol=1e-9)
  np.testing.assert_allclose(metrics.avg_err(20., 0.96, 4.), 0.2, rtol=1e-9)
  np.testing.assert_allclose(metrics.avg_err(0., 0.75, 0.016), 0.2, rtol=1e-9)
  # Elementwise over arrays (broadcast against scalars).
  np.testing.assert_allclose(metrics.avg_err([20., 50.], 0.96, [4., 0.5]),
                             [0.2, 0.01], rtol=1e-9)
  # A perfect SSIM or LPIPS gives zero error; better PSNR gives lower error.
  assert metrics.avg_err(20., 1., 0.5) == 0.
  assert metrics.avg_err(20., 0.96, 0.) == 0.
  assert metrics.avg_err(30., 0.96, 0.5) < metrics.avg_err(20., 0.96, 0.5)


def test_image_metrics_keys_and_values():
  ref, p1 = _load('ref'), _load('p1')
  out = metrics.image_metrics(p1, ref)
  assert set(out) == {'psnr', 'ssim', 'lpips_alex', 'lpips_vgg', 'avg_err'}
  assert all(isinstance(v, float) for v in out.values())
  np.testing.assert_allclose(out['ssim'], _skimage_ssim(p1, ref), atol=1e-4)
  np.testing.assert_allclose(out['lpips_alex'], 0.1376, atol=1e-3)
  np.testing.assert_allclose(
      out['avg_err'],
      metrics.avg_err(out['psnr'], out['ssim'], out['lpips_alex']), rtol=1e-9)
  only_ssim_psnr = metrics.image_metrics(p1, ref, lpips_nets=())
  assert set(only_ssim_psnr) == {'psnr', 'ssim'}


def test_lpips_alex_size_is_checked_before_training():
  """LPIPS-alex on views under 31 px a side is refused by Config check before any
  training (renerf.check_rounds_config calls it), naming the value; vgg alone or 31 px
  pass."""
  from renerf_jax.errors import ConfigError  # pylint: disable=g-import-not-at-top
  with pytest.raises(ConfigError, match=r"Config.lpips_nets=\('vgg', 'alex'\).*24x30"):
    metrics.check_lpips_size(('vgg', 'alex'), 30, 24)
  metrics.check_lpips_size(('vgg',), 30, 24)
  metrics.check_lpips_size(('alexnet',), 31, 31)
  with pytest.raises(ConfigError):
    metrics.check_lpips_size(('alexnet',), 31, 30)
