"""Tile intersection: which Gaussians touch which 16x16 tile, front to back.

`render` uses these lists with a tile cap (Config.gs_tile_cap > 0); without one it
builds 8x8 block lists directly (blocks.pair_lists), whose every pair is one of these
lists' (tests/test_gaussians_raster.py).

Static shapes: the image is cut into T = ceil(H / tile) * ceil(W / tile) tiles in
row-major order (tile t covers columns [tx * tile, (tx + 1) * tile) and rows
[ty * tile, (ty + 1) * tile), t = ty * tiles_x + tx), and each tile keeps a list of
static length: every Gaussian that touches it (no cap, length N), or at most `cap`, the
nearest ones.

Cost: O(T N) time and memory in a handful of dense [T, N] arrays (overlap, positions,
ids, scatter indices: about 1.3 GB at 768 tiles x 1e5 Gaussians, 0.25 GB at the 20000
slots of the configs), fine for small images and N up to a few 1e4, unlike the flat
sort-by-(tile, depth) key of the CUDA reference, whose length is dynamic.
"""
import functools

import jax
import jax.numpy as jnp


def tile_grid(height, width, tile=16):
  """(tiles_y, tiles_x) of an image: ceil(H / tile), ceil(W / tile)."""
  return -(-height // tile), -(-width // tile)


def tile_overlap(means2d, radius, valid, height, width, tile=16):
  """[T, N] bool: the box centre +- radius of Gaussian n overlaps tile t.

  The overlap is of open intervals, as gsplat's tile range [floor((u - r) / tile),
  ceil((u + r) / tile)) in each axis.
  """
  tiles_y, tiles_x = tile_grid(height, width, tile)
  ty, tx = jnp.divmod(jnp.arange(tiles_y * tiles_x), tiles_x)
  x0, y0 = (tx * tile).astype(means2d.dtype), (ty * tile).astype(means2d.dtype)
  u, v = means2d[:, 0], means2d[:, 1]
  return (valid[None, :] &
          (x0[:, None] < u + radius) & (x0[:, None] + tile > u - radius) &
          (y0[:, None] < v + radius) & (y0[:, None] + tile > v - radius))


@functools.partial(jax.jit, static_argnames=('height', 'width', 'tile', 'cap'))
def tile_intersect(means2d, radius, depths, valid, height, width, tile=16, cap=64):
  """Per tile, the ids of the (at most `cap`) nearest Gaussians touching it.

  One depth sort of all Gaussians, then each tile's overlapping ones are packed in that
  order (a running count per tile): O(N log N + T N), no per-tile sort.

  Args:
    means2d: [N, 2] pixel centres of the Gaussians. radius: [N] pixel radii.
    depths: [N] view depths (the sort key, nearest first).
    valid: [N] bool; invalid Gaussians touch nothing.
    height, width, tile: static ints.
    cap: static list length; 0 or None: N (no cap, every overlap is kept).

  Returns:
    ids: [T, cap or N] int32 Gaussian ids sorted front to back (ties: lower id first),
      padded with the sentinel N, which the rasteriser skips.
    count: [T] int32, how many Gaussians touch each tile; count > cap means the cap bound
      and the farthest count - cap of them were dropped.
  """
  means2d, radius, depths = jax.lax.stop_gradient((means2d, radius, depths))
  n = means2d.shape[0]
  length = cap if cap else n
  overlap = tile_overlap(means2d, radius, valid, height, width, tile)
  order = jnp.argsort(jnp.where(valid, depths, jnp.inf), stable=True).astype(jnp.int32)
  hit = overlap[:, order]  # [T, N] in depth order.
  pos = jnp.cumsum(hit, axis=1, dtype=jnp.int32) - 1
  pos = jnp.where(hit, pos, length)  # Misses (and overflow beyond the cap) are dropped.
  rows = jnp.broadcast_to(jnp.arange(hit.shape[0])[:, None], hit.shape)
  ids = jnp.full((hit.shape[0], length), n, jnp.int32)
  ids = ids.at[rows, pos].set(jnp.broadcast_to(order, hit.shape), mode='drop')
  count = jnp.sum(overlap, axis=1, dtype=jnp.int32)
  return ids, count
