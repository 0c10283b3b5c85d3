"""Tiled front-to-back alpha blending of screen-space Gaussians (the 3DGS rasteriser).

Per pixel p (centre at integer + 0.5) and Gaussian i, in depth order:
  d = mean2d_i - p,  sigma = 0.5 (a d_x^2 + c d_y^2) + b d_x d_y  (conic (a, b, c)),
  alpha = min(0.99, opacity_i exp(-sigma)), skipped if sigma < 0 or alpha < 1/255;
  if T (1 - alpha) < 1e-4 the pixel is done and this Gaussian is not composited;
  otherwise C += T alpha c_i, D += T alpha depth_i, T *= 1 - alpha.
Finally rgb = C + T background, acc = 1 - T, and depth = D, the *unnormalised* weighted
sum of depths (D / acc is the expected depth of the opaque part, comparable with the
NeRF renderer's `distance`, whose t is also the depth since its camera rays have unit z).

The lists are per `block` x `block` pixel block (blocks.py: a block keeps only the
Gaussians of its tile's list whose alpha can reach 1/255 in it, in the same order;
`rasterize` splits tile lists so, `rasterize_blocks` takes blocks.pair_lists). Groups of
`group` blocks are blended one after another; each walks its lists in chunks of `chunk`
Gaussians in a `lax.while_loop` that stops when the group's pixels are all done or its
longest list is exhausted. Within a chunk the forward pass goes one Gaussian after
another over all pixels of the group (unrolled: XLA fuses it into one pass); the
backward pass works on [group, chunk, block^2] arrays.

The stop rule: the running product Q of (1 - alpha) over every non-skipped Gaussian,
the one that ends the pixel and those after it included, only decreases, so Gaussian i
is composited exactly when Q up to and including i is still >= 1e-4.

The gradient is a custom VJP, the reference rasteriser's backward pass: each group's
chunks are walked back to front from the final transmittance, which is divided by
(1 - alpha) to recover each Gaussian's T (alpha <= 0.99 and T >= 1e-4 keep this well
conditioned); the forward pass keeps per pixel the list index of the Gaussian that
ended it, so the walk knows which were composited, and
  dL/dalpha_i = T_i (c_i . dL/dC + d_i dL/dD) - S_i / (1 - alpha_i),
where S_i is what lies behind Gaussian i: sum_{j > i} T_j alpha_j (c_j . dL/dC + d_j dL/dD)
+ T_final dL/dT_final. Per chunk the per-Gaussian sums over the block's pixels are two
matrix products (moments of dL/dsigma against the pixels' offsets from the block centre,
from which the mean and conic sums follow; the blend weights against the colour and
depth cotangents), scatter-added into one [N + 1, 10] table. tests/test_gaussians.py checks it against
autodiff of the dense reference.
"""
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from renerf_jax.gaussians import blocks as blocks_lib
from renerf_jax.gaussians import tiles as tiles_lib

ALPHA_MIN = blocks_lib.ALPHA_MIN
ALPHA_MAX = 0.99
T_MIN = 1e-4
# Blended per loop step: `chunk` list entries of `group` blocks, [group, chunk, block^2]
# arrays in the backward pass; 16 x 192 blocks x 64 pixels (0.8 MB a float array) stay
# in a core's L2 cache: less than half the time per pixel-Gaussian pair of 64 entries.
CHUNK = 16
BLOCK = 8
GROUP = 256
# Columns of the packed per-Gaussian table (one gather per chunk instead of five).
U, V, CA, CB, CC, OP, R, G, B, DEP = range(10)
WIDTH = 10
HIGHEST = jax.lax.Precision.HIGHEST


def _table(means2d, conics, colours, opacities, depths):
  """[N + 1, 10] packed fields; the padding row N has opacity 0 (never blended)."""
  t = jnp.concatenate([means2d, conics, opacities[:, None], colours, depths[:, None]], -1)
  return jnp.concatenate([t, jnp.zeros((1, WIDTH), t.dtype)], 0)


