"""Throughput of the Laplace Hessian pass (renerf_jax.uncertainty.laplace.hessian_diagonal), today's
pass against the previous one, side by side in one process.

The previous pass (stop 25, kept below as `previous_hessian_diagonal`) moved all 9
per-entry contributions through a 10-operand sort per ray and padded the last chunk up to
`--chunk` rays. Today's sorts the vertex ids with their positions only and splits the rays
into even chunks (laplace.balanced_chunk) and Kahan-adds each chunk only at the vertices
it touches (laplace.sparse_kahan_add). Both give the same diagonal up to float32
summation order; the script checks it (`max_rel_diff`). A second table splits one of
today's chunks into its parts.

Each config is timed over --rays training rays of its scene, after one compile call per
pass, alternating the two passes --repeats times and keeping the best of each (the CPU
is shared). Timings do not depend on the parameter values, so the field is freshly
initialised. Writes <out>.json and <out>.md:

  python -m benchmarks.bench_hessian --configs experiments/configs/table_converged2.gin \
      experiments/configs/llff3_10min.gin --rays 8883 16384 --out benchmarks/results/hessian_stop26
"""
import argparse
import dataclasses
import functools
import json
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks.bench_throughput import time_calls
from experiments.tables import command_line
from renerf_jax import report
from renerf_jax.nerf import model
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene, ray_pool
from renerf_jax.nerf.fields import init_field_params
from renerf_jax.uncertainty import laplace
from renerf_jax.uncertainty.deformation import grid_size, trilinear_corners


def previous_per_ray_vertex_jtj(sens, means, lo, hi, n: int):
  """laplace.per_ray_vertex_jtj as of stop 25: the 9 contributions ride the sort."""
  ids, w = trilinear_corners(means, lo, hi, n)
  rows = ids.shape[0] * ids.shape[1]
  k = ids.shape[2] * ids.shape[3]
  vals = jnp.einsum('clbsa,lbsk->lbskca', sens, w).reshape(rows, k, 9)
  ids = ids.reshape(rows, k)
  sorted_ops = jax.lax.sort((ids,) + tuple(vals[..., j] for j in range(9)), dimension=1,
                            num_keys=1)
  ids_sorted = sorted_ops[0]
  vals_sorted = jnp.stack(sorted_ops[1:], axis=-1)
  new_seg = jnp.concatenate([jnp.ones((rows, 1), bool),
                             ids_sorted[:, 1:] != ids_sorted[:, :-1]], axis=1)
  seg = jnp.cumsum(new_seg, axis=1, dtype=jnp.int32) - 1
  seg = (seg + k * jnp.arange(rows, dtype=jnp.int32)[:, None]).reshape(-1)
  m = rows * k
  totals = jax.ops.segment_sum(vals_sorted.reshape(m, 9), seg, num_segments=m,
                               indices_are_sorted=True)
  seg_ids = jnp.zeros((m,), jnp.int32).at[seg].set(ids_sorted.reshape(-1))
  return seg_ids, jnp.sum(totals.reshape(m, 3, 3)**2, axis=1)


@functools.partial(jax.jit, static_argnums=(0, 1), donate_argnums=(7, 8))
def _previous_chunk(config, log2_res, params, rays, valid, lo, hi, total, comp):
  sens, means = laplace.sample_sensitivities(config, params, rays, valid)
  seg_ids, sq = previous_per_ray_vertex_jtj(sens, means, lo, hi, 2**log2_res)
  part = jnp.zeros(total.shape, jnp.float32).at[seg_ids].add(sq)
  return laplace.kahan_add(total, comp, part)


def previous_hessian_diagonal(config, params, rays, lo, hi, log2_res, lam, chunk):
  """laplace.hessian_diagonal as of stop 25: chunks of `chunk` rays, the last padded."""
  cfg = dataclasses.replace(config, stop_level_grad=True)
  num = int(rays.origins.shape[0])
  chunk = max(1, min(chunk, num))
  lo = jnp.asarray(lo, jnp.float32) * jnp.ones(3, jnp.float32)
  hi = jnp.asarray(hi, jnp.float32) * jnp.ones(3, jnp.float32)
  total = jnp.zeros((grid_size(log2_res), 3), jnp.float32)
  comp = jnp.zeros_like(total)
  for start in range(0, num, chunk):
    idx, valid = laplace._chunk_indices(num, start, chunk)  # pylint: disable=protected-access
    part = jax.tree_util.tree_map(lambda x, idx=idx: jnp.take(x, idx, axis=0), rays)
    total, comp = _previous_chunk(cfg, log2_res, params, part, jnp.asarray(valid), lo, hi,
                                  total, comp)
  return (2. / num) * (total - comp) + 2. * lam


