"""The spread over seeds of each row of renerf_scenes tables (issue 49: do runs agree?).

For every table, scene and row: the seeds, mean +- std (ddof 1), min and max of PSNR,
SSIM and LPIPS-alex; the per-test-view std over seeds of the row's runs when their run
directories are given (--runs), which tells whether the spread sits in a few views.

  python -m experiments.seed_spread --tables T1.json T2.json --out DIR/spread

A claim that one config's runs agree better than another's is a variance test
(issue 62): --f_test A B, each 'LABEL=TABLE:SCENE:ROW[;TABLE:SCENE:ROW...]' (the PSNRs
of those rows' seeds, pooled), gives both stds and the two-sided F-test's p
(experiments/paired.py); the spread is shown to differ only where p < 0.05.
"""
import argparse
import os

from experiments import paired, tables
from renerf_jax import report, rundir

METRICS = (('psnr', 'PSNR', 2), ('ssim', 'SSIM', 3), ('lpips_alex', 'LPIPS-alex', 3))


def spread(values):
  """{'n', 'mean', 'std', 'min', 'max'} of a list of numbers (std 0 for one)."""
  mean, std = tables.mean_std(values)
  return {'n': len(values), 'mean': mean, 'std': std, 'min': float(min(values)),
          'max': float(max(values))}


def table_spreads(path):
  """{scene: {row: {metric: spread, 'seeds': [...]}}} of one renerf_scenes table."""
  table = report.read_json(path)
  out = {}
  for scene, rows in table['rows'].items():
    for label, by_seed in rows.items():
      entry = {'seeds': sorted(int(s) for s in by_seed)}
      for k, _, _ in METRICS:
        vals = [m[k] for m in by_seed.values() if k in m]
        if vals:
          entry[k] = spread(vals)
      out.setdefault(scene, {})[label] = entry
  return out


def group_values(spec, metric='psnr'):
  """(label, values) of an --f_test group 'LABEL=TABLE:SCENE:ROW[;TABLE:SCENE:ROW...]':
  the metric of every seed of those rows, in order."""
  label, sep, sources = spec.partition('=')
  if not sep or not label or not sources:
    raise SystemExit(f'error: --f_test {spec!r} is not LABEL=TABLE:SCENE:ROW[;...]')
  values = []
  for src in sources.split(';'):
    path, scene, row = (src.split(':', 2) + ['', ''])[:3]
    rows = report.read_json(path)['rows']
    if row not in rows.get(scene, {}):
      raise SystemExit(f'error: --f_test {label!r}: {path} has no row {row!r} of scene '
                       f'{scene!r}')
    values += [m[metric] for m in rows[scene][row].values()]
  return label, values


def view_spread(run_dirs, round_index=0):
  """Per test view: the std over runs of its PSNR ({'name', 'mean', 'std'}), worst first."""
  per_run = [report.read_json(rundir.metrics_path(rundir.eval_dir(rundir.round_dir(
      d, round_index))))['per_image'] for d in run_dirs]
  names = [m['name'] for m in per_run[0]]
  rows = []
  for i, name in enumerate(names):
    s = spread([run[i]['psnr'] for run in per_run])
    rows.append({'name': name, 'mean': s['mean'], 'std': s['std']})
  return sorted(rows, key=lambda r: -r['std'])


def main(argv=None):
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--tables', nargs='+', required=True, help='renerf_scenes .json tables')
  p.add_argument('--runs', nargs='*', default=[], metavar='LABEL=DIR,DIR,...',
                 help='run directories whose per-view PSNR spread to report')
  p.add_argument('--f_test', nargs=2, action='append', default=[], metavar='GROUP',
                 help="two groups 'LABEL=TABLE:SCENE:ROW[;TABLE:SCENE:ROW...]' whose PSNR "
                      'spreads to compare (two-sided F-test of the variances)')
  p.add_argument('--out', required=True, help='output path without extension')
  args = p.parse_args(argv)
  result = {'tables': {}, 'views': {}, 'f_tests': [],
            'command': tables.command_line('experiments.seed_spread', argv)}
  lines = ['| table | scene | row | seeds | ' + ' | '.join(
      f'{name} mean +- std [min, max]' for _, name, _ in METRICS) + ' |',
           '|---|---|---|---|' + '---|' * len(METRICS)]
  for path in args.tables:
    name = os.path.splitext(os.path.basename(path))[0]
    spreads = table_spreads(path)
    result['tables'][name] = spreads
    for scene, rows in spreads.items():
      for label, e in rows.items():
        cells = [f"{e[k]['mean']:.{d}f} +- {e[k]['std']:.{d}f} [{e[k]['min']:.{d}f}, "
                 f"{e[k]['max']:.{d}f}]" if k in e else '' for k, _, d in METRICS]
        lines.append(f"| {name} | {scene} | {label} | {len(e['seeds'])} | "
                     + ' | '.join(cells) + ' |')
  for spec in args.runs:
    label, sep, dirs = spec.partition('=')
    if not sep or not dirs:
      raise SystemExit(f'error: --runs {spec!r} is not LABEL=DIR,DIR,...')
    views = view_spread(dirs.split(','))
    result['views'][label] = views
    lines += ['', f'Per test view, {label} ({len(dirs.split(","))} runs), the 5 views '
              'whose PSNR spreads most over seeds:', '', '| view | PSNR mean | std |',
              '|---|---|---|'] + [f"| {v['name']} | {v['mean']:.2f} | {v['std']:.2f} |"
                                  for v in views[:5]]
  if args.f_test:
    lines += ['', 'Spreads compared (PSNR, std over seeds with ddof 1; two-sided F-test of '
              'the variances: a spread is shown to differ only where p < 0.05):', '',
              '| runs A | n | std A | runs B | n | std B | var A / var B | p |',
              '|---|---|---|---|---|---|---|---|']
  for spec_a, spec_b in args.f_test:
    (label_a, a), (label_b, b) = group_values(spec_a), group_values(spec_b)
    t = dict(paired.f_test(a, b), a=label_a, b=label_b, spec_a=spec_a, spec_b=spec_b)
    result['f_tests'].append(t)
    lines.append(f"| {label_a} | {t['n_a']} | {t['std_a']:.2f} | {label_b} | {t['n_b']} | "
                 f"{t['std_b']:.2f} | {t['ratio']:.2f} | {t['p']:.2g}"
                 + (' (shown)' if t['shown'] else '') + ' |')
  lines += ['', 'Command:', '', f"    {result['command']}", '']
  report.write_json(args.out + '.json', result)
  report.write_markdown(args.out + '.md', '\n'.join(lines))
  print('\n'.join(lines))


if __name__ == '__main__':
  main()
