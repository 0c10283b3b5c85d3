"""Issue 64: does the validation signal of Config.num_rounds = 'auto' predict R1's test gain?

For every finished Re-Nerfing run <runs>/<scene>/Re-Nerfing/seed<k> of the given table
folders (renerf_scenes.py's layout; their configs must have validation views), it renders
B (round 0) and R1 (round 1) at the validation views, one PSNR per view (from the rounds'
saved params; cached in <out>/<name>_views.json), and takes the test PSNRs the runs
recorded. Per (backbone, scene, seed) it reports the signal auto_rounds.decide computes
(the mean per-view validation gain R1 - B and its standard error) beside the test gain,
and the rule's choice at auto_min_gain_se = 0, 1 (the default) and 2. Then:

  - how well the signal predicts the test gain: Pearson r per backbone, pooled, and within
    scenes (each (scene, seed)'s gains minus its scene's mean);
  - the rule's outcome against always-B, always-R1 and the per-seed oracle (the better of
    B / R1 on the test views): mean test PSNR per scene, auto - B, the worst scene, the
    regret to the oracle;
  - its noise estimate (the per-view standard error) beside the spread of the validation
    gain over seeds, which the issue asks the rule to exceed.

The runs keep their checkpoints only locally (results folders keep no params in git), so
this reads run directories that still exist. Trains nothing. Example (the paper-setting
tables of issue 61):

  python -m experiments.auto_rounds_signal --name auto_signal_360 \\
    --out experiments/results/auto_rounds_signal \\
    --runs experiments/results/paper_table2_360/grid experiments/results/paper_table2_360/gaussians
"""
import argparse
import dataclasses
import glob
import json
import os
import sys
import time

import numpy as np

from experiments.tables import command_line
from renerf_jax import auto_rounds, cli, figures, jit_cache, renerf, report, rundir
from renerf_jax.datasets import load_scene
from renerf_jax.progress import progress_bar
from renerf_jax.round_driver import load_round_params
from renerf_jax.run_config import load_run_config

THRESHOLDS = (0., 1., 2.)  # auto_min_gain_se values compared (1: Config's default).
# The shared fields that do not change which photos and cameras load_scene returns.
SEED_FIELDS = ('seed', 'init_seed', 'max_steps', 'backbone', 'random_pose_spread')


def parser():
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--runs', nargs='+', required=True,
                 help='table folders <out>/<name> holding <scene>/Re-Nerfing/seed<k>')
  p.add_argument('--name', default='auto_signal')
  p.add_argument('--out', default='experiments/results/auto_rounds_signal')
  return p


def run_dirs(roots):
  """[(backbone, scene, seed, run directory)] of finished B + R1 runs, sorted."""
  out = []
  for root in roots:
    for d in sorted(glob.glob(os.path.join(root, '*', 'Re-Nerfing', 'seed*'))):
      if all(rundir.is_done(rundir.round_dir(d, r)) for r in (0, 1)):
        scene = os.path.basename(os.path.dirname(os.path.dirname(d)))
        out.append((os.path.basename(os.path.normpath(root)), scene,
                    int(os.path.basename(d)[4:]), d))
  return out


def validation_views(run_dir, cache, scenes):
  """{round: per-view validation PSNRs} of rounds 0 and 1 (cached by path and params
  file time)."""
  config = load_run_config(run_dir)
  key = tuple((f.name, repr(getattr(config, f.name))) for f in dataclasses.fields(config)
              if f.metadata.get('group') == 'shared' and f.name not in SEED_FIELDS)
  if key not in scenes:
    scenes[key] = load_scene(config)
  scene = scenes[key]
  if len(scene.val_idx) < 2:
    raise SystemExit(f'error: {run_dir}: its scene has {len(scene.val_idx)} validation '
                     'views; the signal needs at least 2')
  out = {}
  for r in (0, 1):
    rdir = rundir.round_dir(run_dir, r)
    stamp = f'{rdir}@{os.stat(rundir.params_path(rdir)).st_mtime_ns}'
    if stamp not in cache:
      params = load_round_params(config, rdir, r)
      cache[stamp] = renerf.validation_metrics(config, scene, params, r)['val_psnr_views']
    out[r] = cache[stamp]
  return out


def test_psnr(run_dir, r):
  return float(report.read_json(rundir.result_path(rundir.round_dir(run_dir, r)))
               ['metrics']['psnr'])


def pearson(x, y):
  x, y = np.asarray(x, float), np.asarray(y, float)
  if len(x) < 3 or x.std() == 0. or y.std() == 0.:
    return None
  return float(np.corrcoef(x, y)[0, 1])


