"""Error against run time of finished baseline runs of several backbones / configs.

  python -m experiments.plot_backbones --name fern_backbones \
      --run 'MLP (llff3_cpu.gin)=experiments/results/fern_regularizers/RegNeRF/seed*' \
      --run 'grid (llff3_fast.gin)=experiments/results/fern_fast_baseline/Re-Nerfing/seed*' \
      --sec_per_step 'MLP (llff3_cpu.gin)=0.342' --sec_per_step 'grid (llff3_fast.gin)=0.35'

Each --run is LABEL=GLOB of run directories (round_0 of each is read). The curve of a run
is its cheap test PSNR (Config.eval_stride) logged during training; its final point is
the full-resolution evaluation. Run times: the logged wall seconds, or, with
--sec_per_step LABEL=S, step * S, an idle-CPU rate measured by
benchmarks/bench_throughput.py. Use the latter when the runs shared the CPU with other
jobs (their logged seconds are then inflated by an unknown factor). Writes <name>.json,
<name>.md (final metrics, mean +- std over the runs) and <name>.png.
"""
import argparse
import glob
import os

import numpy as np

from experiments import tables
from renerf_jax import figures, report, rundir

METRICS = ('psnr', 'ssim', 'lpips_alex', 'lpips_vgg')


def read_run(run_dir, sec_per_step=None):
  """(curve [(seconds, cheap PSNR)], final metrics dict, steps) of a run's round_0."""
  path = rundir.result_path(rundir.round_dir(run_dir, 0))
  if not os.path.isfile(path):
    raise SystemExit(f'error: {path} not found (an unfinished run?)')
  res = report.read_json(path)
  curve = [(c['step'] * sec_per_step if sec_per_step else c['time'], c['eval_psnr'])
           for c in res['curve'] if 'eval_psnr' in c]
  return curve, res['metrics'], max(c['step'] for c in res['curve'])


def main(argv=None):
  p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  p.add_argument('--name', required=True)
  p.add_argument('--run', action='append', required=True, help='LABEL=GLOB of run dirs')
  p.add_argument('--sec_per_step', action='append', default=[], help='LABEL=SECONDS')
  p.add_argument('--out', default='experiments/results')
  args = p.parse_args(argv)
  runs = tables.label_values(args.run, '--run')
  rates = {k: float(v) for k, v in tables.label_values(args.sec_per_step, '--sec_per_step').items()}
  unknown = set(rates) - set(runs)
  if unknown:
    raise SystemExit(f'error: --sec_per_step for unknown label(s) {sorted(unknown)}')
  command = tables.command_line('experiments.plot_backbones', argv)
  curves, rows, results = {}, [], {'name': args.name, 'methods': [], 'command': command}
  for label, pattern in runs.items():
    dirs = sorted(glob.glob(pattern))
    if not dirs:
      raise SystemExit(f'error: --run {label}={pattern} matches no directory')
    rate = rates.get(label)
    finals, steps = [], []
    for d in dirs:
      curve, metrics, n = read_run(d, rate)
      curves[f'{label} {os.path.basename(d)}'] = curve
      finals.append(metrics)
      steps.append(n)
    row = {'method': label, 'runs': len(dirs), 'steps': int(np.median(steps)),
           'time_s': float(np.median(steps)) * rate if rate else float(
               np.mean([m['round_seconds'] for m in finals]))}
    for k in METRICS:  # A metric the runs did not compute (Config.lpips_nets) shows '-'.
      vals = [m[k] for m in finals if k in m]
      if len(vals) == len(finals):
        std = np.std(vals, ddof=1) if len(vals) > 1 else 0.
        row[k] = f'{np.mean(vals):.3f} +- {std:.3f}'
    rows.append(row)
    results['methods'].append({'label': label, 'run_dirs': dirs, 'sec_per_step': rate,
                               'final': finals, 'curves': {
                                   os.path.basename(d): curves[f'{label} {os.path.basename(d)}']
                                   for d in dirs}})
  os.makedirs(args.out, exist_ok=True)
  base = os.path.join(args.out, args.name)
  report.write_json(base + '.json', results)
  logged = [label for label in runs if label not in rates]
  time_note = '; '.join(
      ([f'{label}: step x {rate} s (idle-CPU seconds per step, --sec_per_step)'
        for label, rate in rates.items()])
      + ([f"{', '.join(logged)}: seconds as logged by the runs"] if logged else []))
  table = report.markdown_table(rows, [
      ('method', 'method'), ('runs', 'runs'), ('steps', 'steps'), ('time_s', 'train s'),
      ('psnr', 'PSNR'), ('ssim', 'SSIM'), ('lpips_alex', 'LPIPS-alex'),
      ('lpips_vgg', 'LPIPS-vgg')], floatfmt={'time_s': '.0f'})
  text = (f'# {args.name}\n\nFull-resolution test metrics at the end of each run, mean +- '
          f'std over runs; the plot shows the cheap (strided) test PSNR logged during '
          f'training against time ({time_note}).\n\n{table}\n\nCommand:\n\n'
          f'    {results["command"]}\n')
  report.write_markdown(base + '.md', text)
  figures.plot_error_vs_time(curves, base + '.png', metric='psnr',
                            title=f'{args.name}: test PSNR (strided) vs seconds')
  print(text)


if __name__ == '__main__':
  main()
