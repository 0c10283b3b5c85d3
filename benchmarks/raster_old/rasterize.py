"""Tiled front-to-back alpha blending of screen-space Gaussians (the 3DGS rasteriser).

Per pixel p (centre at integer + 0.5) and Gaussian i, in depth order:
  d = mean2d_i - p,  sigma = 0.5 (a d_x^2 + c d_y^2) + b d_x d_y  (conic (a, b, c)),
  alpha = min(0.99, opacity_i exp(-sigma)), skipped if sigma < 0 or alpha < 1/255;
  if T (1 - alpha) < 1e-4 the pixel is done and this Gaussian is not composited;
  otherwise C += T alpha c_i, D += T alpha depth_i, T *= 1 - alpha.
Finally rgb = C + T background, acc = 1 - T, and depth = D, the *unnormalised* weighted
sum of depths (D / acc is the expected depth of the opaque part, comparable with the
NeRF renderer's `distance`, whose t is also the depth since its camera rays have unit z).

As the CUDA rasterisers (3DGS, gsplat) do, the tile lists are walked in chunks of
`chunk` Gaussians for all pixels of all tiles at once ([T, tile^2, chunk] arrays), in a
`lax.while_loop` that stops when every pixel of the image is done or the longest list
is exhausted: a tile list may be as long as the number of Gaussians (no cap). The stop
is global (all tiles step together), so a step costs about T * P * ceil(longest list /
chunk) alpha evaluations unless every pixel saturates first. Within a chunk the
transmittance is a cumulative product, and the first Gaussian that would take it below
1e-4 ends the pixel.

The gradient is a custom VJP, the reference rasteriser's backward pass: the chunks are
walked back to front from the final transmittance, which is divided by (1 - alpha) to
recover each Gaussian's T (alpha <= 0.99 and T >= 1e-4 keep this well conditioned), and
  dL/dalpha_i = T_i (c_i . dL/dC + d_i dL/dD) - S_i / (1 - alpha_i),
where S_i is what lies behind Gaussian i: sum_{j > i} T_j alpha_j (c_j . dL/dC + d_j dL/dD)
+ T_final dL/dT_final. No per-step state is stored, so memory does not grow with the
list length. tests/test_gaussians.py checks it against autodiff of the dense reference.
"""
import functools

import jax
import jax.numpy as jnp

from renerf_jax.gaussians import tiles as tiles_lib

ALPHA_MIN = 1. / 255.
ALPHA_MAX = 0.99
T_MIN = 1e-4
CHUNK = 32
HIGHEST = jax.lax.Precision.HIGHEST  # float32 products everywhere (no TF32 on GPUs).


def pixel_centres(height, width, tile, dtype=jnp.float32):
  """(px, py) [T, tile^2] pixel centres of each tile, tiles row-major, pixels row-major."""
  tiles_y, tiles_x = tiles_lib.tile_grid(height, width, tile)
  ty, tx = jnp.divmod(jnp.arange(tiles_y * tiles_x), tiles_x)
  py_in, px_in = jnp.divmod(jnp.arange(tile * tile), tile)
  px = (tx[:, None] * tile + px_in[None, :]).astype(dtype) + 0.5
  py = (ty[:, None] * tile + py_in[None, :]).astype(dtype) + 0.5
  return px, py


def tiles_to_image(x, height, width, tile):
  """[T, tile^2, ...] per-tile pixels -> [H, W, ...] image (the padding cropped)."""
  tiles_y, tiles_x = tiles_lib.tile_grid(height, width, tile)
  x = x.reshape((tiles_y, tiles_x, tile, tile) + x.shape[2:])
  x = jnp.swapaxes(x, 1, 2).reshape((tiles_y * tile, tiles_x * tile) + x.shape[4:])
  return x[:height, :width]


def _pad(x):
  """One zero row at index N, read by the padding id N."""
  return jnp.concatenate([x, jnp.zeros((1,) + x.shape[1:], x.dtype)], axis=0)


def _chunk_alpha(ids, n, means2d_p, conics_p, opacities_p, px, py):
  """Per pixel and chunk slot: offsets, sigma, raw and clamped alpha, and `cond` (the
  Gaussian is real and passes the sigma >= 0 and alpha >= 1/255 tests). [T, P, C]."""
  m, cn = means2d_p[ids], conics_p[ids]  # [T, C, 2], [T, C, 3]
  dx = m[:, None, :, 0] - px[:, :, None]
  dy = m[:, None, :, 1] - py[:, :, None]
  a, b, c = (cn[:, None, :, k] for k in range(3))
  sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy
  expo = jnp.exp(-jnp.where(sigma >= 0., sigma, 0.))
  raw = opacities_p[ids][:, None, :] * expo
  alpha = jnp.minimum(ALPHA_MAX, raw)
  cond = (ids < n)[:, None, :] & (sigma >= 0.) & (alpha >= ALPHA_MIN)
  return dx, dy, expo, raw, alpha, cond


