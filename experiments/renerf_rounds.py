"""Re-Nerfing rounds against the baseline at equal total wall time, over seeds.

The paper's LLFF 3-view table (baseline, R1, R2, R3), and with --variant its ablation
tables: each variant is the base config plus gin bindings, run for --rounds rounds per
seed with a fixed step count per round. Examples (fern, CPU):

  # Table 1: rounds + the baseline trained for the same total time (3 seeds)
  python experiments/renerf_rounds.py --name fern_rounds_fast \
    --config gin_configs/llff3_fast_renerf.gin --seeds 0 1 2

  # Masks ablation (paper: augmented views / stop aug. views / + masks), round 1 only
  python experiments/renerf_rounds.py --name fern_masks_fast --rounds 1 \
    --config gin_configs/llff3_fast_renerf.gin --seeds 0 1 2 --no_equal_time \
    --variant "augmented views=Config.pseudo_schedule='all'" \
    --variant "stop aug. views=" --variant "+ masks=Config.use_masks=True"

Runs live in <out>/<name>/<variant>/seed<k> (train.py run directories: resumable, finished
rounds are never rewritten). The equal-time baseline gets a FIXED step count, the same for
every seed: the cumulative seconds of seed <first>'s rounds (training + pseudo-view
synthesis + uncertainty) divided by that seed's baseline seconds per step; it is stored in
<out>/<name>/equal_time.json and reused. Writes <out>/<name>.json, .md (mean +- std; the
paper's numbers beside ours) and _time.png (cheap test PSNR against cumulative seconds).
A gain smaller than the seed spread is no gain: the .md marks rows whose mean PSNR gain
over the baseline exceeds the larger of the two stds.
"""
import argparse
import dataclasses
import os
import shlex
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from renerf_jax import report  # pylint: disable=g-import-not-at-top
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene
from renerf_jax.renerf import run_rounds

METRICS = ('psnr', 'ssim', 'lpips_alex', 'lpips_vgg')
# Re-Nerfing paper, LLFF 3 views, mean over the 8 scenes, RegNeRF base (PSNR, SSIM, LPIPS).
PAPER_LLFF3 = {'baseline': (19.08, .685, .148), 'R1': (19.35, .713, .133),
               'R2': (19.47, .724, .126), 'R3': (19.52, .725, .127)}


def mean_std(vals):
  vals = np.asarray(vals, np.float64)
  return float(vals.mean()), float(vals.std(ddof=1)) if len(vals) > 1 else 0.


def round_name(r):
  return 'baseline' if r == 0 else f'R{r}'


def curve_of(run_dir, rounds):
  """(cumulative seconds, cheap test PSNR) over the rounds of one run."""
  pts = []
  for r in range(rounds + 1):
    path = os.path.join(run_dir, f'round_{r}', 'result.json')
    pts += [(c['time'], c['eval_psnr']) for c in report.read_json(path)['curve']]
  return pts


def summarize(label, runs, rounds):
  """Rows (one per round) of mean +- std over seeds."""
  rows = []
  for r in range(rounds + 1):
    ms = [run[r] for run in runs]
    row = {'variant': label, 'round': round_name(r), 'seeds': len(ms)}
    for k in METRICS + ('cumulative_seconds',):
      if all(k in m for m in ms):  # e.g. lpips_vgg is absent when Config.lpips_nets omits it
        row[k], row[k + '_std'] = mean_std([m[k] for m in ms])
    rows.append(row)
  return rows