def summarize(rows):
  """Correlations, outcomes per (backbone, scene) and over them, noise against spread."""
  groups = {}
  for r in rows:
    groups.setdefault((r['backbone'], r['scene']), []).append(r)
  scenes = []
  for (bb, sc), rs in groups.items():
    val = [r['val_gain'] for r in rs]
    b = np.mean([r['test_b'] for r in rs])
    entry = {'backbone': bb, 'scene': sc, 'seeds': len(rs), 'always_B': float(b),
             'always_R1': float(np.mean([r['test_r1'] for r in rs])),
             'oracle': float(np.mean([max(r['test_b'], r['test_r1']) for r in rs])),
             'val_gain': float(np.mean(val)),
             'val_gain_seed_std': float(np.std(val, ddof=1)) if len(rs) > 1 else None,
             'mean_se': float(np.mean([r['se'] for r in rs])),
             'test_gain': float(np.mean([r['test_r1'] - r['test_b'] for r in rs])),
             'r': pearson(val, [r['test_r1'] - r['test_b'] for r in rs])}
    for k in THRESHOLDS:
      pick = [r['test_r1'] if r[f'take_{k:g}'] else r['test_b'] for r in rs]
      entry[f'auto_{k:g}'] = float(np.mean(pick))
      entry[f'kept_{k:g}'] = sum(r[f'take_{k:g}'] for r in rs)
    scenes.append(entry)
  overall = {}
  for bb in sorted({r['backbone'] for r in rows}) + ['all']:
    rs = [r for r in rows if bb in ('all', r['backbone'])]
    ss = [s for s in scenes if bb in ('all', s['backbone'])]
    cell = lambda r: (r['backbone'], r['scene'])
    means = {c: np.mean([r['val_gain'] for r in rs if cell(r) == c]) for c in map(cell, rs)}
    tmeans = {c: np.mean([r['test_r1'] - r['test_b'] for r in rs if cell(r) == c])
              for c in map(cell, rs)}
    o = {'pairs': len(rs), 'scenes': len(ss),
         'r_pooled': pearson([r['val_gain'] for r in rs],
                             [r['test_r1'] - r['test_b'] for r in rs]),
         'r_within_scenes': pearson(
             [r['val_gain'] - means[cell(r)] for r in rs],
             [r['test_r1'] - r['test_b'] - tmeans[cell(r)] for r in rs])}
    for col in ['always_B', 'always_R1', 'oracle'] + [f'auto_{k:g}' for k in THRESHOLDS]:
      o[col] = float(np.mean([s[col] for s in ss]))
    for k in THRESHOLDS:
      d = [s[f'auto_{k:g}'] - s['always_B'] for s in ss]
      o[f'worst_auto_{k:g}_minus_B'] = float(min(d))
      worst = ss[int(np.argmin(d))]
      o[f'worst_scene_{k:g}'] = f"{worst['backbone']} {worst['scene']}"
      o[f'regret_{k:g}'] = o['oracle'] - o[f'auto_{k:g}']
    overall[bb] = o
  return scenes, overall


def markdown(name, rows, scenes, overall, command):
  f = lambda v, d=2: '' if v is None else f'{v:+.{d}f}'
  lines = [f'# {name}', '',
           'The signal of `Config.num_rounds = \'auto\'` (renerf_jax/auto_rounds.py): the mean '
           'per-view PSNR gain R1 - B on the validation views +- its standard error, beside '
           'the test gain R1 - B the runs recorded. The rule keeps R1 when the gain exceeds '
           'k standard errors (k = `Config.auto_min_gain_se`, 1 by default; 0 and 2 shown '
           'beside it). Test PSNR in dB at the tables\' resolution.', '',
           '## Per run', '',
           '| backbone | scene | seed | val gain +- se (views) | test gain | '
           'keeps R1 at k = 0 / 1 / 2 |',
           '|---|---|---|---|---|---|']
  for r in rows:
    keeps = ' / '.join('yes' if r[f'take_{k:g}'] else 'no' for k in THRESHOLDS)
    lines.append(f"| {r['backbone']} | {r['scene']} | {r['seed']} | {r['val_gain']:+.2f} +- "
                 f"{r['se']:.2f} ({r['views']}) | {r['test_r1'] - r['test_b']:+.2f} | {keeps} |")
  lines += ['', '## Per scene: the rule against always-B, always-R1 and the oracle (test PSNR)',
            '', '| backbone | scene | seeds | always B | always R1 | oracle | auto k=0 | '
            'auto k=1 | auto k=2 | auto(1) - B | kept (k=1) | r(val, test) | val gain: seed '
            'std / mean se |', '|---|' * 1 + '---|' * 12]
  for s in scenes:
    spread = ('' if s['val_gain_seed_std'] is None else f"{s['val_gain_seed_std']:.2f}")
    lines.append(
        f"| {s['backbone']} | {s['scene']} | {s['seeds']} | {s['always_B']:.2f} | "
        f"{s['always_R1']:.2f} | {s['oracle']:.2f} | {s['auto_0']:.2f} | {s['auto_1']:.2f} | "
        f"{s['auto_2']:.2f} | {s['auto_1'] - s['always_B']:+.2f} | {s['kept_1']}/{s['seeds']} | "
        f"{f(s['r'])} | {spread} / {s['mean_se']:.2f} |")
  lines += ['', '## Over scenes (means of the per-scene means)', '',
            '| backbones | pairs | scenes | r pooled | r within scenes | always B | always R1 | '
            'oracle | auto k=1 | worst auto(1) - B | regret (1) | auto k=0 / k=2 |',
            '|---|' * 1 + '---|' * 11]
  for bb, o in overall.items():
    lines.append(
        f"| {bb} | {o['pairs']} | {o['scenes']} | {f(o['r_pooled'])} | "
        f"{f(o['r_within_scenes'])} | {o['always_B']:.2f} | {o['always_R1']:.2f} | "
        f"{o['oracle']:.2f} | {o['auto_1']:.2f} | {o['worst_auto_1_minus_B']:+.2f} "
        f"({o['worst_scene_1']}) | {o['regret_1']:.2f} | {o['auto_0']:.2f} / {o['auto_2']:.2f} |")
  lines += ['', 'Cost: the signal needs R1 trained, so a run that keeps B has paid one full '
            'round (always-R1\'s time) plus two renders of the validation views.', '',
            'Command:', '', f'    {command}', '']
  return '\n'.join(lines)


