"""Block lists: each tile's list split among the tile's b x b pixel blocks, keeping in
each block only the Gaussians whose alpha can reach 1/255 at one of its pixels.

The rasteriser blends a Gaussian into a pixel only where alpha = min(0.99, o exp(-sigma))
is at least 1/255, i.e. where sigma <= log(255 o): inside an ellipse, whose bounding
box (`alpha_reach`) is much smaller than the 3-sigma box of the tile test for most
Gaussians (and empty when o < 1/255). A Gaussian left out of a block's list would have
composited nothing and received no gradient at any of its pixels, so the blocks' lists
blend exactly what the tile's list does, in the same (depth) order, at a fraction of
the pixel-Gaussian pairs (about 1/2.3 on a fresh fern scene with 8x8 blocks).

Blocks are numbered row-major over the image's block grid (blocks_y, blocks_x) =
(tiles_y, tiles_x) * tile / block, and a block's pixels row-major within it.
"""
import jax
import jax.numpy as jnp

from renerf_jax.gaussians import tiles as tiles_lib

ALPHA_MIN = 1. / 255.
# Conics more elongated than this (trace^2 / det) keep their whole tile box: the float
# evaluation of sigma is only trusted to ~1e-7 * this, well inside the margins below.
MAX_ELONGATION = 1e4
REACH_SLACK = 1e-3  # Relative and absolute (pixels) margins of the reach.
# pair_lists sorts the smallest prefix of its pair buffer, buffer / 2^(k / 2) with
# k < SIZE_STEPS, that holds all its pairs.
SIZE_STEPS = 10


