"""Dense, untiled rasteriser: the test oracle of `rasterize.rasterize`.

Every valid Gaussian is blended into every pixel in `jnp.argsort` depth order with the
rules of the reference 3DGS (see rasterize.py), written out independently of the tiled
code. With `tile` given, Gaussian i reaches pixel p only if its box centre +- radius
overlaps the tile that holds p: exactly what the tiled rasteriser computes when no tile
list is capped. With tile=None there is no box culling at all (the tiled result differs
from it only where a Gaussian's alpha >= 1/255 reaches beyond its 3-sigma box's tiles).
"""
import functools

import jax
import jax.numpy as jnp


@functools.partial(jax.jit, static_argnames=('height', 'width', 'tile'))
def dense_reference(means2d, conics, colours, opacities, depths, valid, height, width,
                    background, radius=None, tile=None):
  """Blends all Gaussians into all pixels, O(N H W).

  Args:
    means2d: [N, 2]. conics: [N, 3]. colours: [N, 3]. opacities: [N]. depths: [N].
    valid: [N] bool. height, width: static ints. background: [3].
    radius: [N] pixel radii, needed with `tile`.
    tile: static int tile size for box culling, or None.

  Returns:
    (rgb [H, W, 3], depth [H, W] unnormalised weighted depth sum, acc [H, W]).
  """
  dtype = means2d.dtype
  ys, xs = jnp.meshgrid(jnp.arange(height), jnp.arange(width), indexing='ij')
  px, py = xs.astype(dtype) + 0.5, ys.astype(dtype) + 0.5
  if tile is not None:
    x0, y0 = (xs // tile * tile).astype(dtype), (ys // tile * tile).astype(dtype)
  order = jnp.argsort(jnp.where(valid, depths, jnp.inf))

  def body(carry, i):
    trans, done, rgb, dep = carry
    (u, v), (a, b, c) = means2d[i], conics[i]
    dx, dy = u - px, v - py
    sigma = 0.5 * (a * dx**2 + c * dy**2) + b * dx * dy
    ok = valid[i] & (sigma >= 0.) & ~done
    if tile is not None:
      r = radius[i]
      ok = ok & (x0 < u + r) & (x0 + tile > u - r) & (y0 < v + r) & (y0 + tile > v - r)
    alpha = jnp.minimum(0.99, opacities[i] * jnp.exp(-jnp.where(ok, sigma, 0.)))
    ok = ok & (alpha >= 1. / 255.)
    test_t = trans * (1. - alpha)
    finish = ok & (test_t < 1e-4)
    ok = ok & ~finish
    w = jnp.where(ok, alpha * trans, 0.)
    rgb = rgb + w[..., None] * colours[i]
    dep = dep + w * depths[i]
    trans = jnp.where(ok, test_t, trans)
    return (trans, done | finish, rgb, dep), None

  init = (jnp.ones((height, width), dtype), jnp.zeros((height, width), bool),
          jnp.zeros((height, width, 3), dtype), jnp.zeros((height, width), dtype))
  (trans, _, rgb, dep), _ = jax.lax.scan(body, init, order)
  return rgb + trans[..., None] * background, dep, 1. - trans