def _alpha(g, px, py):
  """Offsets, sigma's exponential, raw and clamped alpha and `cond` (not skipped) of
  the chunk's Gaussians g [G, C, 10] at the blocks' pixels px, py [G, P]: [G, C, P]."""
  col = lambda j: g[:, :, j, None]
  dx, dy = col(U) - px[:, None, :], col(V) - py[:, None, :]
  sigma = 0.5 * (col(CA) * dx * dx + col(CC) * dy * dy) + col(CB) * dx * dy
  expo = jnp.exp(-jnp.maximum(sigma, 0.))
  raw = col(OP) * expo
  alpha = jnp.minimum(ALPHA_MAX, raw)
  cond = (sigma >= 0.) & (alpha >= ALPHA_MIN)
  return dx, dy, expo, raw, alpha, cond


def _scan(x, op, reverse=False):
  """Inclusive prefix (or, reverse, suffix) products or sums along axis 1, unrolled:
  for the short chunks XLA's CPU backend fuses the chain into one pass, 2.5x faster
  than its cumulative reductions (reduce-window), with the same sequential rounding."""
  cols = [x[:, c] for c in range(x.shape[1])]
  cols = cols[::-1] if reverse else cols
  out = cols[:1]
  for c in cols[1:]:
    out.append(op(out[-1], c))
  # The barrier asks XLA not to fuse (and recompute) the chain into each consumer; its
  # CPU pipeline may expand it away (no measured difference either way).
  return jax.lax.optimization_barrier(jnp.stack(out[::-1] if reverse else out, axis=1))


def _group(x, i, group):
  """Rows [i * group, (i + 1) * group) of x."""
  return jax.lax.dynamic_slice_in_dim(x, i * group, group, axis=0)


def _chunk(ids, table, k, chunk):
  """Ids [G, C] and packed fields [G, C, 10] of chunk k of the block lists ids."""
  c = jax.lax.dynamic_slice_in_dim(ids, k * chunk, chunk, axis=1)
  return c, table[c]