def chunk_parts(config, params, rays, lo, hi, log2_res, chunk, repeats):
  """Seconds of today's chunk by part (best of repeats, each part jitted alone).

  Parts: the forward render of the chunk; the sensitivities (that forward plus one VJP
  per colour channel); the per-ray vertex sums (per_ray_vertex_jtj); the accumulation
  (sparse_kahan_add into the (2^L + 1)^3 table).
  """
  cfg = dataclasses.replace(config, stop_level_grad=True)
  part = jax.tree_util.tree_map(lambda x: x[:chunk], rays)
  b = int(part.origins.shape[0])
  valid = jnp.ones((b,), jnp.float32)
  lo, hi = jnp.asarray(lo, jnp.float32), jnp.asarray(hi, jnp.float32)
  zeros = jnp.zeros((model.colour_levels(cfg), b, cfg.num_samples, 3), jnp.float32)
  forward = jax.jit(lambda p, r: laplace._render_level_rgb(cfg, p, r, zeros))  # pylint: disable=protected-access
  sens_fn = jax.jit(lambda p, r: laplace.sample_sensitivities(cfg, p, r, valid))
  sums_fn = jax.jit(lambda s, m: laplace.per_ray_vertex_jtj(s, m, lo, hi, 2**log2_res))
  acc_fn = jax.jit(laplace.sparse_kahan_add, donate_argnums=(0, 1, 2))
  table = lambda: jnp.zeros((grid_size(log2_res), 3), jnp.float32)

  best = lambda fn: time_calls(fn, repeats, reduce=min)
  sens, means = sens_fn(params, part)
  ids, sq = sums_fn(sens, means)
  t_fwd = best(lambda: forward(params, part))
  t_sens = best(lambda: sens_fn(params, part))
  t_sums = best(lambda: sums_fn(sens, means))
  t_acc = best(lambda: acc_fn(table(), table(), table(), ids, sq))
  t_tables = best(lambda: (table(), table(), table()))
  return {'rays': b, 'forward_s': t_fwd, 'sensitivities_s': t_sens,
          'per_ray_sums_s': t_sums, 'accumulate_s': max(t_acc - t_tables, 0.)}


def scene_box(scene, rays):
  """The grid box: the NDC cube, or (bench only) the bounding box of the rays' segments."""
  if scene.use_ndc:
    return -np.ones(3, np.float32), np.ones(3, np.float32)
  ends = [np.asarray(rays.origins + t * rays.directions) for t in (rays.near, rays.far)]
  pts = np.concatenate(ends)
  return pts.min(0), pts.max(0)


