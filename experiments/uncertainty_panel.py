"""Laplace-uncertainty masks of one finished model's pseudo-views, with timings and a panel.

Loads round --round of a finished run, synthesises its pseudo-views with masks
(Config.use_masks=True: the Hessian pass, then colour and uncertainty in one render pass)
into --work_dir (resumable, never inside the run), and writes a PNG that stacks the
panels (pseudo-view | uncertainty heat-map | what training sees) of --views, plus a JSON
with the timings and the Hessian pass's share of the round's wall time (the Hessian pass
over the pseudo-view synthesis plus the next round's training, as measured in the run).
Fern, after renerf_rounds.py:

  python -m experiments.uncertainty_panel \
    --run_dir experiments/results/fern_rounds_fast/Re-Nerfing/seed0 \
    --config gin_configs/llff3_fast.gin gin_configs/renerf.gin \
    --data_dir ../shared/data/nerf_llff_data \
    --scene fern --work_dir /tmp/fern_masks \
    --out experiments/results/masks_ablation_fern/fern_uncertainty
"""
import dataclasses
import os

import numpy as np

from experiments import tables
from experiments.render_video import load_params, run_config, run_parser
from renerf_jax import figures, report, round_driver, rundir
from renerf_jax.datasets import load_scene
from renerf_jax.pseudo_views import side_by_side, uncertainty_heatmap


def main(argv=None):
  p = run_parser(__doc__)
  p.add_argument('--round', type=int, default=0, help='the model B whose views are masked')
  p.add_argument('--views', type=int, nargs='+', default=[0, 3, 6])
  p.add_argument('--work_dir', required=True, help='pseudo-views with masks go here')
  p.add_argument('--out', required=True, help='output prefix (.png, .json)')
  args = p.parse_args(argv)
  config = dataclasses.replace(run_config(args), use_masks=True, mask_signal='laplace')
  if config.backbone != 'nerf':
    raise SystemExit(f'error: the Laplace uncertainty needs the NeRF backbone; --config '
                     f'gives Config.backbone={config.backbone!r}')
  if os.path.abspath(args.work_dir).startswith(os.path.abspath(args.run_dir) + os.sep):
    raise SystemExit(f'error: --work_dir {args.work_dir} lies inside --run_dir; '
                     'a finished run is never written to')
  scene = load_scene(config)
  params = load_params(config, args.run_dir, args.round)
  pv, timing, _ = round_driver.stored_synthesis(args.work_dir)(config, scene, params, True)
  seconds = timing['seconds']
  n = pv.images.shape[0]
  bad = [v for v in args.views if not 0 <= v < n]
  if bad:
    raise SystemExit(f'error: --views {bad} out of range: there are {n} pseudo-views')
  rows = [side_by_side(pv.images[v], uncertainty_heatmap(pv.uncertainty[v], pv.uncertainty),
                       pv.masks[v]) for v in args.views]
  gap = np.ones((4,) + rows[0].shape[1:], np.float32)
  panel = np.concatenate([x for r in rows for x in (r, gap)][:-1], axis=0)
  figures.save_image_png(args.out + '.png', panel)
  out = dict(timing, views=args.views, run_dir=args.run_dir, round=args.round,
             hessian_rays=config.hessian_rays, deform_log2_res=config.deform_log2_res,
             command=tables.command_line('experiments.uncertainty_panel'))
  nxt = rundir.result_path(rundir.round_dir(args.run_dir, args.round + 1))
  if os.path.isfile(nxt):
    round_s = report.read_json(nxt)['metrics']['round_seconds']
    out['next_round_seconds_without_masks'] = round_s
    out['hessian_share_of_round'] = timing['hessian_seconds'] / (
        round_s + timing['hessian_seconds'])
  report.write_json(args.out + '.json', out)
  print({k: v for k, v in out.items() if k != 'command'}, f'seconds={seconds:.1f}')


if __name__ == '__main__':
  main()
