"""Laplace uncertainty of a trained NeRF in the style of Bayes' Rays, and pseudo-view masks.

A zero-initialised deformation field theta (3D offsets on a dense (n + 1)^3 vertex grid,
n = 2^L, over an axis-aligned box [lo, hi]) perturbs the sample positions of the trained
model: x -> x + trilinear(theta, x). A Laplace approximation of the posterior over theta
(Gauss-Newton Hessian of the mean squared photometric error, plus an isotropic Gaussian
prior of precision lambda) gives a per-vertex variance; its spatial interpolation,
volume-rendered along pseudo-view rays, is the per-pixel uncertainty U that Re-Nerfing
thresholds to mask unreliable pseudo-view pixels.

Conventions used throughout:
  * Vertex grid: `values` tables are [(n + 1)^3, C], flattened x-major: vertex (i, j, k)
    (i along x, k along z) is row (i * (n + 1) + j) * (n + 1) + k.
  * Clamping: points outside the box are clamped onto it before interpolation, so the
    deformation field is extended constantly outward from the box faces (samples outside
    the box move with the nearest boundary vertices, and those vertices collect their
    sensitivities).
  * Hessian: diag(H) = 2 / R sum_r sum_levels diag(J_r^T J_r) + 2 lambda, J_r the Jacobian
    of ray r's rendered rgb [3] of one level w.r.t. theta at theta = 0. Coarse and fine
    levels count separately (their J^T J are added); the fine sample positions are held
    fixed (stop-gradient w.r.t. the coarse weights, as in mip-NeRF training).
  * Sigma = 1 / diag(H) per axis; a vertex's sigma is the L2 norm of its per-axis standard
    deviations, sqrt(Sigma_x + Sigma_y + Sigma_z). A vertex no ray sees has the prior
    sigma sqrt(3 / (2 lambda)).
  * Rendered uncertainty: U = sum_i w_i U(x_i) + (1 - acc) U_bg with the fine level's
    weights, U(x) = trilinear(sigma, x), and U_bg = the prior sigma by default (the part
    of a ray that hits nothing is as uncertain as unseen space).
  * Masks: 1 keeps a pixel (U <= mu), 0 masks it (U > mu).
"""
import dataclasses
import functools
import time
from typing import NamedTuple, Optional

import jax
import jax.numpy as jnp
import jaxopt
import numpy as np

from renerf_jax import memo, mip
from renerf_jax.model import materialize, render_rays
from renerf_jax.progress import progress_bar

# Corner offsets of a cell, in the order of the flattened vertex index (x-major).
_CORNERS = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], np.int32)


# --------------------------------------------------------------- deformation grid


def grid_size(log2_res: int) -> int:
  """Number of vertices (2^L + 1)^3 of the deformation grid of resolution L."""
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
  """The deformation x -> x + trilinear(offsets, x), the `warp` hook of render_rays.

  Args:
    offsets: [(n + 1)^3, 3] vertex offsets (zeros: the identity, bit for bit).
    lo, hi: [3] box corners.

  Returns:
    function means [..., 3] -> deformed means [..., 3].
  """
  return lambda means: means + trilinear(offsets, means, lo, hi)


# --------------------------------------------------------------- compensated sums


def kahan_add(total, comp, x):
  """One step of Kahan (compensated) summation, elementwise.

  Args:
    total: running sum. comp: running compensation (minus the lost low-order part).
    x: the term to add. All the same shape.

  Returns:
    (new total, new comp); the accurate sum is total - comp.
  """
  y = x - comp
  t = total + y
  return t, (t - total) - y


# --------------------------------------------------------------- Hessian diagonal


