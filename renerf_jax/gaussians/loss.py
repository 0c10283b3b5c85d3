"""3DGS's photometric loss, (1 - l) L1 + l (1 - SSIM), with per-pixel masks."""
import functools

import jax
import jax.numpy as jnp
import numpy as np

from renerf_jax import metrics


def _band(taps, n):
  """[n - len(taps) + 1, n] matrix whose row i holds the taps at columns i .. i + len - 1."""
  k = len(taps)
  band = np.zeros((n - k + 1, n), np.float32)
  for i in range(n - k + 1):
    band[i, i:i + k] = taps
  return band


def _blur_matmul(x, taps):
  """Separable 'valid' filtering of [H, W, C] by `taps` along H and W: two products
  with banded matrices."""
  band_h = jnp.asarray(_band(taps, x.shape[0]), x.dtype)
  band_w = jnp.asarray(_band(taps, x.shape[1]), x.dtype)
  x = jnp.einsum('hi,iwc->hwc', band_h, x, precision=jax.lax.Precision.HIGHEST)
  return jnp.einsum('vw,hwc->hvc', band_w, x, precision=jax.lax.Precision.HIGHEST)


def _blur_valid(x, taps):
  """_blur_matmul, whose gradient is the two transposed banded products.

  Sums of shifted slices, and autodiff of them, fuse badly on XLA's CPU backend: on a
  126x94 image the SSIM loss took ~7 ms with that forward (and 40 ms with its autodiff
  gradient), 0.7 ms with banded products both ways. The products sum the taps in
  another order: SSIM values move by ~2e-6, float32 rounding (both orders are that far
  from a float64 evaluation).
  """
  taps = tuple(float(w) for w in taps)
  return _blur_custom(x, taps)


@functools.partial(jax.custom_vjp, nondiff_argnums=(1,))
def _blur_custom(x, taps):
  return _blur_matmul(x, taps)


def _blur_fwd(x, taps):
  return _blur_matmul(x, taps), x.shape


def _blur_bwd(taps, shape, g):
  band_h = jnp.asarray(_band(taps, shape[0]), g.dtype)
  band_w = jnp.asarray(_band(taps, shape[1]), g.dtype)
  g = jnp.einsum('jw,ijc->iwc', band_w, g, precision=jax.lax.Precision.HIGHEST)
  return (jnp.einsum('ih,iwc->hwc', band_h, g, precision=jax.lax.Precision.HIGHEST),)


_blur_custom.defvjp(_blur_fwd, _blur_bwd)


def masked_ssim_map(img0, img1, mask, blur=_blur_valid):
  """SSIM map of metrics.ssim_map (11x11 Gaussian window, sigma 1.5, 'valid') whose
  local statistics are weighted by a pixel mask: a pixel of weight 0 enters no window.

  Each window's means, variances and covariance are mask-weighted averages (normalised
  by the window's mask weight); with an all-ones mask this is metrics.ssim_map. Windows
  centred on a pixel of weight 0 are excluded (weight 0 and no gradient, even where the
  rest of the window is masked too).

  Args:
    img0, img1: [H, W, 3] (H, W >= 11). mask: [H, W] weights in [0, 1].
    blur: (x [H, W, C], taps) -> the separable 'valid' filtering of x (_blur_valid;
      benchmarks/raster_old passes the slice sums it had before issue 51).

  Returns:
    (ssim [H - 10, W - 10, 3], weight [H - 10, W - 10, 1]: the centre pixels' mask).
  """
  taps = metrics.gaussian_kernel_1d(metrics.SSIM_FILTER_SIZE, metrics.SSIM_FILTER_SIGMA)
  r = (len(taps) - 1) // 2
  m = mask[..., None]
  centre = m[r:m.shape[0] - r, r:m.shape[1] - r]
  use = centre > 0.
  bm = blur(m, taps)
  safe = lambda x, fill: jnp.where(use, x, fill)
  norm = safe(bm, 1.)

  def avg(x):  # Mask-weighted local mean; constants outside `use` (no gradient there).
    return safe(blur(m * x, taps), 0.) / norm

  mu0, mu1 = avg(img0), avg(img1)
  s00 = jnp.maximum(0., avg(img0**2) - mu0**2)
  s11 = jnp.maximum(0., avg(img1**2) - mu1**2)
  s01 = avg(img0 * img1) - mu0 * mu1
  c1, c2 = metrics.SSIM_K1**2, metrics.SSIM_K2**2
  ssim = ((2. * mu0 * mu1 + c1) * (2. * s01 + c2) /
          ((mu0**2 + mu1**2 + c1) * (s00 + s11 + c2)))
  return ssim, centre


def image_loss(rgb, target, mask, lambda_dssim, blur=_blur_valid):
  """(1 - l) L1 + l (1 - SSIM) of a rendered image, pixels weighted by a mask.

  L1 = mean(m |rgb - target|) over all pixels and channels; 1 - SSIM = the mean over
  the SSIM map of w (1 - SSIM) (masked_ssim_map: a pixel of weight 0 enters no window,
  and windows centred on one count 0). A pixel of weight 0 thus enters neither term nor
  any gradient, whatever its rendered or target colour; an all-zero mask gives loss 0
  and zero gradients. Pixels keep the weight of a real view's pixels (no
  renormalisation by the mask's sum), as a pseudo-view's usable pixels join the
  training pixels.

  Args:
    rgb, target: [H, W, 3] (H, W >= 11). mask: [H, W] weights in [0, 1].
    lambda_dssim: weight of the SSIM term. blur: as masked_ssim_map's.

  Returns:
    (loss, masked MSE) scalars; the MSE is sum(m (rgb - target)^2) / (3 sum(m)).
  """
  m = mask[..., None]
  l1 = jnp.mean(m * jnp.abs(rgb - target))
  ssim, weight = masked_ssim_map(rgb, target, mask, blur)
  dssim = jnp.sum(weight * (1. - ssim)) / ssim.size
  loss = (1. - lambda_dssim) * l1 + lambda_dssim * dssim
  mse = jnp.sum(m * (rgb - target)**2) / jnp.maximum(3. * jnp.sum(m), 1e-8)
  return loss, mse