def plot(rows, path):
  fig, axes = figures.subplots(1, 1, (5.5, 4.5))
  ax = axes[0, 0]
  markers = {'grid': 'o', 'gaussians': 's'}
  scenes = sorted({r['scene'] for r in rows})
  colors = {sc: f'C{i}' for i, sc in enumerate(scenes)}
  for r in rows:
    ax.errorbar(r['val_gain'], r['test_r1'] - r['test_b'], xerr=r['se'],
                fmt=markers.get(r['backbone'], '^'), color=colors[r['scene']], alpha=.8)
  for sc in scenes:
    ax.plot([], [], 'o', color=colors[sc], label=sc)
  for bb, m in markers.items():
    ax.plot([], [], m, color='grey', label=bb)
  ax.axhline(0., color='k', lw=.5)
  ax.axvline(0., color='k', lw=.5)
  ax.set_xlabel('validation gain R1 - B [dB] (+- its standard error)')
  ax.set_ylabel('test gain R1 - B [dB]')
  ax.legend(fontsize=7)
  figures.save_figure(fig, path)


@cli.exit_on_error
def main(argv=None):
  t0 = time.perf_counter()
  args = parser().parse_args(argv)
  jit_cache.enable_compilation_cache()
  runs = run_dirs(args.runs)
  if not runs:
    raise SystemExit(f'error: no finished B + R1 run under {args.runs}')
  cache_path = os.path.join(args.out, args.name + '_views.json')
  cache = report.read_json(cache_path) if os.path.isfile(cache_path) else {}
  scenes, rows = {}, []
  bar = progress_bar(total=len(runs), unit='run', desc='validation views')
  try:
    for bb, sc, seed, d in runs:
      views = validation_views(d, cache, scenes)
      os.makedirs(args.out, exist_ok=True)
      report.write_json(cache_path, cache)
      row = {'backbone': bb, 'scene': sc, 'seed': seed, 'run': d,
             'test_b': test_psnr(d, 0), 'test_r1': test_psnr(d, 1)}
      for k in THRESHOLDS:
        dec = auto_rounds.decide(1, views[0], views[1], k)
        row[f'take_{k:g}'] = dec['take']
      row.update(val_gain=dec['gain'], se=dec['se'], views=dec['views'],
                 val_b=views[0], val_r1=views[1])
      rows.append(row)
      bar.update(1)
  finally:
    bar.close()
  per_scene, overall = summarize(rows)
  command = command_line('experiments.auto_rounds_signal', argv)
  report.write_json(os.path.join(args.out, args.name + '.json'), {
      'rows': rows, 'scenes': per_scene, 'overall': overall, 'thresholds': list(THRESHOLDS),
      'command': command, 'seconds': time.perf_counter() - t0})
  md = markdown(args.name, rows, per_scene, overall, command)
  report.write_markdown(os.path.join(args.out, args.name + '.md'), md)
  plot(rows, os.path.join(args.out, args.name + '.png'))
  print(md)
  print(json.dumps(overall['all']), file=sys.stderr)


if __name__ == '__main__':
  main()
