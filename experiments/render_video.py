"""Camera-path video of two rounds side by side (default: the baseline | the last round).

The path runs through all cameras of the scene (training and test, chained by nearest
neighbour) and back, poses interpolated as the pseudo-views are (lerp + SLERP). Each frame
is <round A> | <round B>, rendered at 1/--downscale of the training resolution. Writes a
GIF (imageio) and a PNG of the middle frame. Fern, after renerf_rounds.py:

  python -m experiments.render_video \
    --run_dir experiments/results/fern_rounds_fast/Re-Nerfing/seed0 \
    --config gin_configs/llff3_fast.gin gin_configs/renerf.gin \
    --data_dir ../shared/data/nerf_llff_data \
    --scene fern --out experiments/results/renerf_rounds_fern/fern_rounds_fast_video.gif
"""
import argparse
import os

import imageio.v3 as iio
import numpy as np

from experiments.tables import bindings_of
from renerf_jax import poses as pose_lib
from renerf_jax import figures, round_driver, rundir
from renerf_jax.backbones import get_backbone
from renerf_jax.configs import load_config
from renerf_jax.datasets import downsample_scene, load_scene


def load_params(config, run_dir, r):
  rdir = rundir.round_dir(run_dir, r)
  if not rundir.is_done(rdir):
    raise SystemExit(f'error: {rdir} is not a finished round')
  return round_driver.load_round_params(config, rdir, r)


def finished_rounds(run_dir):
  r = 0
  while rundir.is_done(rundir.round_dir(run_dir, r)):
    r += 1
  return r


def run_parser(description):
  """An argument parser with a finished run's flags: --run_dir, --config, --gin_bindings,
  --data_dir, --scene (the Config comes from run_config)."""
  p = argparse.ArgumentParser(description=description,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--run_dir', required=True)
  p.add_argument('--config', required=True, nargs='+',
                 help='gin config file(s) of the run, stacked in order')
  p.add_argument('--gin_bindings', action='append', default=[])
  p.add_argument('--data_dir', help='shortcut for Config.data_dir')
  p.add_argument('--scene', help='shortcut for Config.scene')
  return p


def run_config(args):
  """The Config of run_parser's flags."""
  return load_config(args.config, bindings_of(args))


def main():
  p = run_parser(__doc__)
  p.add_argument('--rounds', type=int, nargs=2, default=None,
                 help='the two rounds to show (default: 0 and the last finished)')
  p.add_argument('--frames', type=int, default=40)
  p.add_argument('--fps', type=float, default=10.)
  p.add_argument('--downscale', type=int, default=2)
  p.add_argument('--out', required=True, help='output .gif')
  args = p.parse_args()
  config = run_config(args)
  rounds = args.rounds or (0, finished_rounds(args.run_dir) - 1)
  params = [load_params(config, args.run_dir, r) for r in rounds]
  scene = load_scene(config)
  small = downsample_scene(scene, args.downscale)  # focal and principal point scaled
  path = pose_lib.camera_path(scene.poses, args.frames).astype(np.float32)
  render_views = get_backbone(config).render_views
  # Each model renders the whole path in one call (one compilation of its rays).
  videos = [np.clip(render_views(config, small, prm, path, show_progress=True)['rgb'],
                    0., 1.) for prm in params]
  gap = np.ones((small.height, 4, 3), np.float32)
  frames = [figures.to_uint8(np.concatenate([a, gap, b], 1)) for a, b in zip(*videos)]
  os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
  tmp = args.out + '.tmp.gif'
  iio.imwrite(tmp, np.stack(frames), duration=1000. / args.fps, loop=0)
  os.replace(tmp, args.out)
  figures.save_image_png(os.path.splitext(args.out)[0] + '_frame.png',
                        frames[len(frames) // 4])
  print(f'wrote {args.out}: {len(frames)} frames, rounds {rounds[0]} | {rounds[1]}')


if __name__ == '__main__':
  main()