def _render_level_rgb(config, params, rays, deltas):
  """Renders rays with a per-sample offset added to every level's sample means.

  Args:
    config: Config. params: field parameters. rays: Rays [B].
    deltas: [num_levels, B, S, 3] offsets (level l's are added to level l's means).

  Returns:
    (rgb [num_levels, B, 3], t_vals [num_levels, B, S + 1]).
  """
  per_level = iter([deltas[l] for l in range(deltas.shape[0])])
  warp = lambda means: means + next(per_level)  # render_rays warps levels in order.
  levels = render_rays(config, params, rays, jax.random.PRNGKey(0), train=False, warp=warp)
  return (jnp.stack([lv['rgb'] for lv in levels]),
          jnp.stack([lv['t_vals'] for lv in levels]))


def sample_sensitivities(config, params, rays, valid):
  """Per-sample sensitivities of each level's colour to an offset of the sample position.

  One forward pass and one batched VJP per colour channel c (of sum_r valid_r rgb_r,c
  over all levels): with the fine sample positions fixed w.r.t. the coarse weights, level
  l's rgb depends only on level l's offsets, so one VJP gives every level's own Jacobian.

  Args:
    config: Config with stop_level_grad=True (required for the above).
    params: field parameters. rays: Rays [B].
    valid: [B] 1 for real rays, 0 for padding (its sensitivities are 0).

  Returns:
    (sens [3 (channel), num_levels, B, S, 3 (axis)] = d rgb_{l,b,c} / d x_{l,b,s,a},
     means [num_levels, B, S, 3] the undeformed sample means).
  """
  b = rays.origins.shape[0]
  deltas = jnp.zeros((config.num_levels, b, config.num_samples, 3), jnp.float32)
  fn = functools.partial(_render_level_rgb, config, params, rays)
  _, vjp_fn, t_vals = jax.vjp(fn, deltas, has_aux=True)
  sens = []
  for c in range(3):
    cot = jnp.zeros((config.num_levels, b, 3), jnp.float32).at[:, :, c].set(valid)
    sens.append(vjp_fn(cot)[0])
  means, _ = mip.cast_rays(t_vals, rays.origins, rays.directions, rays.radii,
                           config.ray_shape)
  return jnp.stack(sens), means


def per_ray_vertex_jtj(sens, means, lo, hi, n: int):
  """diag(J^T J) contributions of each (level, ray) to the vertices, summed per vertex
  within the ray before squaring.

  The Jacobian of rgb_c w.r.t. vertex v's offset on axis a is sum_i sens[c, i, a] w_i(v)
  over the ray's samples i (w_i(v) the trilinear weight of v at sample i). Each row's 8 S
  (vertex id, contribution) pairs are sorted by id, equal ids segment-summed, and the
  totals squared and summed over channels.

  Args:
    sens: [3, levels, B, S, 3] from sample_sensitivities.
    means: [levels, B, S, 3] sample positions.
    lo, hi: box corners. n: static cells per axis.

  Returns:
    (vertex ids [M] int32, squared totals [M, 3]) with M = levels * B * 8 S; entries of
    unused segment slots are 0 (their id is 0).
  """
  ids, w = trilinear_corners(means, lo, hi, n)  # [L, B, S, 8]
  rows = ids.shape[0] * ids.shape[1]
  k = ids.shape[2] * ids.shape[3]
  vals = jnp.einsum('clbsa,lbsk->lbskca', sens, w).reshape(rows, k, 9)
  ids = ids.reshape(rows, k)
  sorted_ops = jax.lax.sort((ids,) + tuple(vals[..., j] for j in range(9)), dimension=1,
                            num_keys=1)
  ids_sorted = sorted_ops[0]
  vals_sorted = jnp.stack(sorted_ops[1:], axis=-1)  # [rows, K, 9]
  new_seg = jnp.concatenate([jnp.ones((rows, 1), bool),
                             ids_sorted[:, 1:] != ids_sorted[:, :-1]], axis=1)
  seg = jnp.cumsum(new_seg, axis=1, dtype=jnp.int32) - 1
  seg = (seg + k * jnp.arange(rows, dtype=jnp.int32)[:, None]).reshape(-1)
  m = rows * k
  totals = jax.ops.segment_sum(vals_sorted.reshape(m, 9), seg, num_segments=m,
                               indices_are_sorted=True)
  seg_ids = jnp.zeros((m,), jnp.int32).at[seg].set(ids_sorted.reshape(-1))
  sq = jnp.sum(totals.reshape(m, 3, 3)**2, axis=1)  # Sum over colour channels.
  return seg_ids, sq


