"""The Bayes' Rays deformation grid: trilinear interpolation of a vertex table in a box.

A deformation field theta (3D offsets on a dense (n + 1)^3 vertex grid, n = 2^L, over an
axis-aligned box [lo, hi]) moves the sample positions of a trained model:
x -> x + trilinear(theta, x). The same interpolation spreads per-vertex uncertainties
over space (uncertainty.masks, uncertainty.signals).

Conventions:
  * Vertex grid: `values` tables are [(n + 1)^3, C], flattened x-major: vertex (i, j, k)
    (i along x, k along z) is row (i * (n + 1) + j) * (n + 1) + k.
  * Clamping: points outside the box are clamped onto it before interpolation, so the
    deformation field is extended constantly outward from the box faces (samples outside
    the box move with the nearest boundary vertices, and those vertices collect their
    sensitivities).
"""
import jax.numpy as jnp
import numpy as np

# Corner offsets of a cell, in the order of the flattened vertex index (x-major).
_CORNERS = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], np.int32)


def grid_size(log2_res: int) -> int:
  """Number of vertices (2^L + 1)^3 of the deformation grid of resolution L.

  Args:
    log2_res: L.

  Returns:
    (2^L + 1)^3.
  """
  return (2**log2_res + 1)**3


def cells_of(num_vertices: int) -> int:
  """Cells per axis n of a flattened table with (n + 1)^3 rows.

  Args:
    num_vertices: static number of rows of the table.

  Returns:
    n >= 1.

  Raises:
    ValueError: if num_vertices is not (n + 1)^3 with n >= 1.
  """
  m = int(round(num_vertices**(1. / 3.)))
  if m**3 != num_vertices or m < 2:
    raise ValueError(f'a vertex table needs (n + 1)^3 rows with n >= 1, got {num_vertices}')
  return m - 1


def trilinear_corners(points, lo, hi, n: int):
  """Flat vertex ids and trilinear weights of the 8 cell corners around each point.

  Points are clamped into the box first, so a point outside it gets the corners and
  weights of its projection onto the box. The weights are >= 0 and sum to 1.

  Args:
    points: [..., 3] positions.
    lo, hi: [3] (or scalar) box corners, hi > lo.
    n: static cells per axis (the grid has n + 1 vertices per axis).

  Returns:
    (ids [..., 8] int32 rows of the x-major flattened table, weights [..., 8]).
  """
  lo = jnp.asarray(lo, points.dtype)
  hi = jnp.asarray(hi, points.dtype)
  u = jnp.clip((points - lo) / (hi - lo) * n, 0., float(n))
  cell = jnp.clip(jnp.floor(u), 0., float(n - 1))
  frac = u - cell
  ijk = cell.astype(jnp.int32)[..., None, :] + _CORNERS  # [..., 8, 3]
  ids = (ijk[..., 0] * (n + 1) + ijk[..., 1]) * (n + 1) + ijk[..., 2]
  weights = jnp.prod(jnp.where(_CORNERS == 1, frac[..., None, :], 1. - frac[..., None, :]),
                     axis=-1)
  return ids, weights


def trilinear(values, points, lo, hi):
  """Trilinear interpolation of a vertex table at points (one gather for all corners).

  Args:
    values: [(n + 1)^3, C] table, x-major flattened (see module docstring).
    points: [..., 3] positions; points outside [lo, hi] are clamped onto the box.
    lo, hi: [3] (or scalar) box corners.

  Returns:
    [..., C] interpolated values.
  """
  n = cells_of(values.shape[0])
  ids, weights = trilinear_corners(points, lo, hi, n)
  corner_values = jnp.take(values, ids.reshape(-1), axis=0, mode='clip')
  corner_values = corner_values.reshape(ids.shape + values.shape[-1:])
  return jnp.sum(weights[..., None] * corner_values, axis=-2)


def make_warp(offsets, lo, hi):
  """The deformation x -> x + trilinear(offsets, x), as render_rays' `offsets` hook.

  Args:
    offsets: [(n + 1)^3, 3] vertex offsets (zeros: the identity, bit for bit).
    lo, hi: [3] box corners.

  Returns:
    function (level, means [..., 3]) -> offsets [..., 3] added to the means (the same
    field at every level).
  """
  return lambda level, means: trilinear(offsets, means, lo, hi)
