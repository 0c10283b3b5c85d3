"""Compares methods at equal wall time: each gets the step count that fills the budget.

Example (issue 3: mip-NeRF vs RegNeRF vs FreeNeRF-regularised on fern, CPU config):

  python -m experiments.compare_equal_time --name fern_regularizers \
    --base gin_configs/llff3_cpu.gin --budget_s 600 \
    --gin_bindings="Config.data_dir='../shared/data/nerf_llff_data'" \
    --method "mip-NeRF=gin_configs/modifiers/mipnerf.gin" --method "RegNeRF=" \
    --method "RegNeRF+FreeNeRF=gin_configs/modifiers/freenerf.gin"

Per method: seconds per step are measured on --calib_steps steps after compilation, and
max_steps = budget / (seconds per step) is fixed for all its seeds (so every seed runs the
same step count; schedules given in steps stay as in the base config). Each run is the
baseline round of train.py (round_0) in <out>/<name>/<method>/seed<k>, resumable.
The calibration is stored per method and reused by a rerun (delete the method's folder to
recalibrate it, e.g. after measuring on a loaded machine). On a busy machine, give each
method's idle-CPU seconds per step instead (--sec_per_step LABEL=S, e.g. the train stage of
benchmarks/bench_throughput.py run on an idle CPU): the step counts are then those of the
budget on an idle CPU, the runs may share the CPU with other jobs, and the curves' time
axis is step x S instead of the (inflated) logged seconds. --seeds_of LABEL=0,1 gives a
method its own seeds (e.g. a reference config on one seed). Writes <out>/<name>.json, .md
(mean +- std over seeds) and _curves.png (test PSNR against training seconds).

Time to quality (issue 21), 10 minutes on full-resolution fern, old against new config,
with idle-CPU rates from bench_throughput:

  python -m experiments.compare_equal_time --name fern_10min --base gin_configs/llff3_fast.gin \
    --budget_s 600 --method 'llff3_fast=' --method 'llff3_10min=experiments/configs/llff3_10min.gin' \
    --sec_per_step llff3_10min=0.192 --sec_per_step llff3_fast=0.709 \
    --seeds 0 1 2 --seeds_of llff3_fast=0
"""
import argparse
import dataclasses
import os
import sys
import time

import jax
import numpy as np

from experiments import tables
from renerf_jax import figures, jit_cache, report, rundir
from renerf_jax.nerf import training
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene
from renerf_jax.nerf.pools import make_pools
from renerf_jax.round_driver import run_rounds

METRICS = ('psnr', 'ssim', 'lpips_alex', 'lpips_vgg')


def seconds_per_step(config, scene, steps):
  """Median wall seconds of a NeRF train step after compilation."""
  if config.backbone != 'nerf':
    raise SystemExit(f'error: calibration times NeRF steps; Config.backbone='
                     f'{config.backbone!r} needs --sec_per_step (e.g. from '
                     'benchmarks/bench_gaussians.py)')
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


def _positive(text, what):
  try:
    v = float(text)
  except ValueError:
    v = float('nan')
  if not np.isfinite(v) or v <= 0:
    raise SystemExit(f'error: {what}={text!r} is not a positive number of seconds')
  return v


def _seeds(text, what):
  try:
    seeds = [int(t) for t in text.split(',')]
  except ValueError:
    seeds = []
  if not seeds or len(set(seeds)) != len(seeds):
    raise SystemExit(f'error: {what}={text!r} is not a comma-separated list of distinct '
                     f'seeds')
  return seeds


def stored_rates(out, name, labels, given):
  """{label: (stored seconds per step, whether it was given)} of existing calibrations.

  Raises SystemExit (before anything trains) when a given rate differs from a stored one.
  """
  stored = {}
  for label in labels:
    path = os.path.join(out, name, label, 'calibration.json')
    if os.path.isfile(path):
      calib = report.read_json(path)
      stored[label] = (calib['sec_per_step'], calib.get('source') == '--sec_per_step')
      if label in given and given[label] != calib['sec_per_step']:
        raise SystemExit(f"error: {path} holds {calib['sec_per_step']} s/step, not the "
                         f'given {given[label]}; use another --name')
  return stored