def main():
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--name', required=True)
  p.add_argument('--config', required=True, help='gin config (a *_renerf.gin)')
  p.add_argument('--gin_bindings', action='append', default=[])
  p.add_argument('--data_dir', help='shortcut for Config.data_dir')
  p.add_argument('--scene', help='shortcut for Config.scene')
  p.add_argument('--rounds', type=int, default=3)
  p.add_argument('--variant', action='append', default=[],
                 help="LABEL=binding;binding (empty: the config as is); default one "
                      "variant 'Re-Nerfing'")
  p.add_argument('--seeds', type=int, nargs='+', default=[0, 1, 2])
  p.add_argument('--no_equal_time', action='store_true',
                 help='skip the baseline trained for the total time of the rounds')
  p.add_argument('--out', default='experiments/results')
  args = p.parse_args()

  bindings = list(args.gin_bindings)
  if args.data_dir:
    bindings.append(f"Config.data_dir='{args.data_dir}'")
  if args.scene:
    bindings.append(f"Config.scene='{args.scene}'")
  variants = args.variant or ['Re-Nerfing=']
  root = os.path.join(args.out, args.name)
  results = {'name': args.name, 'config': args.config, 'bindings': bindings,
             'rounds': args.rounds, 'seeds': args.seeds, 'variants': [],
             'command': 'python ' + shlex.join(sys.argv)}
  rows, curves, first = [], {}, None
  for spec in variants:
    label, _, extra = spec.partition('=')
    config = load_config([args.config],
                         bindings + [b for b in extra.split(';') if b.strip()])
    config = dataclasses.replace(config, num_rounds=args.rounds)
    scene = load_scene(config)
    runs = []
    for seed in args.seeds:
      run_dir = os.path.join(root, label, f'seed{seed}')
      state = run_rounds(dataclasses.replace(config, seed=seed), scene, run_dir)
      runs.append(list(state.metrics))
      curves[f'{label} seed {seed}'] = curve_of(run_dir, args.rounds)
      first = first or (config, scene, run_dir, state.metrics)
    results['variants'].append({'label': label, 'bindings': extra, 'runs': runs})
    rows += summarize(label, runs, args.rounds)

  if not args.no_equal_time:
    config, scene, run_dir, metrics = first
    eq_path = os.path.join(root, 'equal_time.json')
    if os.path.isfile(eq_path):
      steps = report.read_json(eq_path)['max_steps']
    else:
      sec_per_step = metrics[0]['round_seconds'] / config.max_steps
      steps = int(round(metrics[-1]['cumulative_seconds'] / sec_per_step))
      report.write_json(eq_path, {'max_steps': steps, 'from_run': run_dir,
                                  'sec_per_step': sec_per_step,
                                  'cumulative_seconds': metrics[-1]['cumulative_seconds']})
    runs = []
    for seed in args.seeds:
      cfg = dataclasses.replace(config, seed=seed, num_rounds=0, max_steps=steps)
      eq_dir = os.path.join(root, 'equal_time_baseline', f'seed{seed}')
      runs.append(list(run_rounds(cfg, scene, eq_dir).metrics))
      curves[f'baseline {steps} steps seed {seed}'] = curve_of(eq_dir, 0)
    results['equal_time'] = {'max_steps': steps, 'runs': runs}
    row = summarize('baseline, equal total time', runs, 0)[0]
    row['round'] = f'{steps} steps'
    rows.append(row)

  metrics = [k for k in METRICS if k in rows[0]]
  base = {k: rows[0][k] for k in metrics}
  spread = rows[0]['psnr_std']
  table = []
  for row in rows:
    out = {'variant': row['variant'], 'round': row['round']}
    for k in metrics:
      out[k] = f"{row[k]:.3f} +- {row[k + '_std']:.3f}"
    out['time'] = f"{row['cumulative_seconds']:.0f}"
    gain = row['psnr'] - base['psnr']
    out['gain'] = (f'{gain:+.2f}' + (' *' if abs(gain) > max(spread, row['psnr_std'])
                                     else '')) if row is not rows[0] else ''
    paper = PAPER_LLFF3.get(row['round']) if len(variants) == 1 else None
    out['paper'] = ' / '.join(f'{v:g}' for v in paper) if paper else ''
    table.append(out)
  names = {'psnr': 'PSNR', 'ssim': 'SSIM', 'lpips_alex': 'LPIPS-alex',
           'lpips_vgg': 'LPIPS-vgg'}
  cols = ([('variant', 'variant'), ('round', 'round')] + [(k, names[k]) for k in metrics]
          + [('time', 'cum. s'), ('gain', 'dPSNR'), ('paper', 'paper PSNR / SSIM / LPIPS')])
  results['rows'] = rows
  report.write_json(os.path.join(args.out, args.name + '.json'), results)
  text = (f'# {args.name}\n\nConfig `{args.config}` {bindings}, {args.rounds} round(s), '
          f'seeds {args.seeds}; mean +- std over seeds (fixed step counts). dPSNR: against '
          f'the first row; * = larger than the seed spread. Paper: Re-Nerfing, LLFF 3-view '
          f'mean of 8 scenes, RegNeRF base, at full GPU scale.\n\n'
          + report.markdown_table(table, cols)
          + f"\n\nCommand:\n\n    {results['command']}\n")
  report.write_markdown(os.path.join(args.out, args.name + '.md'), text)
  report.plot_error_vs_time(curves, os.path.join(args.out, args.name + '_time.png'),
                            metric='psnr',
                            title=f'{args.name}: test PSNR vs cumulative seconds')
  print(text)


if __name__ == '__main__':
  main()