@functools.partial(jax.jit, static_argnums=(0, 1), donate_argnums=(7, 8))
def _hessian_chunk(config, log2_res, params, rays, valid, lo, hi, total, comp):
  """Adds one chunk's sum of diag(J^T J) [V, 3] to the compensated accumulator."""
  n = 2**log2_res
  sens, means = sample_sensitivities(config, params, rays, valid)
  seg_ids, sq = per_ray_vertex_jtj(sens, means, lo, hi, n)
  part = jnp.zeros(total.shape, jnp.float32).at[seg_ids].add(sq)
  return kahan_add(total, comp, part)


def _chunk_indices(num: int, start: int, chunk: int):
  """Indices [chunk] of rays start.. (the last ray repeated as padding) and validity."""
  idx = np.arange(start, start + chunk)
  valid = (idx < num).astype(np.float32)
  return np.minimum(idx, num - 1), valid


def hessian_diagonal(config, params, rays, lo, hi, log2_res: int, lam: float,
                     chunk: int = 1024, show_progress: bool = False):
  """Gauss-Newton / Laplace diagonal of the Hessian w.r.t. the deformation grid.

  diag(H) = 2 / R sum_r sum_levels diag(J_r^T J_r) + 2 lam, at the trained model
  (theta = 0), rendered deterministically (train=False). No dense Jacobian is formed
  (see sample_sensitivities and per_ray_vertex_jtj). The fine sample positions are held
  fixed w.r.t. the coarse weights whatever config.stop_level_grad says (the forward
  values are the same; only the linearisation is defined that way).

  Precision: each chunk's sum is accumulated in float32 by a scatter-add (at most
  chunk * levels * 8 S terms), and the chunk sums are added with Kahan compensated
  summation in float32 on the device, so millions of rays neither overflow nor drop small
  terms, and the [V, 3] accumulator never leaves the device.

  Args:
    config: Config. params: field parameters of the trained model.
    rays: flat Rays [R] (training rays).
    lo, hi: [3] box of the deformation grid (NDC cube for LLFF, scene box for Blender).
    log2_res: L; the grid has (2^L + 1)^3 vertices.
    lam: prior precision lambda > 0.
    chunk: rays per jitted chunk (static; the last chunk is padded with zero weight).
    show_progress: draw a bar (rays, rate, ETA).

  Returns:
    [(2^L + 1)^3, 3] float32 diagonal (x-major vertex order, xyz offset axes).
  """
  cfg = dataclasses.replace(config, stop_level_grad=True)
  num = int(rays.origins.shape[0])
  chunk = max(1, min(chunk, num))
  lo = jnp.asarray(lo, jnp.float32) * jnp.ones(3, jnp.float32)
  hi = jnp.asarray(hi, jnp.float32) * jnp.ones(3, jnp.float32)
  total = jnp.zeros((grid_size(log2_res), 3), jnp.float32)
  comp = jnp.zeros_like(total)
  bar = progress_bar(total=num, desc='Hessian', disable=not show_progress, unit='ray')
  for start in range(0, num, chunk):
    idx, valid = _chunk_indices(num, start, chunk)
    part = jax.tree_util.tree_map(lambda x, idx=idx: jnp.take(x, idx, axis=0), rays)
    total, comp = _hessian_chunk(cfg, log2_res, params, part, jnp.asarray(valid), lo, hi,
                                 total, comp)
    bar.update(int(valid.sum()))
  bar.close()
  return (2. / num) * (total - comp) + 2. * lam


