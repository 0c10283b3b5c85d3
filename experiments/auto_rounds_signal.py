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

With --max_round R > 1 (runs with R2, R3, ...: renerf_scenes.py's --rounds_scenes) the
rule decides round after round as train.py does (round r against round r - 1, stopping at
the first discarded round), the oracle is the best of rounds 0..R per seed, and the later
rounds' signal is set beside their test gain (round r - round r - 1).

With --loo, a second signal for captures without validation views: table folders of
leave-one-training-view-out probes, one per j (renerf_scenes.py with --gin_bindings
Config.leave_out_view=j: B and R1 trained without the j-th training view, which is their
only validation view). Per (backbone, scene, seed) the signal is the mean over the folds
of R1 - B at the left-out view, +- its standard error over the folds; it keeps R1 above 1
standard error. Its outcome and cost (the probes' seconds over the run's R1 round) are
reported beside the validation signal's; the probes' result.json are read, nothing is
rendered.

The runs keep their checkpoints only locally (results folders keep no params in git), so
this reads run directories that still exist. Trains nothing. Example (the paper-setting
tables of issue 61):

  python -m experiments.auto_rounds_signal --name auto_signal_360 \\
    --out experiments/results/auto_rounds_signal \\
    --runs experiments/results/paper_table2_360/grid experiments/results/paper_table2_360/gaussians

  python -m experiments.auto_rounds_signal --name auto_signal_rounds_garden --max_round 3 \
    --out experiments/results/auto_rounds_signal --runs experiments/results/paper_table2_360/grid
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
  p.add_argument('--max_round', type=int, default=1,
                 help='rounds 0..max_round are read (runs without them all finished are '
                 'passed over); the rule decides round after round (round r against r - 1) '
                 'and is capped there, as Config.auto_max_rounds caps it')
  p.add_argument('--loo', nargs='*', default=[],
                 help='table folders of leave-one-training-view-out probes (made with '
                 '--gin_bindings Config.leave_out_view=j, one folder per j): a second '
                 'signal, the mean gain R1 - B at the left-out view over the folds, for '
                 'captures without validation views')
  p.add_argument('--name', default='auto_signal')
  p.add_argument('--out', default='experiments/results/auto_rounds_signal')
  return p


def run_dirs(roots, max_round=1):
  """[(backbone, scene, seed, run directory)] of runs with rounds 0..max_round finished,
  sorted."""
  out = []
  for root in roots:
    for d in sorted(glob.glob(os.path.join(root, '*', 'Re-Nerfing', 'seed*'))):
      if all(rundir.is_done(rundir.round_dir(d, r)) for r in range(max_round + 1)):
        scene = os.path.basename(os.path.dirname(os.path.dirname(d)))
        out.append((os.path.basename(os.path.normpath(root)), scene,
                    int(os.path.basename(d)[4:]), d))
  return out


def validation_views(run_dir, cache, scenes, max_round=1):
  """{round: per-view validation PSNRs} of rounds 0..max_round (cached by path and params
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
  for r in range(max_round + 1):
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


def loo_folds(roots):
  """{(backbone field, scene, seed): [fold]} of the finished B + R1 probes under the
  leave-one-out table folders; a fold is {'view': j, 'gain': the left-out view's PSNR,
  R1 - B, 'seconds': the probe's B + R1 seconds, 'run'}."""
  out = {}
  for _, scene, seed, d in run_dirs(roots):
    cfg = report.read_json(rundir.config_json_path(d))
    j = cfg.get('leave_out_view', -1)
    if j < 0:
      raise SystemExit(f'error: {d}: not a leave-one-out probe (Config.leave_out_view='
                       f'{j}); --loo takes tables made with Config.leave_out_view = j')
    b, r1 = (report.read_json(rundir.result_path(rundir.round_dir(d, r)))['metrics']
             for r in (0, 1))
    out.setdefault((cfg['backbone'], scene, seed), []).append(
        {'view': j, 'gain': r1['val_psnr'] - b['val_psnr'],
         'seconds': r1['cumulative_seconds'], 'run': d})
  return out


def loo_signal(folds, k):
  """The leave-one-out signal of one (scene, seed): the mean of the folds' gains, its
  standard error over the folds (two or more), and whether it keeps R1 at k (the
  validation rule's test: gain > 0 and gain > k standard errors)."""
  g = np.asarray([f['gain'] for f in folds], np.float64)
  se = float(g.std(ddof=1) / np.sqrt(len(g))) if len(g) > 1 else float('nan')
  gain = float(g.mean())
  return gain, se, bool(gain > 0. and (len(g) < 2 or gain > k * se))


def tests_of(row):
  """The test PSNR of each round of a row (B, R1, ...)."""
  return row.get('tests') or [row['test_b'], row['test_r1']]


def selected(row, k):
  """The round the rule keeps at threshold k (rows of B and R1 alone: take_k)."""
  return row[f'sel_{k:g}'] if f'sel_{k:g}' in row else int(row[f'take_{k:g}'])


def rule(views, k):
  """The sequential rule of Config.num_rounds = 'auto' on stored per-view PSNRs.

  Args:
    views: [per-view validation PSNRs of round 0, 1, ..., R].
    k: auto_min_gain_se.

  Returns:
    (the round kept, [auto_rounds.decide of rounds 1..: up to the first discarded one]).
  """
  sel, decisions = 0, []
  for r in range(1, len(views)):
    dec = auto_rounds.decide(r, views[r - 1], views[r], k)
    decisions.append(dec)
    if not dec['take']:
      break
    sel = r
  return sel, decisions


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
    n_rounds = min(len(tests_of(r)) for r in rs)
    entry = {'backbone': bb, 'scene': sc, 'seeds': len(rs), 'always_B': float(b),
             'always_R1': float(np.mean([r['test_r1'] for r in rs])),
             'always': [float(np.mean([tests_of(r)[i] for r in rs])) for i in range(n_rounds)],
             'oracle': float(np.mean([max(tests_of(r)[:n_rounds]) for r in rs])),
             'val_gain': float(np.mean(val)),
             'val_gain_seed_std': float(np.std(val, ddof=1)) if len(rs) > 1 else None,
             'mean_se': float(np.mean([r['se'] for r in rs])),
             'test_gain': float(np.mean([r['test_r1'] - r['test_b'] for r in rs])),
             'r': pearson(val, [r['test_r1'] - r['test_b'] for r in rs])}
    for k in THRESHOLDS:
      pick = [tests_of(r)[selected(r, k)] for r in rs]
      entry[f'auto_{k:g}'] = float(np.mean(pick))
      entry[f'kept_{k:g}'] = sum(r[f'take_{k:g}'] for r in rs)
      entry[f'rounds_{k:g}'] = [selected(r, k) for r in rs]
    lo = [r for r in rs if 'loo_gain' in r]
    if lo:  # The leave-one-out signal, on the seeds that have its probes.
      entry.update(
          loo_seeds=len(lo), loo_gain=float(np.mean([r['loo_gain'] for r in lo])),
          loo_r=pearson([r['loo_gain'] for r in lo], [r['test_r1'] - r['test_b'] for r in lo]),
          loo_always_B=float(np.mean([r['test_b'] for r in lo])),
          loo_oracle=float(np.mean([max(r['test_b'], r['test_r1']) for r in lo])),
          auto_loo=float(np.mean([r['test_r1'] if r['loo_take'] else r['test_b']
                                  for r in lo])),
          loo_kept=sum(r['loo_take'] for r in lo),
          loo_cost=float(np.mean([r['loo_seconds'] / r['round_seconds'] for r in lo])))
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
    lo = [r for r in rs if 'loo_gain' in r]
    if lo:
      ls = [s for s in ss if 'loo_gain' in s]
      d = [s['auto_loo'] - s['loo_always_B'] for s in ls]
      o.update(loo_pairs=len(lo),
               r_loo_pooled=pearson([r['loo_gain'] for r in lo],
                                    [r['test_r1'] - r['test_b'] for r in lo]),
               auto_loo=float(np.mean([s['auto_loo'] for s in ls])),
               loo_always_B=float(np.mean([s['loo_always_B'] for s in ls])),
               loo_regret=float(np.mean([s['loo_oracle'] - s['auto_loo'] for s in ls])),
               worst_auto_loo_minus_B=float(min(d)),
               loo_cost=float(np.mean([r['loo_seconds'] / r['round_seconds'] for r in lo])))
    later = [(g['gain'], g['test_gain']) for r in rs for g in r.get('later', [])]
    if later:  # Round r against r - 1 for r >= 2, where the runs have them.
      o['later_pairs'] = len(later)
      o['r_later_rounds'] = pearson(*zip(*later))
      o['r_all_rounds'] = pearson([r['val_gain'] for r in rs] + [g for g, _ in later],
                                  [r['test_r1'] - r['test_b'] for r in rs]
                                  + [t for _, t in later])
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
  later = [r for r in rows if r.get('later')]
  if later:
    lines += ['', '## Later rounds: round r against round r - 1', '',
              '| backbone | scene | seed | round | val gain +- se | test gain | '
              'round kept at k = 0 / 1 / 2 |', '|---|---|---|---|---|---|---|']
    for r in later:
      kept = ' / '.join(str(selected(r, k)) for k in THRESHOLDS)
      for g in r['later']:
        lines.append(f"| {r['backbone']} | {r['scene']} | {r['seed']} | R{g['round']} | "
                     f"{g['gain']:+.2f} +- {g['se']:.2f} | {g['test_gain']:+.2f} | {kept} |")
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
  if any(len(s['always']) > 2 for s in scenes):
    lines += ['', 'Always R2, R3, ... (test PSNR; the oracle above is the best round per '
              'seed) and the rounds the rule keeps at k = 1, per seed:', '']
    for s in scenes:
      later_means = ', '.join(f'R{i} {v:.2f}' for i, v in enumerate(s['always']) if i >= 2)
      lines.append(f"- {s['backbone']} {s['scene']}: {later_means}; rounds kept "
                   f"{s['rounds_1']}")
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
  for bb, o in overall.items():
    if 'later_pairs' in o:
      lines.append(f"\n{bb}: later rounds (r >= 2 against r - 1, {o['later_pairs']} pairs) "
                   f"r = {f(o['r_later_rounds'])}; every round's pair pooled r = "
                   f"{f(o['r_all_rounds'])}.")
  lo = [r for r in rows if 'loo_gain' in r]
  if lo:
    lines += ['', '## The leave-one-out signal (for captures without validation views)', '',
              'Per fold j a probe is trained without the j-th training view (B and R1, '
              '`Config.leave_out_view = j`) and both are scored at that view; the signal is '
              'the mean gain over the folds +- its standard error over them, and keeps R1 '
              'when it exceeds 1 standard error (as the validation rule at k = 1). Cost: the '
              "probes' seconds over the run's R1 round.", '',
              '| backbone | scene | seed | folds | LOO gain +- se | test gain | keeps R1 | '
              'probe cost / round |', '|---|---|---|---|---|---|---|---|']
    for r in lo:
      lines.append(f"| {r['backbone']} | {r['scene']} | {r['seed']} | {r['loo_folds']} | "
                   f"{r['loo_gain']:+.2f} +- {r['loo_se']:.2f} | "
                   f"{r['test_r1'] - r['test_b']:+.2f} | {'yes' if r['loo_take'] else 'no'} | "
                   f"{r['loo_seconds'] / r['round_seconds']:.2f} |")
    lines += ['', '| backbone | scene | seeds | always B | oracle | auto (LOO) | auto - B | '
              'kept | r(LOO, test) | cost / round |', '|---|' * 1 + '---|' * 9]
    for s in scenes:
      if 'loo_gain' in s:
        lines.append(f"| {s['backbone']} | {s['scene']} | {s['loo_seeds']} | "
                     f"{s['loo_always_B']:.2f} | {s['loo_oracle']:.2f} | {s['auto_loo']:.2f} | "
                     f"{s['auto_loo'] - s['loo_always_B']:+.2f} | {s['loo_kept']}/"
                     f"{s['loo_seeds']} | {f(s['loo_r'])} | {s['loo_cost']:.2f} |")
    for bb, o in overall.items():
      if 'loo_pairs' in o:
        lines.append(f"\n{bb}: LOO r pooled {f(o['r_loo_pooled'])} ({o['loo_pairs']} pairs), "
                     f"auto (LOO) {o['auto_loo']:.2f} against always B {o['loo_always_B']:.2f}"
                     f", worst scene {o['worst_auto_loo_minus_B']:+.2f}, regret "
                     f"{o['loo_regret']:.2f}, cost {o['loo_cost']:.2f} of a round.")
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
  if args.max_round < 1:
    raise SystemExit(f'error: --max_round {args.max_round}: the rule needs round 1 at least')
  runs = run_dirs(args.runs, args.max_round)
  if not runs:
    raise SystemExit(f'error: no run with rounds 0..{args.max_round} finished under '
                     f'{args.runs}')
  folds = loo_folds(args.loo) if args.loo else {}
  cache_path = os.path.join(args.out, args.name + '_views.json')
  cache = report.read_json(cache_path) if os.path.isfile(cache_path) else {}
  scenes, rows = {}, []
  bar = progress_bar(total=len(runs), unit='run', desc='validation views')
  try:
    for bb, sc, seed, d in runs:
      views = validation_views(d, cache, scenes, args.max_round)
      os.makedirs(args.out, exist_ok=True)
      report.write_json(cache_path, cache)
      tests = [test_psnr(d, r) for r in range(args.max_round + 1)]
      row = {'backbone': bb, 'scene': sc, 'seed': seed, 'run': d,
             'test_b': tests[0], 'test_r1': tests[1]}
      views = [views[r] for r in range(args.max_round + 1)]
      for k in THRESHOLDS:
        row[f'sel_{k:g}'], decisions = rule(views, k)
        row[f'take_{k:g}'] = decisions[0]['take']
      # Each round against the one before (gain and se do not depend on k).
      steps = [auto_rounds.decide(r, views[r - 1], views[r], 1.)
               for r in range(1, args.max_round + 1)]
      row.update(val_gain=steps[0]['gain'], se=steps[0]['se'], views=steps[0]['views'],
                 val_b=views[0], val_r1=views[1])
      fs = folds.get((report.read_json(rundir.config_json_path(d))['backbone'], sc, seed))
      if fs:
        g, se, take = loo_signal(fs, 1.)
        row.update(loo_gain=g, loo_se=se, loo_take=take, loo_folds=len(fs),
                   loo_views=sorted(f['view'] for f in fs),
                   loo_seconds=float(sum(f['seconds'] for f in fs)),
                   round_seconds=float(report.read_json(rundir.result_path(
                       rundir.round_dir(d, 1)))['metrics']['round_seconds']))
      if args.max_round > 1:
        row['tests'] = tests
        row['val_views'] = views
        row['later'] = [{'round': d['round'], 'gain': d['gain'], 'se': d['se'],
                         'test_gain': tests[d['round']] - tests[d['round'] - 1]}
                        for d in steps[1:]]
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
