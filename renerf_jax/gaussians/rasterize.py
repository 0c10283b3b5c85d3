"""Tiled front-to-back alpha blending of screen-space Gaussians (the 3DGS rasteriser).

Per pixel p (centre at integer + 0.5) and Gaussian i, in depth order:
  d = mean2d_i - p,  sigma = 0.5 (a d_x^2 + c d_y^2) + b d_x d_y  (conic (a, b, c)),
  alpha = min(0.99, opacity_i exp(-sigma)), skipped if sigma < 0 or alpha < 1/255;
  if T (1 - alpha) < 1e-4 the pixel is done and this Gaussian is not composited;
  otherwise C += T alpha c_i, D += T alpha depth_i, T *= 1 - alpha.
Finally rgb = C + T background, acc = 1 - T, and depth = D, the *unnormalised* weighted
sum of depths (D / acc is the expected depth of the opaque part, comparable with the
NeRF renderer's `distance`, whose t is also the depth since its camera rays have unit z).

Implemented as one `lax.scan` over the `cap` slots of the tile lists, vectorised over all
pixels of all tiles ([T, tile^2] arrays); gradients come from autodiff, and masked
contributions are selected with `jnp.where` on finite values, so none can be NaN.
"""
import functools

import jax
import jax.numpy as jnp

from renerf_jax.gaussians import tiles as tiles_lib

ALPHA_MIN = 1. / 255.
ALPHA_MAX = 0.99
T_MIN = 1e-4


def blend_step(trans, done, alpha_raw, sigma, real):
  """One front-to-back compositing step; shared rules of the tiled rasteriser.

  Args:
    trans: [...] transmittance before this Gaussian. done: [...] bool, pixel finished.
    alpha_raw: [...] opacity * exp(-max(sigma, 0)). sigma: [...] Mahalanobis half-square.
    real: [...] bool, the Gaussian exists (not padding / not culled).

  Returns:
    (weight [...], new trans, new done); weight = T alpha where composited, else 0.
  """
  alpha = jnp.minimum(ALPHA_MAX, alpha_raw)
  use = real & (sigma >= 0.) & (alpha >= ALPHA_MIN) & ~done
  next_trans = trans * (1. - alpha)
  stop = use & (next_trans < T_MIN)
  comp = use & ~stop
  weight = jnp.where(comp, trans * alpha, 0.)
  return weight, jnp.where(comp, next_trans, trans), done | stop


def gaussian_sigma(means2d, conics, px, py):
  """0.5 (a dx^2 + c dy^2) + b dx dy for broadcastable means2d [..., 2], conics [..., 3]."""
  dx = means2d[..., 0] - px
  dy = means2d[..., 1] - py
  return (0.5 * (conics[..., 0] * dx * dx + conics[..., 2] * dy * dy) +
          conics[..., 1] * dx * dy)


def gaussian_alpha(opacities, sigma):
  """opacity * exp(-sigma), with sigma < 0 (skipped anyway) evaluated at 0 (no overflow)."""
  return opacities * jnp.exp(-jnp.where(sigma >= 0., sigma, 0.))


@functools.partial(jax.jit, static_argnames=('height', 'width', 'tile'))
def rasterize(tile_ids, means2d, conics, colours, opacities, depths, height, width,
              background, tile=16):
  """Alpha-blends the tile lists of `tiles.tile_intersect` into an image.

  Args:
    tile_ids: [T, K] int Gaussian ids per tile, front to back; ids >= N are padding.
    means2d: [N, 2] pixels. conics: [N, 3]. colours: [N, 3]. opacities: [N] in [0, 1].
    depths: [N] view depths.
    height, width, tile: static ints; T must equal tiles.tile_grid product.
    background: [3] colour behind everything.

  Returns:
    (rgb [H, W, 3], depth [H, W] unnormalised weighted depth sum, acc [H, W]).
  """
  tiles_y, tiles_x = tiles_lib.tile_grid(height, width, tile)
  num_tiles = tiles_y * tiles_x
  if tile_ids.shape[0] != num_tiles:
    raise ValueError(f'{tile_ids.shape[0]} tile lists for {num_tiles} tiles')
  n = means2d.shape[0]
  dtype = means2d.dtype
  ty, tx = jnp.divmod(jnp.arange(num_tiles), tiles_x)
  py_in, px_in = jnp.divmod(jnp.arange(tile * tile), tile)
  px = (tx[:, None] * tile + px_in[None, :]).astype(dtype) + 0.5  # [T, P]
  py = (ty[:, None] * tile + py_in[None, :]).astype(dtype) + 0.5

  def pad(x):  # One zero row at index N for the padding id.
    return jnp.concatenate([x, jnp.zeros((1,) + x.shape[1:], x.dtype)], axis=0)

  means2d_p, conics_p, colours_p = pad(means2d), pad(conics), pad(colours)
  opacities_p, depths_p = pad(opacities), pad(depths)

  def step(carry, ids):
    trans, done, rgb, dep = carry
    ids = jnp.minimum(ids, n)
    real = (ids < n)[:, None]
    sigma = gaussian_sigma(means2d_p[ids][:, None, :], conics_p[ids][:, None, :], px, py)
    alpha_raw = gaussian_alpha(opacities_p[ids][:, None], sigma)
    weight, trans, done = blend_step(trans, done, alpha_raw, sigma, real)
    rgb = rgb + weight[..., None] * colours_p[ids][:, None, :]
    dep = dep + weight * depths_p[ids][:, None]
    return (trans, done, rgb, dep), None

  shape = px.shape
  init = (jnp.ones(shape, dtype), jnp.zeros(shape, bool), jnp.zeros(shape + (3,), dtype),
          jnp.zeros(shape, dtype))
  (trans, _, rgb, dep), _ = jax.lax.scan(step, init, tile_ids.T)
  rgb = rgb + trans[..., None] * background

  def to_image(x):  # [T, P, ...] -> [H, W, ...]
    x = x.reshape((tiles_y, tiles_x, tile, tile) + x.shape[2:])
    x = jnp.swapaxes(x, 1, 2).reshape((tiles_y * tile, tiles_x * tile) + x.shape[4:])
    return x[:height, :width]

  return to_image(rgb), to_image(dep), to_image(1. - trans)