def _level_rgbs(config, params, rays, lo, hi, theta):
  """Every level's rgb [levels, R, 3] with the deformation theta [V * 3] applied."""
  warp = make_warp(theta.reshape(-1, 3), lo, hi)
  levels = render_rays(config, params, rays, jax.random.PRNGKey(0), train=False, warp=warp)
  return jnp.stack([lv['rgb'] for lv in levels])


@functools.partial(jax.jit, static_argnums=(0, 1))
def _dense_hessian_diagonal(config, log2_res, params, rays, lo, hi, target):
  """diag of jax.hessian of 1/R sum ||rgb(theta) - target||^2 at theta = 0, [V, 3]."""
  num = rays.origins.shape[0]
  loss = lambda th: jnp.sum((_level_rgbs(config, params, rays, lo, hi, th) - target)**2) / num
  theta0 = jnp.zeros((grid_size(log2_res) * 3,), jnp.float32)
  return jnp.diag(jax.hessian(loss)(theta0)).reshape(-1, 3)


def reference_hessian_diagonals(config, params, rays, lo, hi, log2_res: int,
                                gt_rgb=None):
  """Dense jax.hessian reference (small grids and few rays only: O(V) passes).

  GN objective g(theta) = 1/R sum_levels sum_r ||rgb_r(theta) - sg(rgb_r(0))||^2, whose
  Hessian at 0 is exactly 2/R sum_levels J^T J; optionally the true squared-error loss
  f(theta) = 1/R sum_levels sum_r ||rgb_r(theta) - gt_r||^2 (Hessian = GN + residual-
  weighted second derivatives of the renderer). Neither includes the prior 2 lambda.
  The fine sample positions are held fixed w.r.t. the coarse weights, as in
  hessian_diagonal.

  Args:
    config: Config. params: field parameters. rays: flat Rays [R].
    lo, hi: box. log2_res: L.
    gt_rgb: optional ground-truth colours, [R, 3] (the same target for every level) or
      [levels, R, 3], for the true Hessian.

  Returns:
    dict with 'gn' [V, 3] and, if gt_rgb is given, 'true' [V, 3] Hessian diagonals.
  """
  cfg = dataclasses.replace(config, stop_level_grad=True)
  lo = jnp.asarray(lo, jnp.float32) * jnp.ones(3, jnp.float32)
  hi = jnp.asarray(hi, jnp.float32) * jnp.ones(3, jnp.float32)
  theta0 = jnp.zeros((grid_size(log2_res) * 3,), jnp.float32)
  rgb0 = jax.jit(_level_rgbs, static_argnums=0)(cfg, params, rays, lo, hi, theta0)
  out = {'gn': _dense_hessian_diagonal(cfg, log2_res, params, rays, lo, hi, rgb0)}
  if gt_rgb is not None:
    target = jnp.broadcast_to(jnp.asarray(gt_rgb, jnp.float32), rgb0.shape)
    out['true'] = _dense_hessian_diagonal(cfg, log2_res, params, rays, lo, hi, target)
  return out


# --------------------------------------------------------------- uncertainty


def prior_sigma(lam: float) -> float:
  """Sigma of a vertex no ray sees: ||sqrt(1 / (2 lam)) * (1, 1, 1)|| = sqrt(3 / (2 lam))."""
  return float(np.sqrt(3. / (2. * lam)))


def vertex_sigma(h_diag):
  """Per-vertex uncertainty from the Hessian diagonal.

  Args:
    h_diag: [V, 3] diag(H) > 0 (lambda > 0 guarantees it).

  Returns:
    [V] sqrt(sum_a 1 / H_a): the L2 norm of the per-axis standard deviations.
  """
  return jnp.sqrt(jnp.sum(1. / h_diag, axis=-1))