def _reverse_cumprod(x):
  return jnp.flip(jnp.cumprod(jnp.flip(x, -1), axis=-1), -1)


def _forward(tile_ids, means2d, conics, colours, opacities, depths, height, width, tile,
             chunk):
  """The chunked forward pass. Returns (rgb [T, P, 3] without background, depth [T, P],
  final transmittance [T, P], stop slot [T, P] (the list index of the Gaussian that ended
  the pixel, or the list length), number of chunks walked)."""
  n = means2d.shape[0]
  dtype = means2d.dtype
  px, py = pixel_centres(height, width, tile, dtype)
  num_tiles, length = tile_ids.shape
  num_chunks = length // chunk
  means2d_p, conics_p, colours_p = _pad(means2d), _pad(conics), _pad(colours)
  opacities_p, depths_p = _pad(opacities), _pad(depths)
  # Chunks past the last real id of every list hold only padding: stop before them.
  used = jnp.max(jnp.where(tile_ids < n, jnp.arange(1, length + 1), 0))
  last = -(-used // chunk)
  slot = jnp.arange(chunk, dtype=jnp.int32)

  def cond_fn(carry):
    k, _, done, _, _, _ = carry
    return (k < jnp.minimum(last, num_chunks)) & ~jnp.all(done)

  def body(carry):
    k, trans, done, stop_slot, rgb, dep = carry
    ids = jax.lax.dynamic_slice_in_dim(tile_ids, k * chunk, chunk, axis=1)
    _, _, _, _, alpha, cond = _chunk_alpha(ids, n, means2d_p, conics_p, opacities_p, px,
                                           py)
    live = cond & ~done[..., None]
    after = trans[..., None] * jnp.cumprod(1. - jnp.where(live, alpha, 0.), axis=-1)
    stop = live & (after < T_MIN)
    any_stop = jnp.any(stop, axis=-1)
    first = jnp.where(any_stop, jnp.argmax(stop, axis=-1).astype(jnp.int32), chunk)
    comp = live & (slot < first[..., None])
    keep = jnp.cumprod(1. - jnp.where(comp, alpha, 0.), axis=-1)
    before = trans[..., None] * jnp.concatenate(
        [jnp.ones_like(keep[..., :1]), keep[..., :-1]], axis=-1)
    w = jnp.where(comp, before * alpha, 0.)
    rgb = rgb + jnp.einsum('tpc,tck->tpk', w, colours_p[ids], precision=HIGHEST)
    dep = dep + jnp.einsum('tpc,tc->tp', w, depths_p[ids], precision=HIGHEST)
    stop_slot = jnp.where(any_stop, k * chunk + first, stop_slot).astype(jnp.int32)
    return (k + 1, trans * keep[..., -1], done | any_stop, stop_slot, rgb, dep)

  shape = px.shape
  # The padding pixels of the last tile row and column (outside the image) start done,
  # with nothing composited (stop slot 0), so they never keep the loop going.
  outside = (px > width) | (py > height)
  init = (jnp.zeros((), jnp.int32), jnp.ones(shape, dtype), outside,
          jnp.where(outside, 0, length).astype(jnp.int32), jnp.zeros(shape + (3,), dtype),
          jnp.zeros(shape, dtype))
  k, trans, _, stop_slot, rgb, dep = jax.lax.while_loop(cond_fn, body, init)
  return rgb, dep, trans, stop_slot, k


def _backward(tile_ids, means2d, conics, colours, opacities, depths, trans_final,
              stop_slot, num_chunks, g_rgb, g_dep, g_trans, height, width, tile, chunk):
  """Cotangents of (means2d, conics, colours, opacities, depths), walking back to front."""
  n = means2d.shape[0]
  dtype = means2d.dtype
  px, py = pixel_centres(height, width, tile, dtype)
  means2d_p, conics_p, colours_p = _pad(means2d), _pad(conics), _pad(colours)
  opacities_p, depths_p = _pad(opacities), _pad(depths)
  slot = jnp.arange(chunk)
  zeros = lambda x: jnp.zeros_like(_pad(x))
  grads0 = tuple(zeros(x) for x in (means2d, conics, colours, opacities, depths))

  def body(j, carry):
    trans, behind, grads = carry
    k = num_chunks - 1 - j
    ids = jax.lax.dynamic_slice_in_dim(tile_ids, k * chunk, chunk, axis=1)
    dx, dy, expo, raw, alpha, cond = _chunk_alpha(ids, n, means2d_p, conics_p,
                                                  opacities_p, px, py)
    comp = cond & (k * chunk + slot < stop_slot[..., None])
    one_minus = 1. - jnp.where(comp, alpha, 0.)
    before = trans[..., None] / _reverse_cumprod(one_minus)
    w = jnp.where(comp, before * alpha, 0.)
    col, dep = colours_p[ids], depths_p[ids]  # [T, C, 3], [T, C]
    v = (jnp.einsum('tpk,tck->tpc', g_rgb, col, precision=HIGHEST) +
         g_dep[..., None] * dep[:, None, :])
    wv = w * v
    after = behind[..., None] + jnp.flip(jnp.cumsum(jnp.flip(wv, -1), -1), -1) - wv
    d_alpha = jnp.where(comp, before * v - after / one_minus, 0.)
    d_raw = jnp.where(raw < ALPHA_MAX, d_alpha, 0.)
    d_sigma = -d_raw * raw
    gm, gc, gcol, gop, gdep = grads
    cn = conics_p[ids][:, None]  # [T, 1, C, 3]
    gm = gm.at[ids].add(jnp.stack(
        [jnp.sum(d_sigma * (cn[..., 0] * dx + cn[..., 1] * dy), 1),
         jnp.sum(d_sigma * (cn[..., 2] * dy + cn[..., 1] * dx), 1)], -1))
    gc = gc.at[ids].add(jnp.stack([jnp.sum(d_sigma * 0.5 * dx * dx, 1),
                                   jnp.sum(d_sigma * dx * dy, 1),
                                   jnp.sum(d_sigma * 0.5 * dy * dy, 1)], -1))
    gcol = gcol.at[ids].add(jnp.einsum('tpc,tpk->tck', w, g_rgb, precision=HIGHEST))
    gop = gop.at[ids].add(jnp.sum(d_raw * expo, 1))
    gdep = gdep.at[ids].add(jnp.sum(w * g_dep[..., None], 1))
    return before[..., 0], behind + jnp.sum(wv, -1), (gm, gc, gcol, gop, gdep)

  init = (trans_final, trans_final * g_trans, grads0)
  _, _, grads = jax.lax.fori_loop(0, num_chunks, body, init)
  return tuple(x[:n] for x in grads)


@functools.partial(jax.custom_vjp, nondiff_argnums=(6, 7, 8, 9))
def _composite(tile_ids, means2d, conics, colours, opacities, depths, height, width, tile,
               chunk):
  rgb, dep, trans, _, _ = _forward(tile_ids, means2d, conics, colours, opacities, depths,
                                   height, width, tile, chunk)
  return rgb, dep, trans


def _composite_fwd(tile_ids, means2d, conics, colours, opacities, depths, height, width,
                   tile, chunk):
  rgb, dep, trans, stop_slot, k = _forward(tile_ids, means2d, conics, colours, opacities,
                                           depths, height, width, tile, chunk)
  res = (tile_ids, means2d, conics, colours, opacities, depths, trans, stop_slot, k)
  return (rgb, dep, trans), res


def _composite_bwd(height, width, tile, chunk, res, cotangents):
  tile_ids, means2d, conics, colours, opacities, depths, trans, stop_slot, k = res
  g_rgb, g_dep, g_trans = cotangents
  grads = _backward(tile_ids, means2d, conics, colours, opacities, depths, trans,
                    stop_slot, k, g_rgb, g_dep, g_trans, height, width, tile, chunk)
  return (None,) + grads


_composite.defvjp(_composite_fwd, _composite_bwd)


@functools.partial(jax.jit, static_argnames=('height', 'width', 'tile', 'chunk'))
def rasterize(tile_ids, means2d, conics, colours, opacities, depths, height, width,
              background, tile=16, chunk=CHUNK):
  """Alpha-blends the tile lists of `tiles.tile_intersect` into an image.

  Args:
    tile_ids: [T, L] int Gaussian ids per tile, front to back; ids >= N are padding
      (skipped wherever they stand). L may be anything up to N (no cap).
    means2d: [N, 2] pixels. conics: [N, 3]. colours: [N, 3]. opacities: [N] in [0, 1].
    depths: [N] view depths.
    height, width, tile: static ints; T must equal tiles.tile_grid product.
    background: [3] colour behind everything.
    chunk: static number of list entries blended per loop step.

  Returns:
    (rgb [H, W, 3], depth [H, W] unnormalised weighted depth sum, acc [H, W]).
  """
  tiles_y, tiles_x = tiles_lib.tile_grid(height, width, tile)
  num_tiles = tiles_y * tiles_x
  if tile_ids.shape[0] != num_tiles:
    raise ValueError(f'{tile_ids.shape[0]} tile lists for {num_tiles} tiles')
  n = means2d.shape[0]
  tile_ids = jnp.minimum(tile_ids, n).astype(jnp.int32)
  pad = -tile_ids.shape[1] % chunk
  if pad or tile_ids.shape[1] == 0:
    pad = pad or chunk
    tile_ids = jnp.pad(tile_ids, ((0, 0), (0, pad)), constant_values=n)
  rgb, dep, trans = _composite(tile_ids, means2d, conics, colours, opacities, depths,
                               height, width, tile, chunk)
  rgb = rgb + trans[..., None] * background
  return (tiles_to_image(rgb, height, width, tile), tiles_to_image(dep, height, width, tile),
          tiles_to_image(1. - trans, height, width, tile))
