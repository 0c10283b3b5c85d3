"""Test renders of a renerf_scenes table side by side: the photo | B | R1 | B 2x longer
(at B's seed, or with --b2x d_seed B's training 2x longer at D's seed: the --no_b2x
tables' control; --b2x control: B's training at D's seed at B's steps).

Reads the test-view PNGs and per-image metrics that every finished round already wrote
(<run>/round_<r>/eval/test_XXX.png, metrics.json) from the run tree of
experiments/renerf_scenes.py (<runs>/<scene>/<row>/seed<k>) and the photos from the
scene; trains and renders nothing. One row per scene, each image titled with its PSNR.
The Gaussians table (experiments/results/gaussians_llff):

  python -m experiments.test_renders --runs experiments/results/gaussians_llff/runs \
    --config experiments/configs/table_gaussians.gin \
    --scenes fern orchids room trex fortress --seed 0 \
    --out experiments/results/gaussians_llff/test_renders_seed0.png
"""
import argparse
import os

import imageio.v3 as iio
import numpy as np

from experiments.renerf_scenes import CONTROL, CONTROL_2X, TWO_X
from renerf_jax import figures, report, rundir
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene
from renerf_jax.evaluation import view_name
from renerf_jax.round_driver import hardest_test_view

# (column title, row folder of renerf_scenes.py, round); the last by --b2x.
COLUMNS = (('B', 'Re-Nerfing', 0), ('R1', 'Re-Nerfing', 1))
B2X_COLUMNS = {'b_seed': ('B 2x longer', TWO_X, 0),
               'd_seed': ("B 2x longer, D's seed", CONTROL_2X, 0),
               'control': ("control (D's seed)", CONTROL, 0)}


def round_render(run_dir, r, view):
  """(image [H, W, 3] in [0, 1], PSNR) of test view `view` (its index in the scene) of
  round r of a finished run. Raises SystemExit with one line if it is missing."""
  rdir, name = rundir.round_dir(run_dir, r), view_name(view)
  png = rundir.render_path(rundir.eval_dir(rdir), name)
  if not rundir.is_done(rdir) or not os.path.isfile(png):
    raise SystemExit(f'error: {png} does not exist (round {r} of {run_dir} unfinished?)')
  per_image = report.read_json(rundir.metrics_path(rundir.eval_dir(rdir)))['per_image']
  psnr = [m['psnr'] for m in per_image if m['name'] == name]
  return iio.imread(png)[..., :3].astype(np.float32) / 255., psnr[0] if psnr else None


def main(argv=None):
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--runs', required=True, help='<out>/<name> of renerf_scenes.py')
  p.add_argument('--config', required=True, nargs='+', help="the table's --config")
  p.add_argument('--gin_bindings', action='append', default=[], help="the table's bindings")
  p.add_argument('--data_dir', default='../shared/data/nerf_llff_data')
  p.add_argument('--scenes', nargs='+', required=True)
  p.add_argument('--seed', type=int, default=0)
  p.add_argument('--test_view', default='0',
                 help="which test view (0: the first of the split; 'farthest': the one "
                      'farthest from the training cameras, as train.py\'s comparison.png)')
  p.add_argument('--b2x', choices=sorted(B2X_COLUMNS), default='b_seed',
                 help="the last column: B 2x longer at B's seed, or at D's seed, or the "
                      "seed-matched control (B's training at D's seed, B's steps)")
  p.add_argument('--out', required=True, help='output .png')
  args = p.parse_args(argv)
  columns = COLUMNS + (B2X_COLUMNS[args.b2x],)
  fig, axes = figures.subplots(len(args.scenes), 1 + len(columns),
                              figsize=(3.2 * (1 + len(columns)), 2.6 * len(args.scenes)))
  for row, sc in enumerate(args.scenes):
    scene = load_scene(load_config(args.config, args.gin_bindings + [
        f'Config.data_dir = {args.data_dir!r}', f'Config.scene = {sc!r}']))
    if args.test_view == 'farthest':
      k = hardest_test_view(scene)
    elif args.test_view.isdigit() and int(args.test_view) < len(scene.test_idx):
      k = int(args.test_view)
    else:
      raise SystemExit(f'error: --test_view {args.test_view}: {sc} has '
                       f"{len(scene.test_idx)} test views (or give 'farthest')")
    view = int(scene.test_idx[k])
    print(f'{sc}: test view {k} of the split ({view_name(view)})')
    panels = [('photo', scene.images[view], None)]
    for title, folder, r in columns:
      img, psnr = round_render(os.path.join(args.runs, sc, folder, f'seed{args.seed}'), r,
                               view)
      panels.append((title, img, psnr))
    for col, (title, img, psnr) in enumerate(panels):
      ax = axes[row][col]
      ax.imshow(np.clip(img, 0., 1.))
      ax.set_xticks([])
      ax.set_yticks([])
      ax.set_title(f'{sc}: {title}' + (f' ({psnr:.2f} dB)' if psnr is not None else ''),
                   fontsize=9)
  fig.tight_layout()
  figures.save_figure(fig, args.out, dpi=110)
  print(f'wrote {args.out}')


if __name__ == '__main__':
  main()
