"""Laplace diagonal of a trained NeRF w.r.t. a deformation grid, in the style of Bayes' Rays.

A zero-initialised deformation field theta on the vertex grid of uncertainty.deformation
perturbs the sample positions of the trained model: x -> x + trilinear(theta, x). A
Laplace approximation of the posterior over theta (Gauss-Newton Hessian of the mean
squared photometric error, plus an isotropic Gaussian prior of precision lambda) gives a
per-vertex variance (uncertainty.masks renders it into per-pixel uncertainty).

Conventions (the vertex grid and clamping are uncertainty.deformation's):
  * Hessian: diag(H) = 2 / R sum_r sum_levels diag(J_r^T J_r) + 2 lambda, J_r the Jacobian
    of ray r's rendered rgb [3] of one level w.r.t. theta at theta = 0. Coarse and fine
    levels count separately (their J^T J are added); the fine sample positions are held
    fixed (stop-gradient w.r.t. the coarse weights, as in mip-NeRF training). With the
    proposal sampler (Config.sampler = 'proposal') only the fine level renders colour,
    so the sum has one level: the diagonal is about half the coarse-to-fine one, and a
    hessian_lambda or mask threshold chosen for two levels weighs twice as much.
  * Sigma = 1 / diag(H) per axis; a vertex's sigma is the L2 norm of its per-axis standard
    deviations, sqrt(Sigma_x + Sigma_y + Sigma_z). A vertex no ray sees has the prior
    sigma sqrt(3 / (2 lambda)).
"""
import dataclasses
import functools
import time

import jax
import jax.numpy as jnp
import numpy as np

from renerf_jax import distributed
from renerf_jax.nerf import mip
from renerf_jax.nerf.model import colour_levels, render_rays
from renerf_jax.progress import progress_bar
from renerf_jax.uncertainty.deformation import grid_size, trilinear_corners


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
  """Renders rays with a per-sample offset added to the sample means of every level that
  renders colour.

  Args:
    config: Config. params: field parameters. rays: Rays [B].
    deltas: [colour levels, B, S, 3] offsets, one per level that renders colour
      (model.colour_levels: with the proposal sampler, the fine level only; the proposal
      samples are not deformed: the fine positions are held fixed w.r.t. them anyway).

  Returns:
    (rgb [colour levels, B, 3], t_vals [colour levels, B, S + 1]).
  """
  first = config.num_levels - colour_levels(config)
  offsets = lambda level, means: deltas[level - first] if level >= first else 0.
  levels = render_rays(config, params, rays, jax.random.PRNGKey(0), train=False,
                       offsets=offsets)[first:]
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
    (sens [3 (channel), levels, B, S, 3 (axis)] = d rgb_{l,b,c} / d x_{l,b,s,a},
     means [levels, B, S, 3] the undeformed sample means), over the levels that render
    colour (model.colour_levels).
  """
  b = rays.origins.shape[0]
  deltas = jnp.zeros((colour_levels(config), b, config.num_samples, 3), jnp.float32)
  fn = functools.partial(_render_level_rgb, config, params, rays)
  _, vjp_fn, t_vals = jax.vjp(fn, deltas, has_aux=True)
  sens = []
  for c in range(3):
    cot = jnp.zeros((colour_levels(config), b, 3), jnp.float32).at[:, :, c].set(valid)
    sens.append(vjp_fn(cot)[0])
  means, _ = mip.cast_rays(t_vals, rays.origins, rays.directions, rays.radii,
                           config.ray_shape)
  return jnp.stack(sens), means


def per_ray_vertex_jtj(sens, means, lo, hi, n: int):
  """diag(J^T J) contributions of each (level, ray) to the vertices, summed per vertex
  within the ray before squaring.

  The Jacobian of rgb_c w.r.t. vertex v's offset on axis a is sum_i sens[c, i, a] w_i(v)
  over the ray's samples i (w_i(v) the trilinear weight of v at sample i). Each row's 8 S
  vertex ids are sorted (ids only, with their positions: the 9 contributions per entry
  are not moved through the sort), equal ids numbered as one segment, and each entry's
  contributions segment-summed in place; the totals are squared and summed over channels.

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
  row = jnp.arange(rows, dtype=jnp.int32)[:, None]
  pos = jnp.broadcast_to(jnp.arange(k, dtype=jnp.int32), (rows, k))
  ids_sorted, perm = jax.lax.sort((ids, pos), dimension=1, num_keys=1)
  new_seg = jnp.concatenate([jnp.ones((rows, 1), bool),
                             ids_sorted[:, 1:] != ids_sorted[:, :-1]], axis=1)
  seg_sorted = jnp.cumsum(new_seg, axis=1, dtype=jnp.int32) - 1 + k * row
  seg = jnp.zeros((rows, k), jnp.int32).at[row, perm].set(seg_sorted).reshape(-1)
  m = rows * k
  totals = jax.ops.segment_sum(vals.reshape(m, 9), seg, num_segments=m)
  seg_ids = jnp.zeros((m,), jnp.int32).at[seg].set(ids.reshape(-1))
  sq = jnp.sum(totals.reshape(m, 3, 3)**2, axis=1)  # Sum over colour channels.
  return seg_ids, sq


