"""What the persistent compilation cache (renerf_jax/jit_cache.py) saves per train step.

python -m benchmarks.bench_compile_cache --config experiments/configs/table_small.gin \
  --gin_bindings "Config.data_dir='../shared/data/nerf_llff_data'"

Each measurement runs in a fresh process: the cache off, the cache on in an empty
directory (cold) and the cache on again in the same directory (warm: what a resumed run,
a later table or another variant of a table finds). Per process: seconds of the first
train step (trace + compile + one step), of the first step of a round with another seed
(every round trains with its own seed, and the seed is part of the static Config: a new
trace, and without the cache a new compile), and of a steady step. Writes JSON and a
markdown table to benchmarks/results/compile_cache (or --out).
"""
import argparse
import json
import os
import shlex
import subprocess
import sys
import tempfile
import time


def child(config_path, bindings, cache_dir):
  """Times the train step in this process; prints one JSON line."""
  import dataclasses  # pylint: disable=g-import-not-at-top
  import jax  # pylint: disable=g-import-not-at-top
  from renerf_jax import jit_cache  # pylint: disable=g-import-not-at-top
  from renerf_jax.nerf import training  # pylint: disable=g-import-not-at-top
  from renerf_jax.configs import load_config  # pylint: disable=g-import-not-at-top
  from renerf_jax.datasets import load_scene  # pylint: disable=g-import-not-at-top
  from renerf_jax.nerf.pools import make_pools  # pylint: disable=g-import-not-at-top
  jit_cache.enable_compilation_cache(cache_dir)
  config = load_config([config_path], bindings)
  scene = load_scene(config)
  pools = make_pools(config, scene, None)
  cam = training.Camera.of(scene)
  state = jax.device_put(training.init_state(config, jax.random.PRNGKey(0)),
                         training.replicated_sharding())

  def step(cfg, state, i):
    t = time.perf_counter()
    state, stats = training.train_step(cfg, cam, False, state, pools, jax.random.PRNGKey(i))
    jax.block_until_ready(stats)
    return state, time.perf_counter() - t

  state, first = step(config, state, 0)
  state, steady = step(config, state, 1)
  state, reseed = step(dataclasses.replace(config, seed=config.seed + 1000), state, 2)
  print(json.dumps({'first_step_s': first, 'new_seed_step_s': reseed,
                    'steady_step_s': steady}))


def run_child(args, cache_dir):
  cmd = [sys.executable, '-m', 'benchmarks.bench_compile_cache', '--child',
         '--config', args.config, '--cache_dir', cache_dir] + [
             f'--gin_bindings={b}' for b in args.gin_bindings]
  out = subprocess.run(cmd, capture_output=True, text=True, check=True,
                       cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__)))).stdout
  return json.loads(out.strip().splitlines()[-1])


def main():
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--config', default='experiments/configs/table_small.gin')
  p.add_argument('--gin_bindings', action='append', default=[])
  p.add_argument('--out', default='benchmarks/results/compile_cache')
  p.add_argument('--child', action='store_true', help=argparse.SUPPRESS)
  p.add_argument('--cache_dir', default='off', help=argparse.SUPPRESS)
  args = p.parse_args()
  if args.child:
    child(args.config, args.gin_bindings, args.cache_dir)
    return
  from renerf_jax import report  # pylint: disable=g-import-not-at-top
  rows = []
  with tempfile.TemporaryDirectory() as cache:
    for label, cache_dir in (('cache off', 'off'), ('cache on, empty (cold)', cache),
                             ('cache on, filled (warm)', cache)):
      row = dict(run_child(args, cache_dir), process=label)
      rows.append(row)
      print(row, flush=True)
  table = report.markdown_table(rows, [
      ('process', 'process'), ('first_step_s', 'first step s'),
      ('new_seed_step_s', 'first step, new seed s'), ('steady_step_s', 'steady step s')],
      floatfmt={k: '.2f' for k in ('first_step_s', 'new_seed_step_s', 'steady_step_s')})
  command = 'python ' + shlex.join(['-m', 'benchmarks.bench_compile_cache'] + sys.argv[1:])
  text = (f'# Persistent compilation cache, train step of `{args.config}`\n\n'
          f'Each row is a fresh process (see the script).\n\n{table}\n\n'
          f'Command:\n\n    {command}\n')
  report.write_json(args.out + '.json', {'config': args.config, 'bindings': args.gin_bindings,
                                         'rows': rows, 'command': command})
  report.write_markdown(args.out + '.md', text)
  print(text)


if __name__ == '__main__':
  main()
