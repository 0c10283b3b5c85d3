"""Rays/s of the train step, the render step and the Hessian pass, per config.

python -m benchmarks.bench_throughput --configs gin_configs/llff3_cpu.gin \
    gin_configs/llff3_fast.gin gin_configs/llff3.gin

For each config and stage, on the configured scene with freshly initialised parameters
(the cost does not depend on their values):
  train    one jitted training step (batch rays + random-pose patch rays, fwd + bwd) at
           step --train_at * max_steps (default 0: the annealed sampling interval is
           narrow, so a grid's rate is an upper bound; 0.5: after the annealing);
  render   one jitted chunk of Config.render_chunk rays (forward, coarse + fine: what
           eval and pseudo-view synthesis run);
  hessian  one jitted chunk of Config.hessian_chunk rays of the Laplace Gauss-Newton diagonal
           w.r.t. the (2^L + 1)^3 deformation grid (L = Config.deform_log2_res).
Seconds per call are the median of --repeats calls after warm-up calls; GFLOP per call is
XLA's cost analysis of the compiled function; efficiency = achieved GFLOP/s / the measured
float32 matmul GFLOP/s of this CPU; the speed-up of a stage is its rays/s over the first
config's in the same run. Writes JSON and a markdown table (--out). Run it on an
idle machine: a second job on the 2 cores halves every rate.
"""
import argparse
import dataclasses
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks.bench_train_step import matmul_gflops
from experiments.tables import command_line
from renerf_jax import report
from renerf_jax.nerf import model, training
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene, ray_pool
from renerf_jax.nerf.fields import init_field_params
from renerf_jax.nerf.rendering import _render_chunk
from renerf_jax.nerf.pools import make_pools
from renerf_jax.uncertainty import deformation, laplace


def time_calls(fn, repeats, warmups=1, reduce=np.median):
  """Median (or `reduce`, e.g. min) seconds of `repeats` calls of fn() after `warmups`
  calls (the second call of a step that donates its state can compile again for the
  returned arrays' layout)."""
  for _ in range(warmups):
    jax.block_until_ready(fn())
  times = []
  for _ in range(repeats):
    t = time.perf_counter()
    jax.block_until_ready(fn())
    times.append(time.perf_counter() - t)
  return float(reduce(times))


def xla_cost(compiled):
  """(GFLOP, GB accessed) of one call of a compiled executable (NaN where XLA does not say)."""
  cost = compiled.cost_analysis()
  cost = (cost[0] if cost else {}) if isinstance(cost, (list, tuple)) else cost
  return (float(cost.get('flops', float('nan'))) / 1e9,
          float(cost.get('bytes accessed', float('nan'))) / 1e9)


def _compile(jitted, *args):
  """(compile seconds, GFLOP of one call) of a jitted function at these arguments."""
  t = time.perf_counter()
  compiled = jitted.lower(*args).compile()
  seconds = time.perf_counter() - t
  return seconds, xla_cost(compiled)[0]


def _row(config, stage, rays, sec, gflop, compile_s):
  return {'stage': stage, 'rays': int(rays), 'sec_per_call': sec, 'rays_per_s': rays / sec,
          'samples_per_s': rays * sum(model.level_samples(config)) / sec,
          'gflop_per_call': gflop, 'achieved_gflops': gflop / sec, 'compile_s': compile_s,
          'field': config.field,
          'samples': model.samples_label(config)}


def bench_train(config, scene, repeats, at_fraction=0.):
  pools = make_pools(config, scene, None)
  cam = training.Camera.of(scene)
  state = training.init_state(config, jax.random.PRNGKey(0))
  # At step 0 the annealed samples crowd into a sliver of each ray, which a grid's gathers
  # find in cache; past the annealing they spread over the whole interval.
  state = state.replace(step=jnp.asarray(int(at_fraction * config.max_steps), jnp.int32))
  key = jax.random.PRNGKey(0)
  compile_s, gflop = _compile(training.train_step, config, cam, 0, state, pools, key)
  holder = [state]  # train_step donates its state: thread it through the calls.

  def step():
    holder[0], stats = training.train_step(config, cam, False, holder[0], pools, key)
    return stats

  sec = time_calls(step, repeats, warmups=2)
  rays = config.batch_size + (config.batch_size_random if config.depth_tv_loss_mult > 0
                              else 0)
  return _row(config, 'train', rays, sec, gflop, compile_s)


def bench_render(config, rays, params, repeats):
  n = config.render_chunk
  part = jax.tree_util.tree_map(lambda x: x[:n], rays)
  compile_s, gflop = _compile(_render_chunk, config, params, part)
  sec = time_calls(lambda: _render_chunk(config, params, part), repeats)
  return _row(config, 'render', n, sec, gflop, compile_s)