def column_mean_std(rows, key):
  """(mean, std, count) of rows[i][key] over the rows that have it (nan, nan, 0 if none)."""
  vals = [r[key] for r in rows if key in r]
  return (*tables.mean_std(vals), len(vals)) if vals else (float('nan'), float('nan'), 0)


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
  p.add_argument('--sec_per_step', action='append', default=[],
                 help='LABEL=S: that method\'s idle-CPU seconds per step (no calibration)')
  p.add_argument('--seeds_of', action='append', default=[],
                 help='LABEL=0,1: that method\'s seeds instead of --seeds')
  p.add_argument('--out', default='experiments/results')
  args = p.parse_args()
  labels = [spec.partition('=')[0] for spec in args.method]
  given = {k: _positive(v, f'--sec_per_step {k}')
           for k, v in tables.label_values(args.sec_per_step, '--sec_per_step', labels).items()}
  seeds_of = {k: _seeds(v, f'--seeds_of {k}')
              for k, v in tables.label_values(args.seeds_of, '--seeds_of', labels).items()}
  stored = stored_rates(args.out, args.name, labels, given)
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
    if label in stored:  # a rerun reuses the calibration and finished runs
      sps, was_given = stored[label]
    elif label in given:
      sps, was_given = given[label], True
      report.write_json(calib_path, {'sec_per_step': sps, 'source': '--sec_per_step'})
    else:
      sps, was_given = seconds_per_step(config, scene, args.calib_steps), False
      report.write_json(calib_path, {'sec_per_step': sps})
    steps = max(int(args.budget_s / sps), 1)
    print(f'{label}: {sps:.3f} s/step -> max_steps = {steps}', file=sys.stderr, flush=True)
    runs = []
    seeds = seeds_of.get(label, args.seeds)
    for seed in seeds:
      cfg = dataclasses.replace(config, max_steps=steps, seed=seed, num_rounds=0)
      run_dir = os.path.join(args.out, args.name, label, f'seed{seed}')
      state = run_rounds(cfg, scene, run_dir)
      m = dict(state.metrics[0], seed=seed)
      runs.append(m)
      curve = report.read_json(rundir.result_path(rundir.round_dir(run_dir, 0)))['curve']
      curves[f'{label} (seed {seed})'] = [
          (c['step'] * sps if was_given else c['train_seconds'], c['eval_psnr'])
          for c in curve]
    summary = {'label': label, 'configs': files, 'sec_per_step': sps, 'max_steps': steps,
               'sec_per_step_given': was_given, 'seeds': seeds, 'runs': runs}
    for k in METRICS + ('round_seconds',):
      summary[k], summary[k + '_std'], summary[k + '_n'] = column_mean_std(runs, k)
    results['methods'].append(summary)
    report.write_json(os.path.join(args.out, args.name + '.json'), results)

  rows = []
  for s in results['methods']:
    row = {'method': s['label'], 'seeds': ', '.join(map(str, s['seeds'])),
           'steps': s['max_steps'],
           'sps': f"{s['sec_per_step']:.3f}" + (' (given)' if s['sec_per_step_given'] else ''),
           'seconds': s['round_seconds']}
    for k in METRICS:
      if s[k + '_n']:
        row[k] = f"{s[k]:.3f} +- {s[k + '_std']:.3f}" if s[k + '_n'] > 1 else s[k]
    rows.append(row)
  cols = [('method', 'method'), ('seeds', 'seeds'), ('steps', 'steps'),
          ('sps', 's / step'), ('seconds', 'train s (logged)')] + [
              (k, k.upper().replace('_', '-')) for k in METRICS]
  cmd = tables.command_line('experiments.compare_equal_time')
  note = ('\n\n"s / step (given)": an idle-CPU rate passed with --sec_per_step; that '
          'method\'s steps fill the budget at that rate, its curve\'s time axis is step x '
          'that rate, and its logged train seconds may be inflated by other jobs.'
          if any(m['sec_per_step_given'] for m in results['methods']) else '')
  text = (f'# {args.name}\n\nEqual wall time: {args.budget_s:.0f} s of training per run; '
          f'base `{args.base}`.\n\n' + report.markdown_table(rows, cols) + note
          + f'\n\nCommand:\n\n    {cmd}\n')
  report.write_markdown(os.path.join(args.out, args.name + '.md'), text)
  figures.plot_error_vs_time(curves, os.path.join(args.out, args.name + '_curves.png'),
                            metric='psnr', title=f'{args.name}: test PSNR vs training time')
  print(text)


if __name__ == '__main__':
  main()
