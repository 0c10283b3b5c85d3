"""Train-step throughput of configs, next to this CPU's matmul roof.

python -m benchmarks.bench_train_step --configs gin_configs/llff3_cpu.gin gin_configs/llff3.gin

For each config: compile time, seconds per step (median of --steps after one warm-up),
rays/s (batch rays + random-pose patch rays), XLA's FLOP count of the compiled step and the
FLOP efficiency = achieved FLOP/s / measured matmul FLOP/s. Writes JSON and a markdown table
to benchmarks/results/ (or --out).
"""
import argparse
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

from experiments.tables import command_line
from renerf_jax import report
from renerf_jax.nerf import model, training
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene
from renerf_jax.nerf.pools import make_pools


def matmul_gflops(n=2048, repeats=5):
  """Best float32 n x n matmul rate on this machine, GFLOP/s."""
  a = jnp.asarray(np.random.default_rng(0).normal(size=(n, n)), jnp.float32)
  f = jax.jit(lambda x: x @ x)
  f(a).block_until_ready()
  best = np.inf
  for _ in range(repeats):
    t = time.perf_counter()
    f(a).block_until_ready()
    best = min(best, time.perf_counter() - t)
  return 2 * n**3 / best / 1e9


def bench(config_path, bindings, steps):
  config = load_config([config_path], bindings)
  scene = load_scene(config)
  pools = make_pools(config, scene, None)
  cam = training.Camera.of(scene)
  state = training.init_state(config, jax.random.PRNGKey(0))
  t = time.perf_counter()
  compiled = training.train_step.lower(config, cam, 0, state, pools,
                                       jax.random.PRNGKey(0)).compile()
  compile_s = time.perf_counter() - t
  flops = float(compiled.cost_analysis().get('flops', float('nan')))
  state, stats = training.train_step(config, cam, False, state, pools, jax.random.PRNGKey(0))
  jax.block_until_ready(stats)
  times = []
  for i in range(steps):
    t = time.perf_counter()
    state, stats = training.train_step(config, cam, False, state, pools, jax.random.PRNGKey(i + 1))
    jax.block_until_ready(stats)
    times.append(time.perf_counter() - t)
  sec = float(np.median(times))
  rays = config.batch_size + (config.batch_size_random if config.depth_tv_loss_mult > 0 else 0)
  samples = rays * sum(model.level_samples(config))
  return {'config': os.path.basename(config_path), 'bindings': ' '.join(bindings),
          'compile_s': compile_s, 'sec_per_step': sec, 'rays_per_s': rays / sec,
          'samples_per_s': samples / sec, 'step_gflop': flops / 1e9,
          'achieved_gflops': flops / sec / 1e9}


def main():
  p = argparse.ArgumentParser(description=__doc__)
  p.add_argument('--configs', nargs='+', default=['gin_configs/llff3_cpu.gin'])
  p.add_argument('--gin_bindings', action='append', default=[])
  p.add_argument('--steps', type=int, default=5)
  p.add_argument('--out', default='benchmarks/results/train_step')
  args = p.parse_args()
  roof = matmul_gflops()
  rows = []
  for path in args.configs:
    row = bench(path, args.gin_bindings, args.steps)
    row['matmul_gflops'] = roof
    row['flop_efficiency'] = row['achieved_gflops'] / roof
    rows.append(row)
    print(row, flush=True)
  report.write_json(args.out + '.json', {'matmul_gflops': roof, 'device': str(jax.devices()[0]),
                                         'rows': rows,
                                         'command': command_line('benchmarks.bench_train_step')})
  text = write_table(rows, roof, args.out)
  print(text)


def write_table(rows, roof, out):
  """Markdown table of the rows next to the matmul roof; returns its text."""
  table = report.markdown_table(rows, [
      ('config', 'config'), ('sec_per_step', 's/step'), ('rays_per_s', 'rays/s'),
      ('samples_per_s', 'samples/s'), ('step_gflop', 'GFLOP/step'),
      ('achieved_gflops', 'GFLOP/s'), ('flop_efficiency', 'of matmul roof'),
      ('compile_s', 'compile s')], floatfmt={
          'sec_per_step': '.3f', 'rays_per_s': '.0f', 'samples_per_s': '.0f',
          'step_gflop': '.1f', 'achieved_gflops': '.1f', 'flop_efficiency': '.1%',
          'compile_s': '.1f'})
  text = f'Matmul roof (float32 2048^2, best of 5): {roof:.1f} GFLOP/s\n\n{table}\n'
  report.write_markdown(out + '.md', text)
  return text


if __name__ == '__main__':
  main()
