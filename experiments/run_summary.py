"""Summarises finished baseline runs (train.py run directories), one per scene.

For each run: the final test metrics of round 0, the best test PSNR of the training
curve (its evaluations use every Config.eval_stride-th pixel) and its step, the training time, steps per second and Gaussians at the end; a
plot of test PSNR against training time (.png); and the first test view, photo | render,
one row per run at half resolution (_renders.png). Reads
what the runs wrote and the photos from the scene; trains nothing. The paper-scale
Gaussians check (experiments/device_gaussians_paper_scale.sh on a GPU, run directories
copied back):

  python -m experiments.run_summary --runs /tmp/gpu/fern /tmp/gpu/orchids \
    --data_dir ../shared/data/nerf_llff_data \
    --out experiments/results/gaussians_paper_scale/baseline
"""
import argparse
import os

import imageio.v3 as iio
import numpy as np

from experiments import tables
from renerf_jax import cli, figures, report, rundir
from renerf_jax.datasets import load_scene
from renerf_jax.evaluation import view_name
from renerf_jax.run_config import load_run_config


def summarise(run_dir):
  """(row dict, curve [(seconds, test PSNR)]) of round 0 of a finished run."""
  path = rundir.result_path(rundir.round_dir(run_dir, 0))
  if not os.path.isfile(path):
    raise SystemExit(f'error: {path} does not exist (round 0 of {run_dir} unfinished?)')
  result = report.read_json(path)
  curve = [c for c in result['curve'] if 'eval_psnr' in c]
  last = result['curve'][-1]
  best = max(curve, key=lambda c: c['eval_psnr']) if curve else last
  m = result['metrics']
  row = {'run': os.path.basename(os.path.normpath(run_dir)), 'psnr': m['psnr'],
         'ssim': m['ssim'], 'lpips_alex': m.get('lpips_alex', float('nan')),
         'best_psnr': best.get('eval_psnr', float('nan')), 'best_step': best['step'],
         'steps': last['step'], 'train_s': last['train_seconds'],
         'steps_per_s': last['step'] / last['train_seconds'],
         'gaussians': last.get('num_gaussians', float('nan'))}
  return row, [(c['train_seconds'], c['eval_psnr']) for c in curve]


def photo_and_render(run_dir, config):
  """[H, 2W, 3] photo | render of the first test view (config: the run's Config)."""
  scene = load_scene(config)
  view = int(scene.test_idx[0])
  png = rundir.render_path(rundir.eval_dir(rundir.round_dir(run_dir, 0)), view_name(view))
  render = iio.imread(png)[..., :3].astype(np.float32) / 255.
  return np.concatenate([np.asarray(scene.images[view], np.float32), render], axis=1)


@cli.exit_on_error
def main():
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--runs', nargs='+', required=True, help='run directories')
  p.add_argument('--data_dir', required=True, help='Config.data_dir for the photos')
  p.add_argument('--out', required=True, help='output prefix (.json, .md, .png, _renders.png)')
  args = p.parse_args()
  # Every run's config first: a damaged config.gin / config.json (or the two disagreeing)
  # is one line and exit 2 before anything is written.
  configs = [load_run_config(run, [f"Config.data_dir = '{args.data_dir}'"])
             for run in args.runs]
  rows, curves = [], {}
  for run in args.runs:
    row, curve = summarise(run)
    rows.append(row)
    curves[row['run']] = curve
  mean = {'run': 'mean'}
  for k in ('psnr', 'ssim', 'lpips_alex', 'best_psnr', 'train_s', 'steps_per_s'):
    mean[k] = float(np.mean([r[k] for r in rows]))
  cmd = tables.command_line('experiments.run_summary')
  os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
  report.write_json(args.out + '.json', {'rows': rows, 'mean': mean, 'curves': curves,
                                         'command': cmd})
  table = report.markdown_table(rows + [mean], [
      ('run', 'run'), ('psnr', 'PSNR'), ('ssim', 'SSIM'), ('lpips_alex', 'LPIPS-alex'),
      ('best_psnr', 'best test PSNR'), ('best_step', 'at step'), ('steps', 'steps'),
      ('train_s', 'train [s]'), ('steps_per_s', 'steps/s'), ('gaussians', 'Gaussians')],
      floatfmt={'best_psnr': '.2f', 'train_s': '.0f', 'steps_per_s': '.1f'})
  table += ('\nPSNR, SSIM, LPIPS: every test view at the end. Best test PSNR: the '
            'training curve\'s evaluations (every Config.eval_stride-th pixel).\n')
  report.write_markdown(args.out + '.md', table + f'\n\nCommand:\n\n    {cmd}\n')
  fig, axes = figures.subplots(1, 1, (6, 4))
  ax = axes[0, 0]
  for name, curve in curves.items():
    if curve:
      ax.plot(*zip(*curve), marker='o', ms=3, label=name)
  ax.set_xlabel('training time [s]')
  ax.set_ylabel('test PSNR [dB] (curve evaluations)')
  ax.legend()
  figures.save_figure(fig, args.out + '.png')
  strips = [photo_and_render(run, config)[::2, ::2]
            for run, config in zip(args.runs, configs)]
  width = max(s.shape[1] for s in strips)
  strips = [np.pad(s, ((0, 4), (0, width - s.shape[1]), (0, 0)), constant_values=1.)
            for s in strips]
  figures.save_image_png(args.out + '_renders.png', np.concatenate(strips, axis=0))
  print(table)


if __name__ == '__main__':
  main()
