"""Compares methods at equal wall time: each gets the step count that fills the budget.

Example (issue 3: mip-NeRF vs RegNeRF vs FreeNeRF-regularised on fern, CPU config):

  python experiments/compare_equal_time.py --name fern_regularizers \
    --base gin_configs/llff3_cpu.gin --budget_s 600 \
    --gin_bindings="Config.data_dir='../shared/data/nerf_llff_data'" \
    --method "mip-NeRF=gin_configs/modifiers/mipnerf.gin" --method "RegNeRF=" \
    --method "RegNeRF+FreeNeRF=gin_configs/modifiers/freenerf.gin"

Per method: seconds per step are measured on --calib_steps steps after compilation, and
max_steps = budget / (seconds per step) is fixed for all its seeds (so every seed runs the
same step count; schedules given in steps stay as in the base config). Each run is the
baseline round of train.py (round_0) in <out>/<name>/<method>/seed<k>, resumable.
The calibration is stored per method and reused by a rerun (delete the method's folder to
recalibrate it, e.g. after measuring on a loaded machine). Writes <out>/<name>.json, .md (mean +- std over seeds) and _curves.png (test PSNR against
training seconds).
"""
import argparse
import dataclasses
import os
import sys
import time

import jax
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from renerf_jax import jit_cache, report, training  # pylint: disable=g-import-not-at-top
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene
from renerf_jax.renerf import make_pools
from renerf_jax.resume import run_rounds

METRICS = ('psnr', 'ssim', 'lpips_alex', 'lpips_vgg')


def seconds_per_step(config, scene, steps):
  """Median wall seconds of a train step after compilation."""
  pools = make_pools(config, scene, None)
  cam = training.Camera.of(scene)
  state = training.init_state(config, jax.random.PRNGKey(0))
  state, stats = training.train_step(config, cam, False, state, pools, jax.random.PRNGKey(0))
  jax.block_until_ready(stats)
  times = []
  for i in range(steps):
    t = time.perf_counter()
    state, stats = training.train_step(config, cam, False, state, pools, jax.random.PRNGKey(i))
    jax.block_until_ready(stats)
    times.append(time.perf_counter() - t)
  return float(np.median(times))


def mean_std(rows, key):
  vals = np.array([r[key] for r in rows if key in r], np.float64)
  return float(vals.mean()), float(vals.std(ddof=1)) if len(vals) > 1 else 0.


def main():
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--name', required=True)
  p.add_argument('--base', required=True, help='base gin config')
  p.add_argument('--method', action='append', required=True,
                 help='LABEL=modifier.gin[,more.gin] (empty: the base alone)')
  p.add_argument('--gin_bindings', action='append', default=[])
  p.add_argument('--budget_s', type=float, required=True, help='training seconds per run')
  p.add_argument('--seeds', type=int, nargs='+', default=[0])
  p.add_argument('--calib_steps', type=int, default=15)
  p.add_argument('--out', default='experiments/results')
  args = p.parse_args()
  jit_cache.enable_compilation_cache()

  results = {'name': args.name, 'base': args.base, 'bindings': args.gin_bindings,
             'budget_s': args.budget_s, 'seeds': args.seeds, 'methods': []}
  curves = {}
  for spec in args.method:
    label, _, mods = spec.partition('=')
    files = [args.base] + [m for m in mods.split(',') if m]
    config = load_config(files, args.gin_bindings)
    scene = load_scene(config)
    calib_path = os.path.join(args.out, args.name, label, 'calibration.json')
    if os.path.isfile(calib_path):  # a rerun reuses the calibration and finished runs
      sps = report.read_json(calib_path)['sec_per_step']
    else:
      sps = seconds_per_step(config, scene, args.calib_steps)
      report.write_json(calib_path, {'sec_per_step': sps})
    steps = max(int(args.budget_s / sps), 1)
    print(f'{label}: {sps:.3f} s/step -> max_steps = {steps}', file=sys.stderr, flush=True)
    runs = []
    for seed in args.seeds:
      cfg = dataclasses.replace(config, max_steps=steps, seed=seed, num_rounds=0)
      run_dir = os.path.join(args.out, args.name, label, f'seed{seed}')
      state = run_rounds(cfg, scene, run_dir)
      m = dict(state.metrics[0], seed=seed)
      runs.append(m)
      curve = report.read_json(os.path.join(run_dir, 'round_0', 'result.json'))['curve']
      curves[f'{label} (seed {seed})'] = [(c['train_seconds'], c['eval_psnr']) for c in curve]
    summary = {'label': label, 'configs': files, 'sec_per_step': sps, 'max_steps': steps,
               'runs': runs}
    for k in METRICS + ('round_seconds',):
      summary[k], summary[k + '_std'] = mean_std(runs, k)
    results['methods'].append(summary)
    report.write_json(os.path.join(args.out, args.name + '.json'), results)

  rows = []
  for s in results['methods']:
    row = {'method': s['label'], 'steps': s['max_steps'], 'seconds': s['round_seconds']}
    for k in METRICS:
      row[k] = f"{s[k]:.3f} +- {s[k + '_std']:.3f}" if len(args.seeds) > 1 else s[k]
    rows.append(row)
  cols = [('method', 'method'), ('steps', 'steps'), ('seconds', 'train s')] + [
      (k, k.upper().replace('_', '-')) for k in METRICS]
  cmd = 'python ' + ' '.join(sys.argv)
  text = (f'# {args.name}\n\nEqual wall time: {args.budget_s:.0f} s of training per run, '
          f'seeds {args.seeds}; base `{args.base}`.\n\n'
          + report.markdown_table(rows, cols) + f'\n\nCommand:\n\n    {cmd}\n')
  report.write_markdown(os.path.join(args.out, args.name + '.md'), text)
  report.plot_error_vs_time(curves, os.path.join(args.out, args.name + '_curves.png'),
                            metric='psnr', title=f'{args.name}: test PSNR vs training time')
  print(text)


if __name__ == '__main__':
  main()
