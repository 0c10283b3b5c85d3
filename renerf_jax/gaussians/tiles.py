"""Tile intersection: which Gaussians touch which 16x16 tile, front to back, capped.

Static shapes: the image is cut into T = ceil(H / tile) * ceil(W / tile) tiles in
row-major order (tile t covers columns [tx * tile, (tx + 1) * tile) and rows
[ty * tile, (ty + 1) * tile), t = ty * tiles_x + tx), and each tile keeps at most `cap`
Gaussians, the nearest ones.

Cost: a dense [T, N] depth-key matrix and a top-k per tile, O(T N) time and memory
(e.g. 1200 tiles x 1e5 Gaussians = 1.2e8 keys, ~0.5 GB in float32), fine for small images
and N up to ~1e5, unlike the sort-by-(tile, depth) key of the CUDA reference.
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

  Args:
    means2d: [N, 2] pixel centres of the Gaussians. radius: [N] pixel radii.
    depths: [N] view depths (the sort key, nearest first).
    valid: [N] bool; invalid Gaussians touch nothing.
    height, width, tile, cap: static ints.

  Returns:
    ids: [T, cap] int32 Gaussian ids sorted front to back (ties: lower id first), padded
      with the sentinel N, which the rasteriser skips.
    count: [T] int32, how many Gaussians touch each tile; count > cap means the cap bound
      and the farthest count - cap of them were dropped.
  """
  means2d, radius, depths = jax.lax.stop_gradient((means2d, radius, depths))
  n = means2d.shape[0]
  overlap = tile_overlap(means2d, radius, valid, height, width, tile)
  key = jnp.where(overlap, depths, jnp.inf)
  if cap > n:
    key = jnp.pad(key, ((0, 0), (0, cap - n)), constant_values=jnp.inf)
  neg_key, ids = jax.lax.top_k(-key, cap)
  ids = jnp.where(jnp.isfinite(neg_key), ids, n).astype(jnp.int32)
  count = jnp.sum(overlap, axis=1, dtype=jnp.int32)
  return ids, count