@functools.partial(jax.jit, static_argnums=(0,))
def _uncertainty_chunk(config, params, sigma, rays, lo, hi, u_bg):
  """Fine-level volume rendering of trilinear(sigma) plus the background term."""
  fine = render_rays(config, params, rays, jax.random.PRNGKey(0), train=False)[-1]
  means, _ = mip.cast_rays(fine['t_vals'], rays.origins, rays.directions, rays.radii,
                           config.ray_shape)
  means = materialize(means)  # Computed once, not once per trilinear corner.
  u_points = trilinear(sigma[:, None], means, lo, hi)[..., 0]  # [B, S]
  u = jnp.sum(fine['weights'] * u_points, axis=-1)
  u = u + jnp.clip(1. - fine['acc'], 0., 1.) * u_bg
  return u, fine['rgb']


def render_uncertainty(config, params, sigma, rays, lo, hi, chunk: int = 4096,
                       u_bg: Optional[float] = None, log_scale: bool = False,
                       show_progress: bool = False, desc: str = 'uncertainty'):
  """Per-ray uncertainty U = sum_i w_i U(x_i) + (1 - acc) U_bg over the fine level.

  The colour comes out of the same pass, so pseudo-views with masks cost one render.

  Args:
    config: Config. params: field parameters.
    sigma: [V] per-vertex sigma (vertex_sigma).
    rays: flat Rays [N].
    lo, hi: box of the grid.
    chunk: rays per jitted chunk (last chunk padded).
    u_bg: uncertainty of the part of the ray that hits nothing (default: the largest
      vertex sigma, which is the prior sigma whenever some vertex is unseen; pass
      prior_sigma(lambda) to make it explicit).
    log_scale: return log U (Bayes' Rays visualises / thresholds log U; a keep-fraction
      threshold is the same either way, an absolute one is not).
    show_progress: draw a bar (rays, rate, ETA). desc: its label.

  Returns:
    (u [N], rgb [N, 3]) host numpy float32 arrays.
  """
  sigma = jnp.asarray(sigma, jnp.float32)
  if u_bg is None:
    u_bg = float(jnp.max(sigma))
  num = int(rays.origins.shape[0])
  chunk = max(1, min(chunk, num))
  lo = jnp.asarray(lo, jnp.float32) * jnp.ones(3, jnp.float32)
  hi = jnp.asarray(hi, jnp.float32) * jnp.ones(3, jnp.float32)
  us, rgbs = [], []
  bar = progress_bar(total=num, desc=desc, disable=not show_progress, unit='ray')
  for start in range(0, num, chunk):
    idx, valid = _chunk_indices(num, start, chunk)
    part = jax.tree_util.tree_map(lambda x, idx=idx: jnp.take(x, idx, axis=0), rays)
    u, rgb = _uncertainty_chunk(config, params, sigma, part, lo, hi,
                                jnp.float32(u_bg))
    m = int(valid.sum())
    us.append(np.asarray(u[:m]))
    rgbs.append(np.asarray(rgb[:m]))
    bar.update(m)
  bar.close()
  u = np.concatenate(us)
  if log_scale:
    u = np.log(np.maximum(u, np.finfo(np.float32).tiny))
  return u, np.concatenate(rgbs)


# --------------------------------------------------------------- thresholds and masks


@jax.jit
def _bisect_threshold(u, k):
  """jaxopt.Bisection for the k-th smallest of u [N] (1 <= k <= N, traced int)."""
  num = u.shape[0]
  # (count(u <= mu) - k + 1/2) / N = mean(u <= mu) - (k - 1/2) / N; counted in int32 so
  # it is exact for any N, and never 0: a clean sign change at the k-th smallest u.
  fn = lambda mu: (jnp.sum(u <= mu, dtype=jnp.int32) - k + 0.5) / num
  lower = jnp.nextafter(jnp.min(u), -jnp.inf)  # f < 0: nothing kept.
  upper = jnp.max(u)  # f > 0: everything kept.
  solver = jaxopt.Bisection(optimality_fun=fn, lower=lower, upper=upper, maxiter=200,
                            tol=0., check_bracket=False, jit=True)
  return solver.run().state.high


