"""3DGS's photometric loss of commit 7346aa4: renerf_jax.gaussians.loss with the SSIM
blur as sums of shifted slices, differentiated by autodiff (issue 51 replaced it by
banded matrix products)."""
import functools

import jax

from renerf_jax.gaussians import loss


def _blur_slices(x, taps):
  """Separable 'valid' filtering of [H, W, C] by `taps` along H and W."""
  for axis in (0, 1):
    n_out = x.shape[axis] - len(taps) + 1
    x = sum(float(w) * jax.lax.slice_in_dim(x, k, k + n_out, axis=axis)
            for k, w in enumerate(taps))
  return x


image_loss = functools.partial(loss.image_loss, blur=_blur_slices)