def sparse_kahan_add(total, comp, scratch, ids, vals):
  """Adds vals at ids (repeats allowed) to a compensated accumulator, touching only ids.

  The terms are first summed per vertex in float32 by a scatter-add into `scratch` (all
  zeros outside a call), then each touched vertex's sum is added to (total, comp) with
  kahan_add, and scratch is zeroed again at ids. Repeated ids gather the same values
  and write the same results, so the outcome does not depend on the order of writes. Cost
  is proportional to len(ids), not to the table size.

  Args:
    total, comp: [V, C] Kahan accumulator (see kahan_add). scratch: [V, C] zeros.
    ids: [M] int32 rows. vals: [M, C] terms.

  Returns:
    (new total, new comp, scratch: zeros again).
  """
  scratch = scratch.at[ids].add(vals)
  t, c = kahan_add(total[ids], comp[ids], scratch[ids])
  return total.at[ids].set(t), comp.at[ids].set(c), scratch.at[ids].set(0.)


@functools.partial(jax.jit, static_argnums=(0, 1), donate_argnums=(7, 8, 9))
def _hessian_chunk(config, log2_res, params, rays, valid, lo, hi, total, comp, scratch):
  """Adds one chunk's sum of diag(J^T J) to the compensated accumulator.

  Args:
    config: static Config (stop_level_grad=True). log2_res: static L.
    params: field parameters. rays: Rays [B]. valid: [B] 1 real ray, 0 padding.
    lo, hi: [3] box. total, comp: [V, 3] Kahan accumulator; scratch: [V, 3] zeros (all
      three donated).

  Returns:
    (new total, new comp, scratch), as sparse_kahan_add.
  """
  n = 2**log2_res
  sens, means = sample_sensitivities(config, params, rays, valid)
  seg_ids, sq = per_ray_vertex_jtj(sens, means, lo, hi, n)
  return sparse_kahan_add(total, comp, scratch, seg_ids, sq)