def threshold_for_keep_fraction(u, keep_frac: float):
  """The threshold mu that keeps a target fraction of pixels (U <= mu kept).

  Solves f(mu) = mean(U <= mu) - keep_frac = 0 with jaxopt.Bisection on the bracket
  [min U, max U]. f is a monotone step function, so the target is shifted half a step,
  (k - 1/2) / N with k = ceil(keep_frac N), which puts the sign change exactly at the
  k-th smallest U; the upper end of the bracket is returned (it always keeps >= k pixels).
  Tolerance: tol = 0 and 200 halvings, i.e. the bracket shrinks until its ends are
  adjacent float32 numbers, so exactly k pixels are kept unless U has ties at u_(k) (the
  kept fraction is then within 1 / N of the target, or above it by the tie count).

  Args:
    u: [N] finite uncertainties (any leading shape; flattened).
    keep_frac: target fraction in [0, 1]; <= 0 masks everything (mu below min U),
      >= 1 keeps everything (mu = max U).

  Returns:
    float mu.
  """
  u = jnp.asarray(u, jnp.float32).reshape(-1)
  if keep_frac <= 0.:
    return float(jnp.nextafter(jnp.min(u), -jnp.inf))
  if keep_frac >= 1.:
    return float(jnp.max(u))
  k = min(max(int(np.ceil(keep_frac * u.shape[0] - 1e-9)), 1), u.shape[0])
  return float(_bisect_threshold(u, jnp.int32(k)))


def masks_from_uncertainty(u, mu):
  """Float masks: 1 keeps a pixel (U <= mu), 0 masks it (U > mu).

  mu = inf keeps everything; mu = 0 (or below min U; U > 0) masks everything.

  Args:
    u: [...] uncertainties. mu: scalar threshold.

  Returns:
    [...] float32 mask.
  """
  return (jnp.asarray(u) <= mu).astype(jnp.float32)


def subsample_rays(rays, num: int, seed: int):
  """num rays of a flat pool drawn without replacement with a fixed seed (all if fewer)."""
  total = int(rays.origins.shape[0])
  if num >= total:
    return rays
  idx = np.sort(np.random.default_rng(seed).permutation(total)[:num])
  return jax.tree_util.tree_map(lambda x: jnp.take(x, idx, axis=0), rays)


class Masks(NamedTuple):
  """Result of compute_masks (host numpy arrays shaped like the pseudo rays)."""
  uncertainty: np.ndarray  # [...] rendered U.
  mask: np.ndarray  # [...] 1 keeps a pixel, 0 masks it.
  mu: float  # The threshold.
  rgb: np.ndarray  # [..., 3] the fine colour, rendered in the same pass as U.
  hessian_seconds: float  # Wall time of the Hessian pass (of the first, when cached).
  hessian_cached: bool = False  # The pass was shared (cached_vertex_sigma).


# Config fields that choose or use the pseudo-views but cannot change the Hessian pass
# (the seed acts only through the subsampled training rays, which are part of the key).
HESSIAN_IRRELEVANT_FIELDS = ('interp_factors', 'sequencing', 'pseudo_targets',
                             'pseudo_n_random', 'mask_keep_frac', 'mask_threshold',
                             'num_rounds', 'pseudo_frac', 'pseudo_until', 'pseudo_schedule',
                             'renerf_init', 'seed')
HESSIAN_CACHE_SIZE = 4
_HESSIAN_CACHE = memo.LruCache(max_items=HESSIAN_CACHE_SIZE)  # key -> (sigma, seconds)


def hessian_cache_key(config, params, train_rays, lo, hi, chunk):
  """Digest of everything the Hessian pass depends on (see cached_vertex_sigma)."""
  return memo.digest(memo.config_key(config, HESSIAN_IRRELEVANT_FIELDS), np.int64(chunk),
                     params, train_rays, lo, hi)