def bench_config(path, bindings, n_rays, chunk, log2_res, repeats):
  """Times both passes on one config; returns one row (dict)."""
  config = load_config([path], bindings)
  chunk = chunk or config.hessian_chunk
  log2_res = config.deform_log2_res if log2_res is None else log2_res
  scene = load_scene(config)
  pool = ray_pool(scene, scene.train_idx)['rays']
  rays = laplace.subsample_rays(pool, n_rays, config.seed)
  n_rays = int(rays.origins.shape[0])
  lo, hi = scene_box(scene, rays)
  params = init_field_params(config, jax.random.PRNGKey(config.seed))
  passes = {
      'previous': lambda: previous_hessian_diagonal(config, params, rays, lo, hi, log2_res,
                                                    config.hessian_lambda, chunk),
      'today': lambda: laplace.hessian_diagonal(config, params, rays, lo, hi, log2_res,
                                                config.hessian_lambda, chunk=chunk)}
  first, best, out = {}, {}, {}
  for name, fn in passes.items():  # The first call compiles.
    t0 = time.perf_counter()
    out[name] = np.asarray(jax.block_until_ready(fn()))
    first[name] = time.perf_counter() - t0
    best[name] = float('inf')
  for _ in range(repeats):
    for name, fn in passes.items():
      t0 = time.perf_counter()
      jax.block_until_ready(fn())
      best[name] = min(best[name], time.perf_counter() - t0)
  seen = out['previous'] - 2. * config.hessian_lambda
  diff = np.max(np.abs(out['today'] - out['previous'])) / max(float(np.max(seen)), 1e-30)
  balanced = laplace.balanced_chunk(n_rays, chunk)
  return {
      'config': os.path.basename(path), 'bindings': bindings, 'scene': config.scene,
      'rays': n_rays, 'chunk': chunk,
      'rays_computed_previous': -(-n_rays // min(chunk, n_rays)) * min(chunk, n_rays),
      'rays_computed_today': -(-n_rays // balanced) * balanced, 'log2_res': log2_res,
      'vertices': grid_size(log2_res), 'samples': model.samples_label(config),
      'first_call_s_previous': first['previous'], 'first_call_s_today': first['today'],
      's_previous': best['previous'], 's_today': best['today'],
      'rays_per_s_previous': n_rays / best['previous'],
      'rays_per_s_today': n_rays / best['today'],
      'speedup': best['previous'] / best['today'], 'max_rel_diff': float(diff),
      'finite': bool(np.all(np.isfinite(out['today']))),
      'parts': chunk_parts(config, params, rays, lo, hi, log2_res, balanced, repeats)}


def markdown(rows, command):
  lines = ['# Hessian pass: today against the previous (stop 25), side by side', '',
           f'Backend: {jax.default_backend()}. Best of the alternating repeats; first call '
           'includes compilation.', '',
           '| config | scene | rays | chunk | rays computed (previous / today) | samples | '
           'previous s | today s | previous rays/s | today rays/s | speed-up | first call s '
           '(previous / today) | max rel diff |',
           '|---|---|---|---|---|---|---|---|---|---|---|---|---|']
  for r in rows:
    lines.append(
        f"| {r['config']} | {r['scene']} | {r['rays']} | {r['chunk']} | "
        f"{r['rays_computed_previous']} / {r['rays_computed_today']} | {r['samples']} | "
        f"{r['s_previous']:.2f} | {r['s_today']:.2f} | {r['rays_per_s_previous']:.0f} | "
        f"{r['rays_per_s_today']:.0f} | {r['speedup']:.2f} | "
        f"{r['first_call_s_previous']:.1f} / {r['first_call_s_today']:.1f} | "
        f"{r['max_rel_diff']:.1e} |")
  lines += ['', "Where today's chunk spends its time (each part jitted and timed alone, "
            'best of the repeats; the sensitivities include their forward render):', '',
            '| config | rays/chunk | forward s | sensitivities s | per-ray sums s | '
            'accumulate s | sensitivities share |', '|---|---|---|---|---|---|---|']
  for r in rows:
    q = r['parts']
    whole = q['sensitivities_s'] + q['per_ray_sums_s'] + q['accumulate_s']
    lines.append(f"| {r['config']} | {q['rays']} | {q['forward_s']:.2f} | "
                 f"{q['sensitivities_s']:.2f} | {q['per_ray_sums_s']:.2f} | "
                 f"{q['accumulate_s']:.3f} | {q['sensitivities_s'] / whole:.0%} |")
  return '\n'.join(lines + ['', 'Command:', '', '    ' + command, ''])


def main(argv=None):
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument('--configs', nargs='+', required=True, help='gin config files')
  parser.add_argument('--gin_bindings', action='append', default=[])
  parser.add_argument('--rays', type=int, nargs='+', default=[1024],
                      help='training rays timed, one per config (or one for all)')
  parser.add_argument('--chunk', type=int, default=None,
                      help='most rays per jitted chunk (default Config.hessian_chunk)')
  parser.add_argument('--log2_res', type=int, default=None,
                      help='grid resolution L (default Config.deform_log2_res)')
  parser.add_argument('--repeats', type=int, default=3)
  parser.add_argument('--out', default='benchmarks/results/hessian')
  args = parser.parse_args(argv)
  if len(args.rays) not in (1, len(args.configs)):
    parser.error(f'--rays takes one value or one per config ({len(args.configs)}), '
                 f'got {len(args.rays)}')
  rays = args.rays * len(args.configs) if len(args.rays) == 1 else args.rays
  rows = []
  for path, n in zip(args.configs, rays):
    rows.append(bench_config(path, args.gin_bindings, n, args.chunk, args.log2_res,
                             args.repeats))
    print(json.dumps(rows[-1]), flush=True)
  command = command_line('benchmarks.bench_hessian', argv)
  report.write_json(args.out + '.json', {'rows': rows, 'command': command})
  report.write_markdown(args.out + '.md', markdown(rows, command))
  return rows


if __name__ == '__main__':
  main()