def balanced_chunk(num: int, chunk: int) -> int:
  """The chunk size that covers num rays in as few chunks as `chunk` allows, evenly.

  ceil(num / c) chunks of c = ceil(num / ceil(num / chunk)) rays: at most one padded
  ray per chunk instead of up to chunk - 1 in the last one (8883 rays in chunks of 8192
  would otherwise compute 16384).

  Args:
    num: rays in all (>= 1). chunk: the largest chunk allowed (>= 1).

  Returns:
    c, 1 <= c <= min(chunk, num).
  """
  chunks = -(-num // max(1, min(chunk, num)))
  return -(-num // chunks)


def _chunk_indices(num: int, start: int, chunk: int):
  """Indices of one chunk of rays, the last ray repeated as padding.

  Args:
    num: rays in all (>= 1). start: first ray of the chunk. chunk: chunk size.

  Returns:
    (indices [chunk] int, valid [chunk] float32: 1 for rays start..num - 1, 0 padding).
  """
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
  summation in float32 on the device (sparse_kahan_add: only at the vertices the chunk
  touches), so millions of rays neither overflow nor drop small terms, and the [V, 3]
  accumulator never leaves the device. With several processes (renerf_jax.distributed)
  each sums every P-th chunk and the P compensated sums are added in process order
  (one all-gather of the [V, 3] accumulator): the same sum to float32 rounding, not bit
  for bit (the chunks are added in another order).

  Args:
    config: Config. params: field parameters of the trained model.
    rays: flat Rays [R] (training rays).
    lo, hi: [3] box of the deformation grid (NDC cube for LLFF, scene box for Blender).
    log2_res: L; the grid has (2^L + 1)^3 vertices.
    lam: prior precision lambda > 0.
    chunk: the most rays per jitted chunk; the rays are split into as few chunks as
      that allows, of equal size (balanced_chunk; the last is padded with zero weight).
    show_progress: draw a bar (rays, rate, ETA).

  Returns:
    [(2^L + 1)^3, 3] float32 diagonal (x-major vertex order, xyz offset axes).
  """
  cfg = dataclasses.replace(config, stop_level_grad=True)
  num = int(rays.origins.shape[0])
  chunk = balanced_chunk(num, chunk)
  lo = jnp.asarray(lo, jnp.float32) * jnp.ones(3, jnp.float32)
  hi = jnp.asarray(hi, jnp.float32) * jnp.ones(3, jnp.float32)
  total = jnp.zeros((grid_size(log2_res), 3), jnp.float32)
  comp = jnp.zeros_like(total)
  scratch = jnp.zeros_like(total)
  params = distributed.local(params)
  bar = progress_bar(total=num, desc='Hessian', disable=not show_progress, unit='ray')
  for k in distributed.share(-(-num // chunk)):  # All chunks with one process.
    idx, valid = _chunk_indices(num, k * chunk, chunk)
    part = jax.tree_util.tree_map(lambda x, idx=idx: jnp.take(x, idx, axis=0), rays)
    total, comp, scratch = _hessian_chunk(cfg, log2_res, params, part, jnp.asarray(valid),
                                          lo, hi, total, comp, scratch)
    bar.update(int(valid.sum()))
  bar.close()
  return (2. / num) * distributed.sum_over_processes(total - comp) + 2. * lam


# --------------------------------------------------------------- per-vertex sigma


def prior_sigma(lam: float) -> float:
  """Sigma of a vertex no ray sees.

  Args:
    lam: prior precision lambda > 0.

  Returns:
    ||sqrt(1 / (2 lam)) * (1, 1, 1)|| = sqrt(3 / (2 lam)).
  """
  return float(np.sqrt(3. / (2. * lam)))


def vertex_sigma(h_diag):
  """Per-vertex uncertainty from the Hessian diagonal.

  Args:
    h_diag: [V, 3] diag(H) > 0 (lambda > 0 guarantees it).

  Returns:
    [V] sqrt(sum_a 1 / H_a): the L2 norm of the per-axis standard deviations.
  """
  return jnp.sqrt(jnp.sum(1. / h_diag, axis=-1))


def subsample_rays(rays, num: int, seed: int):
  """num rays of a flat pool drawn without replacement with a fixed seed (all if fewer).

  Args:
    rays: flat Rays [R]. num: rays wanted. seed: seed of the draw.

  Returns:
    Rays [min(num, R)] in pool order (rays itself when num >= R).
  """
  total = int(rays.origins.shape[0])
  if num >= total:
    return rays
  idx = np.sort(np.random.default_rng(seed).permutation(total)[:num])
  return jax.tree_util.tree_map(lambda x: jnp.take(x, idx, axis=0), rays)


def vertex_sigma_pass(config, params, train_rays, lo, hi, chunk, show_progress=False):
  """The Hessian pass: per-vertex sigma of the trained model, timed.

  Uses config.deform_log2_res and config.hessian_lambda. Not memoised (a caller that runs
  the same pass several times can wrap it; see masks.compute_masks' sigma_fn).

  Args:
    config: Config. params: trained field parameters.
    train_rays: flat Rays [R] (the subsampled training rays).
    lo, hi: [3] box of the deformation grid.
    chunk: rays per jitted chunk of hessian_diagonal.
    show_progress: draw a bar over the rays.

  Returns:
    (sigma [V] float32 on the device, wall seconds of the pass, until sigma is ready).
  """
  t0 = time.perf_counter()
  h_diag = hessian_diagonal(config, params, train_rays, lo, hi, config.deform_log2_res,
                            config.hessian_lambda, chunk=chunk, show_progress=show_progress)
  sigma = jax.block_until_ready(vertex_sigma(h_diag))
  return sigma, time.perf_counter() - t0