def _forward(ids, last, table, px, py, height, width, chunk, group):
  """The forward pass over block lists ids [K, L] (K a multiple of group, L of chunk),
  one group of blocks after another, each walking its chunks until its pixels are done
  or its lists (last[i] chunks long) exhausted.

  Returns:
    rgb [K, 3, P] (no background), depth [K, P], final transmittance T [K, P], stop [K, P]
    (the list index of the Gaussian that ended the pixel, or L), chunks walked per
    group [K / group].
  """
  num_blocks, length = ids.shape
  shape = (group, px.shape[1])
  dtype = table.dtype

  def one_group(i, out):
    gids, gpx, gpy = (_group(x, i, group) for x in (ids, px, py))

    def cond_fn(carry):
      k, q = carry[:2]
      return (k < last[i]) & jnp.any(q >= T_MIN)

    def body(carry):
      # One Gaussian after another, vectorised over the group's pixels: XLA fuses the
      # unrolled chain into one pass that keeps the running state in registers.
      k, q, trans, rgb, dep, stop = carry
      _, g = _chunk(gids, table, k, chunk)
      rgb = list(rgb)
      for c in range(chunk):
        _, _, _, _, alpha, cond = _alpha(g[:, c:c + 1], gpx, gpy)
        alpha, cond = alpha[:, 0], cond[:, 0]
        after = q * jnp.where(cond, 1. - alpha, 1.)
        comp = cond & (after >= T_MIN)
        w = jnp.where(comp, q * alpha, 0.)
        rgb = [x + w * g[:, c, j, None] for x, j in zip(rgb, (R, G, B))]
        dep = dep + w * g[:, c, DEP, None]
        trans = jnp.where(comp, after, trans)
        stop = jnp.where(cond & (after < T_MIN) & (stop == length), k * chunk + c, stop)
        q = after
      return k + 1, q, trans, tuple(rgb), dep, stop

    # Pixels outside the image (the last blocks' padding) start done.
    inside = ((gpx < width) & (gpy < height)).astype(dtype)
    init = (jnp.zeros((), jnp.int32), inside, jnp.ones(shape, dtype),
            (jnp.zeros(shape, dtype),) * 3, jnp.zeros(shape, dtype),
            jnp.full(shape, length, jnp.int32))
    k, _, trans, rgb, dep, stop = jax.lax.while_loop(cond_fn, body, init)
    rgb = jnp.stack(rgb, axis=1)
    put = lambda o, r: jax.lax.dynamic_update_slice_in_dim(o, r, i * group, 0)
    return (put(out[0], rgb), put(out[1], dep), put(out[2], trans), put(out[3], stop),
            out[4].at[i].set(k))

  init = (jnp.zeros((num_blocks, 3) + shape[1:], dtype),
          jnp.zeros((num_blocks,) + shape[1:], dtype),
          jnp.ones((num_blocks,) + shape[1:], dtype),
          jnp.full((num_blocks,) + shape[1:], length, jnp.int32),
          jnp.zeros((num_blocks // group,), jnp.int32))
  rgb, dep, trans, stop, walked = jax.lax.fori_loop(0, num_blocks // group, one_group,
                                                    init)
  return rgb, dep, trans, stop, walked


def _backward(ids, table, px, py, trans, stop, walked, g_rgb, g_dep, g_trans, chunk,
              group):
  """[N + 1, 10] cotangents of the packed table, each group's chunks back to front."""
  num_blocks = ids.shape[0]
  slot = jnp.arange(chunk, dtype=jnp.int32)[:, None]
  qx, qy = px[0] - jnp.mean(px[0]), py[0] - jnp.mean(py[0])  # Offsets from the centre.
  basis = jnp.stack([jnp.ones_like(qx), qx, qy, qx * qx, qx * qy, qy * qy], -1)

  def one_group(i, grads):
    gids, gpx, gpy, gstop, grgb, gdep = (_group(x, i, group) for x in (
        ids, px, py, stop, g_rgb, g_dep))
    gcot = jnp.concatenate([jnp.swapaxes(grgb, 1, 2), gdep[..., None]], -1)  # [G, P, 4]
    cx, cy = jnp.mean(gpx, axis=1), jnp.mean(gpy, axis=1)

    def body(j, carry):
      t_after, behind, grads = carry
      k = walked[i] - 1 - j
      c, g = _chunk(gids, table, k, chunk)
      dx, dy, expo, raw, alpha, cond = _alpha(g, gpx, gpy)
      comp = cond & (k * chunk + slot < gstop[:, None])
      keep = jnp.where(comp, 1. - alpha, 1.)
      suffix_keep = _scan(keep, jnp.multiply, reverse=True)  # Inclusive.
      before = t_after[:, None] / suffix_keep
      w = jnp.where(comp, before * alpha, 0.)
      col = lambda j: g[:, :, j, None]
      v = (col(R) * grgb[:, None, 0] + col(G) * grgb[:, None, 1] +
           col(B) * grgb[:, None, 2] + col(DEP) * gdep[:, None])
      wv = w * v
      suffix = _scan(wv, jnp.add, reverse=True)  # Inclusive.
      after = behind[:, None] + suffix - wv
      d_alpha = jnp.where(comp, before * v - after / keep, 0.)
      d_raw = jnp.where(raw < ALPHA_MAX, d_alpha, 0.)
      d_sigma = -d_raw * raw
      # Pixel sums as two matrix products: moments of d_sigma over the block's pixel
      # offsets from its centre, and w against the block's colour and depth cotangents.
      mom = jnp.einsum('gcp,pk->gck', d_sigma, basis, precision=HIGHEST)  # [G, C, 6]
      cw = jnp.einsum('gcp,gpk->gck', w, gcot, precision=HIGHEST)  # [G, C, 4]
      m0, mx, my, mxx, mxy, myy = (mom[..., j] for j in range(6))
      ul, vl = g[:, :, U] - cx[:, None], g[:, :, V] - cy[:, None]
      sdx, sdy = ul * m0 - mx, vl * m0 - my
      sxx = ul * ul * m0 - 2. * ul * mx + mxx
      sxy = ul * vl * m0 - ul * my - vl * mx + mxy
      syy = vl * vl * m0 - 2. * vl * my + myy
      op = g[:, :, OP]
      d_op = jnp.where(op > 0., -m0 / jnp.where(op > 0., op, 1.), 0.)
      per = jnp.stack([g[:, :, CA] * sdx + g[:, :, CB] * sdy,
                       g[:, :, CC] * sdy + g[:, :, CB] * sdx,
                       0.5 * sxx, sxy, 0.5 * syy, d_op], -1)
      per = jnp.concatenate([per, cw], -1)  # [G, C, 10], as table.
      return before[:, 0], behind + suffix[:, 0], grads.at[c].add(per)

    init = (_group(trans, i, group), _group(trans * g_trans, i, group), grads)
    return jax.lax.fori_loop(0, walked[i], body, init)[2]

  return jax.lax.fori_loop(0, num_blocks // group, one_group, jnp.zeros_like(table))


@functools.partial(jax.custom_vjp, nondiff_argnums=(7, 8))
def _composite(ids, last, means2d, conics, colours, opacities, depths, grid, chunk):
  out, _ = _composite_fwd(ids, last, means2d, conics, colours, opacities, depths, grid,
                          chunk)
  return out


def _composite_fwd(ids, last, means2d, conics, colours, opacities, depths, grid, chunk):
  table = _table(means2d, conics, colours, opacities, depths)
  px, py = _pixels(grid, table.dtype)
  rgb, dep, trans, stop, walked = _forward(ids, last, table, px, py, grid.height,
                                           grid.width, chunk, grid.group)
  return (rgb, dep, trans), (ids, table, trans, stop, walked)


def _composite_bwd(grid, chunk, res, cotangents):
  ids, table, trans, stop, walked = res
  px, py = _pixels(grid, table.dtype)
  g = _backward(ids, table, px, py, trans, stop, walked, *cotangents, chunk,
                grid.group)[:-1]
  return (None, None, g[:, U:V + 1], g[:, CA:CC + 1], g[:, R:B + 1], g[:, OP], g[:, DEP])


_composite.defvjp(_composite_fwd, _composite_bwd)


class _Grid(NamedTuple):
  """Static layout: image size, block size and grid, blocks padded to whole groups."""
  height: int
  width: int
  block: int
  blocks_y: int
  blocks_x: int
  group: int
  num_blocks: int  # blocks_y * blocks_x rounded up to a multiple of group.


def _pixels(grid, dtype):
  """(px, py) [num_blocks, block^2] pixel centres (group padding: beyond the image)."""
  rows = -(-grid.num_blocks // grid.blocks_x)
  px, py = blocks_lib.block_pixels(grid.block, rows, grid.blocks_x, dtype)
  return px[:grid.num_blocks], py[:grid.num_blocks]


def _prepare(tile_ids, means2d, conics, opacities, height, width, tile, chunk, block,
             group):
  """Block lists of tile lists (padded to whole chunks and groups), chunks per group,
  the _Grid."""
  tiles_y, tiles_x = tiles_lib.tile_grid(height, width, tile)
  if tile_ids.shape[0] != tiles_y * tiles_x:
    raise ValueError(f'{tile_ids.shape[0]} tile lists for {tiles_y * tiles_x} tiles')
  n = means2d.shape[0]
  block = min(block, tile)
  tile_ids = jnp.minimum(tile_ids, n).astype(jnp.int32)
  ids, length = blocks_lib.block_lists(tile_ids, means2d, conics, opacities, height,
                                       width, tile, block)
  return _pad_blocks(ids, length, n, height, width, tile, chunk, block, group)


def _pad_blocks(ids, length, n, height, width, tile, chunk, block, group):
  """Block lists ids [K, L], length [K] padded to whole chunks and groups, the chunks
  per group and the _Grid."""
  blocks_y, blocks_x = blocks_lib.block_grid(height, width, tile, block)
  num_blocks = blocks_y * blocks_x
  if ids.shape[0] != num_blocks:
    raise ValueError(f'{ids.shape[0]} block lists for {num_blocks} blocks')
  group = min(group, num_blocks)
  rows = -(-num_blocks // group) * group
  pad = -ids.shape[1] % chunk or (chunk if ids.shape[1] == 0 else 0)
  ids = jnp.pad(ids, ((0, rows - num_blocks), (0, pad)), constant_values=n)
  length = jnp.pad(length, (0, rows - num_blocks)).reshape(-1, group)
  grid = _Grid(height, width, block, blocks_y, blocks_x, group, rows)
  return ids, -(-jnp.max(length, axis=1) // chunk), grid


def _image(x, grid):
  """[K, P] or [K, 3, P] per-block values -> [H, W] or [H, W, 3]."""
  if x.ndim == 3:
    x = jnp.swapaxes(x, 1, 2)
  return blocks_lib.blocks_to_image(x[:grid.blocks_y * grid.blocks_x], grid.height,
                                    grid.width, grid.block, grid.blocks_y, grid.blocks_x)


@functools.partial(jax.jit, static_argnames=('height', 'width', 'tile', 'chunk',
                                             'block', 'group'))
def walk(tile_ids, means2d, conics, colours, opacities, depths, height, width, tile=16,
         chunk=CHUNK, block=BLOCK, group=GROUP):
  """How the forward pass walks the lists (for tests): (ended [H, W] bool, the pixels
  that a Gaussian ended (T would fall below 1e-4), chunks walked per group, block list
  lengths)."""
  ids, last, grid = _prepare(tile_ids, means2d, conics, opacities, height, width, tile,
                             chunk, block, group)
  table = _table(means2d, conics, colours, opacities, depths)
  px, py = _pixels(grid, table.dtype)
  _, _, _, stop, walked = _forward(ids, last, table, px, py, height, width, chunk,
                                   grid.group)
  return (_image(stop < ids.shape[1], grid), walked,
          jnp.sum(ids < means2d.shape[0], axis=1))


@functools.partial(jax.jit, static_argnames=('height', 'width', 'tile', 'chunk',
                                             'block', 'group'))
def rasterize(tile_ids, means2d, conics, colours, opacities, depths, height, width,
              background, tile=16, chunk=CHUNK, block=BLOCK, group=GROUP):
  """Alpha-blends the tile lists of `tiles.tile_intersect` into an image.

  Args:
    tile_ids: [T, L] int Gaussian ids per tile, front to back; ids >= N are padding
      (skipped wherever they stand). L may be anything up to N.
    means2d: [N, 2] pixels. conics: [N, 3]. colours: [N, 3]. opacities: [N] in [0, 1].
    depths: [N] view depths.
    height, width, tile: static ints; T must equal tiles.tile_grid product.
    background: [3] colour behind everything.
    chunk: static number of list entries blended per loop step.
    block: static pixel block size (divides tile; clipped to it).
    group: static number of blocks blended together.

  Returns:
    (rgb [H, W, 3], depth [H, W] unnormalised weighted depth sum, acc [H, W]).
  """
  ids, last, grid = _prepare(tile_ids, means2d, conics, opacities, height, width, tile,
                             chunk, block, group)
  rgb, dep, trans = _composite(ids, last, means2d, conics, colours, opacities, depths,
                               grid, chunk)
  rgb = rgb + trans[:, None, :] * background[:, None]
  return _image(rgb, grid), _image(dep, grid), _image(1. - trans, grid)


@functools.partial(jax.jit, static_argnames=('height', 'width', 'tile', 'chunk',
                                             'block', 'group'))
def rasterize_blocks(block_ids, length, means2d, conics, colours, opacities, depths,
                     height, width, background, tile=16, chunk=CHUNK, block=BLOCK,
                     group=GROUP):
  """`rasterize` of block lists (blocks.pair_lists or blocks.block_lists).

  Args:
    block_ids: [K, L] int32 Gaussian ids per block, front to back, padded with N at the
      end. length: [K] int32 real ids per block.
    The rest as `rasterize`.
  """
  ids, last, grid = _pad_blocks(block_ids, length, means2d.shape[0], height, width,
                                tile, chunk, block, group)
  rgb, dep, trans = _composite(ids, last, means2d, conics, colours, opacities, depths,
                               grid, chunk)
  rgb = rgb + trans[:, None, :] * background[:, None]
  return _image(rgb, grid), _image(dep, grid), _image(1. - trans, grid)