def block_grid(height, width, tile, block):
  """(blocks_y, blocks_x): the tile grid refined by tile // block in each axis."""
  if tile % block:
    raise ValueError(f'block {block} does not divide tile {tile}')
  tiles_y, tiles_x = tiles_lib.tile_grid(height, width, tile)
  return tiles_y * (tile // block), tiles_x * (tile // block)


def alpha_reach(conics, opacities):
  """Half-widths of the box around each mean outside which alpha < 1/255.

  sigma = d^T Q d / 2 for the conic Q = Sigma^-1, so sigma <= s holds only within
  |dx| <= sqrt(2 s Sigma_xx), |dy| <= sqrt(2 s Sigma_yy), where Sigma_xx = c / det Q and
  Sigma_yy = a / det Q, with s = log(255 o).

  Args:
    conics: [N, 3] (a, b, c). opacities: [N].

  Returns:
    (rx, ry) [N]: -1 where alpha < 1/255 everywhere (o < 1/255); inf where the conic is
    singular, indefinite, not finite or too elongated to bound safely.
  """
  a, b, c = conics[:, 0], conics[:, 1], conics[:, 2]
  det = a * c - b * b
  trace = a + c
  trusted = (det > 0.) & (trace * trace < MAX_ELONGATION * det) & jnp.isfinite(det)
  safe_det = jnp.where(trusted, det, 1.)
  s = jnp.log(jnp.maximum(opacities, 1e-30) / ALPHA_MIN)
  s = jnp.maximum(s, 0.) + REACH_SLACK

  def reach(diag):
    r = jnp.sqrt(2. * s * jnp.maximum(diag, 0.) / safe_det)
    r = r * (1. + REACH_SLACK) + REACH_SLACK
    return jnp.where(trusted, r, jnp.inf)

  visible = opacities >= ALPHA_MIN * (1. - 1e-5)
  return jnp.where(visible, reach(c), -1.), jnp.where(visible, reach(a), -1.)


def block_lists(tile_ids, means2d, conics, opacities, height, width, tile, block):
  """Splits tile lists among the blocks of their tiles (module docstring).

  Args:
    tile_ids: [T, L] Gaussian ids per tile, front to back; ids >= N are padding.
    means2d: [N, 2]. conics: [N, 3]. opacities: [N].
    height, width, tile, block: static ints (block divides tile).

  Returns:
    ids: [K, L] int32 per block (K = blocks_y * blocks_x), the ids of its tile's list
      that can reach it, in the list's order, padded at the end with N.
    length: [K] int32, the number of real ids per block.
  """
  means2d, conics, opacities = jax.lax.stop_gradient((means2d, conics, opacities))
  n = means2d.shape[0]
  num_tiles, length = tile_ids.shape
  tiles_y, tiles_x = tiles_lib.tile_grid(height, width, tile)
  m = tile // block
  rx, ry = alpha_reach(conics, opacities)
  real = tile_ids < n
  ids = jnp.where(real, tile_ids, 0)
  u, v = means2d[ids, 0], means2d[ids, 1]  # [T, L]
  rx, ry = rx[ids], ry[ids]
  ty, tx = jnp.divmod(jnp.arange(num_tiles), tiles_x)
  sy, sx = jnp.divmod(jnp.arange(m * m), m)
  dtype = means2d.dtype
  # First and last pixel centres of each block, [T, S, 1].
  x0 = (tx[:, None] * tile + sx[None, :] * block).astype(dtype)[..., None] + 0.5
  y0 = (ty[:, None] * tile + sy[None, :] * block).astype(dtype)[..., None] + 0.5
  x1, y1 = x0 + (block - 1), y0 + (block - 1)
  u, v, rx, ry, real = (z[:, None, :] for z in (u, v, rx, ry, real))
  hit = real & (u - rx <= x1) & (u + rx >= x0) & (v - ry <= y1) & (v + ry >= y0)
  pos = jnp.cumsum(hit, axis=-1, dtype=jnp.int32) - 1
  count = pos[..., -1] + 1 if length else jnp.zeros(hit.shape[:2], jnp.int32)
  shape = hit.shape  # [T, S, L]
  rows = jnp.arange(num_tiles * m * m).reshape(num_tiles, m * m, 1)
  out = jnp.full((num_tiles * m * m, length), n, jnp.int32)
  out = out.at[jnp.broadcast_to(rows, shape), jnp.where(hit, pos, length)].set(
      jnp.broadcast_to(tile_ids[:, None, :], shape).astype(jnp.int32), mode='drop')
  # [T, S] -> block grid row-major: (ty, tx, sy, sx) -> (ty, sy, tx, sx).
  order = lambda x: jnp.swapaxes(x.reshape((tiles_y, tiles_x, m, m) + x.shape[2:]),
                                 1, 2).reshape((-1,) + x.shape[2:])
  return order(out.reshape(num_tiles, m * m, length)), order(count)


def block_pixels(block, blocks_y, blocks_x, dtype=jnp.float32):
  """(px, py) [K, block^2] pixel centres of each block, row-major within the block."""
  by, bx = jnp.divmod(jnp.arange(blocks_y * blocks_x), blocks_x)
  qy, qx = jnp.divmod(jnp.arange(block * block), block)
  px = (bx[:, None] * block + qx[None, :]).astype(dtype) + 0.5
  py = (by[:, None] * block + qy[None, :]).astype(dtype) + 0.5
  return px, py


def blocks_to_image(x, height, width, block, blocks_y, blocks_x):
  """[K, block^2, ...] per-block pixels -> [H, W, ...] image (the padding cropped)."""
  x = x.reshape((blocks_y, blocks_x, block, block) + x.shape[2:])
  x = jnp.swapaxes(x, 1, 2).reshape((blocks_y * block, blocks_x * block) + x.shape[4:])
  return x[:height, :width]


def _block_range(centre, radius, reach, tile, block, size):
  """[lo, hi) block indices along one axis: blocks of the tiles that the open box
  centre +- radius overlaps (tiles.tile_overlap) whose pixel centres come within
  `reach` of the centre; `size` blocks in all."""
  m = tile // block
  lo_t = jnp.floor((centre - radius) / tile) * m
  hi_t = jnp.ceil((centre + radius) / tile) * m
  lo_r = jnp.ceil((centre - reach - block + 0.5) / block)
  hi_r = jnp.floor((centre + reach - 0.5) / block) + 1.
  clip = lambda x: jnp.clip(x, 0., size).astype(jnp.int32)
  return clip(jnp.maximum(lo_t, lo_r)), clip(jnp.minimum(hi_t, hi_r))


def _rect_counts(y0, y1, x0, x1, on, shape):
  """[rows, cols] int32: how many of the rectangles [y0, y1) x [x0, x1) where `on`
  hold each cell (a 2D difference array: four scatter-adds per rectangle, then two
  cumulative sums)."""
  rows, cols = shape
  empty = ~on | (y1 <= y0) | (x1 <= x0)
  d = jnp.zeros((rows + 1, cols + 1), jnp.int32)
  for y, x, sign in ((y0, x0, 1), (y0, x1, -1), (y1, x0, -1), (y1, x1, 1)):
    d = d.at[jnp.where(empty, rows + 1, y), x].add(sign, mode='drop')
  return jnp.cumsum(jnp.cumsum(d, 0), 1)[:rows, :cols]


def pair_lists(means2d, radius, conics, opacities, depths, valid, height, width, tile,
               block, capacity):
  """Block lists straight from the Gaussians: every (block, Gaussian) pair of
  `block_lists(tiles.tile_intersect(...))` (no tile cap), from one sort.

  In depth order (a stable argsort, nearest first, ties by id), each Gaussian emits one
  pair per block of its box (its tiles' blocks within its alpha reach) into a buffer
  of K * capacity pairs; a pair's key, block * N + depth rank, is unique, so one
  single-operand int32 sort groups the pairs by block in depth order. The pairs fill
  the buffer's first slots, so only the smallest of SIZE_STEPS prefixes that holds them
  is built and sorted (a lax.switch; the lists are the whole buffer's).

  Args:
    means2d: [N, 2]. radius: [N] (tile box). conics: [N, 3]. opacities: [N].
    depths: [N]. valid: [N] bool.
    height, width, tile, block: static ints.
    capacity: static; the buffer holds K * capacity pairs (K blocks) and each block
      list at most 2 * capacity ids. Where it binds, the farthest Gaussians are dropped.

  Returns:
    ids [K, 2 * capacity] int32 (padding N), length [K] int32 (ids kept per block),
    count [T] int32 (Gaussians whose box overlaps each tile, kept or not), bound [T]
    bool (some block of the tile lost Gaussians to the capacity).
  """
  means2d, radius, conics, opacities, depths = jax.lax.stop_gradient(
      (means2d, radius, conics, opacities, depths))
  n = means2d.shape[0]
  blocks_y, blocks_x = block_grid(height, width, tile, block)
  num_blocks = blocks_y * blocks_x
  if (num_blocks + 1) * n >= 2**31 - 1:
    raise ValueError(f'{num_blocks} blocks x {n} Gaussians overflow the int32 sort key')
  pairs, width_l = num_blocks * capacity, 2 * capacity
  order = jnp.argsort(jnp.where(valid, depths, jnp.inf), stable=True).astype(jnp.int32)
  u, v = means2d[order, 0], means2d[order, 1]
  r, ok = radius[order], valid[order]
  rx, ry = alpha_reach(conics[order], opacities[order])
  x0, x1 = _block_range(u, r, rx, tile, block, blocks_x)
  y0, y1 = _block_range(v, r, ry, tile, block, blocks_y)
  span = jnp.maximum(x1 - x0, 0)
  num = jnp.where(ok & (rx >= 0.), span * jnp.maximum(y1 - y0, 0), 0)
  start = jnp.cumsum(num) - num  # First pair of each Gaussian, in depth order.
  total = start[-1] + num[-1] if n else jnp.zeros((), jnp.int32)

  def lists(size):
    """ids, kept from the first `size` (>= min(total, pairs)) slots of the buffer."""
    # Pair m belongs to the last Gaussian (rank s) starting at or before m.
    first = jnp.zeros((size,), jnp.int32).at[start].max(jnp.arange(n, dtype=jnp.int32),
                                                       mode='drop')
    s = jax.lax.cummax(first)
    j = jnp.arange(size, dtype=jnp.int32) - start[s]
    by, bx = jnp.divmod(j, jnp.maximum(span[s], 1))
    key = (y0[s] + by) * (blocks_x * n) + (x0[s] + bx) * n + s
    key = jnp.sort(jnp.where(jnp.arange(size) < total, key, jnp.iinfo(jnp.int32).max))
    bounds = jnp.searchsorted(key, jnp.arange(num_blocks + 1, dtype=jnp.int32) * n)
    kept = bounds[1:] - bounds[:-1]
    slot = jnp.arange(width_l, dtype=jnp.int32)
    at = jnp.minimum(bounds[:-1, None] + slot, size - 1)
    return jnp.where(slot < kept[:, None], order[key[at] % n], n), kept

  # The pairs fill the buffer's first `total` slots (the rest sort last): only the
  # smallest of these prefixes that holds them is built and sorted.
  sizes = sorted({max(-(-pairs * 2**16 // round(2**(16 + k / 2))), 1)
                  for k in range(SIZE_STEPS)})
  which = jnp.sum(jnp.asarray(sizes[:-1], jnp.int32) < total) if len(sizes) > 1 else 0
  ids, kept = jax.lax.switch(which, [lambda z=z: lists(z) for z in sizes])
  # What was dropped: true pair counts per block against the kept ones.
  want = _rect_counts(y0, y1, x0, x1, ok & (rx >= 0.), (blocks_y, blocks_x)).ravel()
  lost = (want > jnp.minimum(kept, width_l)).reshape(blocks_y, blocks_x)
  m = tile // block
  tiles_y, tiles_x = blocks_y // m, blocks_x // m
  bound = jnp.any(lost.reshape(tiles_y, m, tiles_x, m), axis=(1, 3)).ravel()
  tx0 = jnp.clip(jnp.floor((u - r) / tile), 0, tiles_x).astype(jnp.int32)
  tx1 = jnp.clip(jnp.ceil((u + r) / tile), 0, tiles_x).astype(jnp.int32)
  ty0 = jnp.clip(jnp.floor((v - r) / tile), 0, tiles_y).astype(jnp.int32)
  ty1 = jnp.clip(jnp.ceil((v + r) / tile), 0, tiles_y).astype(jnp.int32)
  count = _rect_counts(ty0, ty1, tx0, tx1, ok, (tiles_y, tiles_x)).ravel()
  return ids, jnp.minimum(kept, width_l), count, bound