def bench_hessian(config, scene, rays, params, chunk, repeats):
  cfg = dataclasses.replace(config, stop_level_grad=True)
  log2_res = config.deform_log2_res
  lo, hi = (np.asarray(b, np.float32) for b in scene.bbox)
  part = jax.tree_util.tree_map(lambda x: x[:chunk], rays)
  valid = np.ones((chunk,), np.float32)
  zeros = lambda: np.zeros((deformation.grid_size(log2_res), 3), np.float32)
  args = lambda: (cfg, log2_res, params, part, valid, lo, hi, zeros(), zeros(), zeros())
  # pylint: disable=protected-access
  compile_s, gflop = _compile(laplace._hessian_chunk, *args())
  sec = time_calls(lambda: laplace._hessian_chunk(*args()), repeats)
  row = _row(config, 'hessian', chunk, sec, gflop, compile_s)
  row['samples'] += f', grid 2^{log2_res}+1'
  return row


def bench_config(path, bindings, repeats, hessian_chunk, stages, train_at=0.):
  """Rows of one config; `path` is a gin file or several joined by commas (a base and
  its modifiers, e.g. gin_configs/llff3_fast.gin,gin_configs/modifiers/no_anneal.gin)."""
  config = load_config(path.split(','), bindings)
  scene = load_scene(config)
  hessian_chunk = hessian_chunk or config.hessian_chunk
  pool = ray_pool(scene, scene.train_idx)['rays']
  perm = np.random.default_rng(0).permutation(pool.origins.shape[0])
  rays = jax.tree_util.tree_map(lambda x: x[perm[:max(config.render_chunk,
                                                       hessian_chunk)]], pool)
  params = init_field_params(config, jax.random.PRNGKey(0))
  rows = []
  if 'train' in stages:
    rows.append(bench_train(config, scene, repeats, train_at))
  if 'render' in stages:
    rows.append(bench_render(config, rays, params, repeats))
  if 'hessian' in stages:
    rows.append(bench_hessian(config, scene, rays, params, hessian_chunk, repeats))
  for row in rows:
    row['config'] = '+'.join(os.path.basename(p) for p in path.split(','))
    print(row, flush=True)
  return rows


def add_speedups(rows):
  """Sets row['speedup']: its rays/s over the first config's rays/s in the same stage
  (both measured in this run, so the ratio holds while absolute rates drift with load)."""
  first = {}
  for row in rows:
    first.setdefault(row['stage'], row['rays_per_s'])
    row['speedup'] = row['rays_per_s'] / first[row['stage']]


def write_table(rows, roof, out, command):
  """Markdown table of the rows next to the matmul roof; returns its text."""
  table = report.markdown_table(rows, [
      ('config', 'config'), ('field', 'field'), ('samples', 'samples/ray'),
      ('stage', 'stage'), ('rays', 'rays/call'), ('sec_per_call', 's/call'),
      ('rays_per_s', 'rays/s'), ('samples_per_s', 'samples/s'),
      ('gflop_per_call', 'GFLOP/call'), ('achieved_gflops', 'GFLOP/s'),
      ('flop_efficiency', 'of matmul roof'), ('speedup', 'rays/s vs first config'),
      ('compile_s', 'compile s')], floatfmt={
          'sec_per_call': '.3f', 'speedup': '.2f', 'rays_per_s': '.0f', 'samples_per_s': '.0f',
          'gflop_per_call': '.1f', 'achieved_gflops': '.1f', 'flop_efficiency': '.1%',
          'compile_s': '.1f'})
  text = (f'Matmul roof (float32 2048^2, best of 5): {roof:.1f} GFLOP/s\n\n{table}\n\n'
          f'Command:\n\n    {command}\n')
  report.write_markdown(out + '.md', text)
  return text


def main(argv=None):
  p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  p.add_argument('--configs', nargs='+', default=['gin_configs/llff3_cpu.gin',
                                                  'gin_configs/llff3_fast.gin'])
  p.add_argument('--gin_bindings', action='append', default=[])
  p.add_argument('--stages', nargs='+', default=['train', 'render', 'hessian'],
                 choices=['train', 'render', 'hessian'])
  p.add_argument('--repeats', type=int, default=5)
  p.add_argument('--hessian_chunk', type=int, default=None,
                 help='rays per Hessian chunk (default Config.hessian_chunk)')
  p.add_argument('--train_at', type=float, default=0.,
                 help='time the train step at this fraction of max_steps')
  p.add_argument('--out', default='benchmarks/results/throughput')
  args = p.parse_args(argv)
  roof = matmul_gflops()
  rows = []
  for path in args.configs:
    rows += bench_config(path, args.gin_bindings, args.repeats, args.hessian_chunk,
                         args.stages, args.train_at)
  add_speedups(rows)
  for row in rows:
    row['flop_efficiency'] = row['achieved_gflops'] / roof
  command = command_line('benchmarks.bench_throughput', argv)
  os.makedirs(os.path.dirname(args.out) or '.', exist_ok=True)
  report.write_json(args.out + '.json', {'matmul_gflops': roof,
                                         'device': str(jax.devices()[0]),
                                         'rows': rows, 'command': command})
  print(write_table(rows, roof, args.out, command))
  return rows


if __name__ == '__main__':
  main()