def cached_vertex_sigma(config, params, train, lo, hi, chunk, show_progress=False):
  """Per-vertex sigma of the Hessian pass, memoised within the process.

  The variants of a view-selection table share one baseline per seed and differ only in
  which pseudo-views they render: they need the same Hessian. The last
  HESSIAN_CACHE_SIZE results are kept (a (2^8 + 1)^3 grid: 68 MB each), keyed on the
  digest of the params, the subsampled training rays, the box and the config without
  HESSIAN_IRRELEVANT_FIELDS.

  Returns:
    (sigma [V], seconds of the pass that computed it, whether it came from the cache).
  """
  key = hessian_cache_key(config, params, train, lo, hi, chunk)
  hit = _HESSIAN_CACHE.get(key)
  if hit is not None:
    sigma, seconds = hit
    return sigma, seconds, True
  t0 = time.perf_counter()
  h_diag = hessian_diagonal(config, params, train, lo, hi, config.deform_log2_res,
                            config.hessian_lambda, chunk=chunk, show_progress=show_progress)
  sigma = jax.block_until_ready(vertex_sigma(h_diag))
  seconds = time.perf_counter() - t0
  _HESSIAN_CACHE.put(key, (sigma, seconds))
  return sigma, seconds, False


def compute_masks(config, params, train_rays, pseudo_rays, lo, hi,
                  hessian_chunk: Optional[int] = None, show_progress: bool = False) -> Masks:
  """Uncertainty masks of pseudo-view pixels (the Re-Nerfing + Bayes' Rays step).

  Uses config.deform_log2_res, config.hessian_rays (training rays drawn with
  config.seed), config.hessian_lambda, config.mask_threshold (>= 0: absolute mu) or else
  config.mask_keep_frac (mu by bisection), and config.render_chunk. U_bg is the prior
  sigma sqrt(3 / (2 lambda)). The pseudo-view colours come out of the uncertainty render,
  so masked pseudo-views cost the Hessian pass plus one render, not two renders.

  Args:
    config: Config. params: trained field parameters.
    train_rays: Rays of the training pool (any leading shape; flattened).
    pseudo_rays: Rays of the pseudo-view pixels, leading shape [...] (e.g. [M, H, W]).
    lo, hi: [3] box of the deformation grid.
    hessian_chunk: rays per chunk of the Hessian pass (default config.hessian_chunk).
    show_progress: draw bars over the Hessian rays and the pseudo rays.

  Returns:
    Masks.
  """
  flat = lambda r: jax.tree_util.tree_map(lambda x: x.reshape((-1, x.shape[-1])), r)
  shape = pseudo_rays.origins.shape[:-1]
  train = subsample_rays(flat(train_rays), config.hessian_rays, config.seed)
  lam = config.hessian_lambda
  sigma, hessian_seconds, cached = cached_vertex_sigma(
      config, params, train, lo, hi, hessian_chunk or config.hessian_chunk, show_progress)
  u, rgb = render_uncertainty(config, params, sigma, flat(pseudo_rays), lo,
                              hi, chunk=config.render_chunk, u_bg=prior_sigma(lam),
                              show_progress=show_progress,
                              desc=(f'pseudo-views + uncertainty ({shape[0]})'
                                    if len(shape) == 3 else 'uncertainty'))
  if config.mask_threshold >= 0:
    mu = float(config.mask_threshold)
  else:
    mu = threshold_for_keep_fraction(u, config.mask_keep_frac)
  mask = np.asarray(masks_from_uncertainty(u, mu))
  return Masks(uncertainty=u.reshape(shape), mask=mask.reshape(shape), mu=float(mu),
               rgb=rgb.reshape(shape + (3,)), hessian_seconds=hessian_seconds,
               hessian_cached=cached)
