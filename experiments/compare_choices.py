"""A recipe choice made on validation views: B under each candidate setting, paired by seed.

Reads the finished baselines of experiments/convergence.py runs (one --name per candidate,
the same scene, step count and seeds) and tabulates, per candidate, the validation views'
PSNR / SSIM / LPIPS-alex (mean +- std over seeds) and, against the reference candidate,
the paired deltas (experiments/paired.py: wins, p, Holm over the candidates, bootstrap
95% interval). The choice is read on the validation columns; the test PSNR stands beside
them only to show what the choice would have been on test views (never used to choose).

  python -m experiments.compare_choices --root experiments/results/recipe_choices_val \\
      --scene fox --steps 4000 --seeds 0 1 2 --reference "radius 0.15" \\
      --choice "off=fox_off" --choice "radius 0.15=fox_r015" --choice "radius 0.30=fox_r030" \\
      --out experiments/results/recipe_choices_val/fox_near_camera

Writes <out>.json and <out>.md; trains nothing.
"""
import argparse
import os
import sys

from experiments import convergence, paired, tables
from experiments.tables import command_line, mean_std
from renerf_jax import report

METRICS = (('psnr', 'PSNR', 1.), ('ssim', 'SSIM', 1.), ('lpips_alex', 'LPIPS-alex', -1.))


def compare(results, reference):
  """Rows of a choice table.

  Args:
    results: {label: {seed: finished run's result (metrics with val_<metric>)}}.
    reference: the label the others are paired with.

  Returns:
    [{'label', 'seeds', 'val_<m>' (mean, std), 'test_psnr' (mean, std), 'delta_<m>'
    (paired_summary against the reference on validation views, Holm over the rows)}].
  """
  rows = []
  for label, runs in results.items():
    row = {'label': label, 'seeds': sorted(runs)}
    for k, _, _ in METRICS:
      row[f'val_{k}'] = mean_std([convergence.score(r, k, 'val', label) for r in runs.values()])
    row['test_psnr'] = mean_std([r['metrics']['psnr'] for r in runs.values()])
    if label != reference:
      common = sorted(set(runs) & set(results[reference]))
      for k, _, better in METRICS:
        row[f'delta_{k}'] = paired.paired_summary(
            [runs[s]['metrics'][f'val_{k}'] - results[reference][s]['metrics'][f'val_{k}']
             for s in common], better)
    rows.append(row)
  for k, _, better in METRICS:
    family = [r[f'delta_{k}'] for r in rows if f'delta_{k}' in r]
    if family:
      paired.adjust_family(family, better)
  return rows


def markdown(rows, reference, scene, steps, command):
  fmt = lambda ms, d: f'{ms[0]:.{d}f} +- {ms[1]:.{d}f}'
  lines = [f'### {scene}, B at {steps} steps: validation views (the choice) and test PSNR '
           '(beside it, never used)', '',
           '| setting | seeds | val PSNR | val SSIM | val LPIPS-alex | test PSNR | '
           + ' | '.join(f'd val {name} vs {reference}' for _, name, _ in METRICS) + ' |',
           '|---' * (6 + len(METRICS)) + '|']
  for r in rows:
    deltas = [paired.format_cell(r[f'delta_{k}'], 2 if k == 'psnr' else 3)
              if f'delta_{k}' in r else '' for k, _, _ in METRICS]
    lines.append(f"| {r['label']} | {len(r['seeds'])} | {fmt(r['val_psnr'], 2)} | "
                 f"{fmt(r['val_ssim'], 3)} | {fmt(r['val_lpips_alex'], 3)} | "
                 f"{fmt(r['test_psnr'], 2)} | " + ' | '.join(deltas) + ' |')
  return ('\n'.join(lines) + '\n\nDeltas: the setting minus the reference on the same seed, '
          'mean +- std (wins/n), paired t-test p, its Holm adjustment over the settings, '
          'bootstrap 95% interval; bold where shown.\n\nCommand:\n\n    ' + command + '\n')


def main(argv=None):
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--root', required=True, help='the convergence.py --out folder')
  p.add_argument('--scene', required=True)
  p.add_argument('--steps', type=int, required=True)
  p.add_argument('--seeds', type=int, nargs='+', required=True)
  p.add_argument('--choice', action='append', required=True, help="'LABEL=run name'")
  p.add_argument('--reference', required=True, help='the label the others are paired with')
  p.add_argument('--out', required=True)
  args = p.parse_args(argv)
  names = tables.label_values(args.choice, '--choice')
  if args.reference not in names:
    sys.exit(f'error: --reference {args.reference!r} is none of the --choice labels')
  results = {}
  for label, name in names.items():
    runs = {s: convergence.finished(os.path.join(args.root, name), args.scene, args.steps, s)
            for s in args.seeds}
    missing = [s for s, r in runs.items() if r is None]
    if missing:
      sys.exit(f'error: {label}: no finished run for seeds {missing} in '
               f'{os.path.join(args.root, name)}')
    results[label] = runs
  try:
    rows = compare(results, args.reference)
  except ValueError as e:
    print(f'error: {e}', file=sys.stderr)
    sys.exit(2)
  command = command_line('experiments.compare_choices', sys.argv[1:] if argv is None else argv)
  report.write_json(args.out + '.json', {'rows': rows, 'reference': args.reference,
                                         'scene': args.scene, 'steps': args.steps,
                                         'command': command})
  text = markdown(rows, args.reference, args.scene, args.steps, command)
  report.write_markdown(args.out + '.md', text)
  print(text)


if __name__ == '__main__':
  main()
