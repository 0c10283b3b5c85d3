"""Where a trained NeRF puts the rendering weight of its test views (issue 49's diagnosis).

For each test view of a finished round: the fraction of the rendered weight (sum over
samples of w_i) that lies (a) outside Config.grid_box in world space (bounded scenes: the
grid clamps such points onto the box faces unless Config.outside_box = 'empty'; with
contraction it is only the far background), (b) within a distance `--near_dist` of some
training camera centre (world space: not for NDC scenes), and the opacity; with the
per-view PSNR of the round's evaluation.
A run whose test PSNR is low because of floaters shows weight where no surface is.

  python -m experiments.weight_location --run_dir RUN [RUN ...] --out FILE.json
"""
import argparse
import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from renerf_jax import renerf, report, round_driver, rundir
from renerf_jax.configs import load_config
from renerf_jax.datasets import camera_rays, load_scene
from renerf_jax.nerf.model import empty_outside_box, render_rays
from renerf_jax.nerf.regularizers import near_camera_ray_weight


@functools.partial(jax.jit, static_argnums=(0, 4))
def _chunk_weights(config, params, rays, centres, near_dist):
  """Per ray of one chunk: weight outside the box, near a camera, and the opacity."""
  fine = render_rays(config, params, rays, jax.random.PRNGKey(0), train=False)[-1]
  t, w = fine['t_vals'], fine['weights']
  mid = 0.5 * (t[..., 1:] + t[..., :-1])
  pts = rays.origins[:, None] + mid[..., None] * rays.directions[:, None]
  box_only = dataclasses.replace(config, outside_box='empty', contraction='')
  outside = ~empty_outside_box(box_only, pts,
                               jnp.ones_like(w)).astype(bool)
  near = near_camera_ray_weight(rays.origins, rays.directions, t, w, centres, near_dist)
  return jnp.sum(w * outside, -1), near, jnp.sum(w, -1)


def view_weights(config, params, rays, train_centres, near_dist, chunk=4096):
  """Per pixel of one view: weight outside the box, near a training camera, opacity."""
  flat = jax.tree_util.tree_map(lambda x: x.reshape((-1,) + x.shape[3:]), rays)
  n = flat.origins.shape[0]
  outs = [_chunk_weights(config, params, jax.tree_util.tree_map(
      lambda x: x[i:i + chunk], flat), train_centres, float(near_dist))
          for i in range(0, n, chunk)]
  return [np.concatenate([np.asarray(o[k]) for o in outs]) for k in range(3)]


def main(argv=None):
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--run_dir', nargs='+', required=True)
  p.add_argument('--round', type=int, default=0)
  p.add_argument('--near_dist', type=float, default=1.0)
  p.add_argument('--out', required=True)
  p.add_argument('--gin_bindings', action='append', default=[],
                 help="e.g. Config.blender_split='linspace' for a run made before the field")
  args = p.parse_args(argv)
  result = {}
  for run_dir in args.run_dir:
    config = load_config([rundir.config_gin_path(run_dir)], args.gin_bindings)
    scene = load_scene(config)
    cfg = renerf.round_config(config, args.round)
    rdir = rundir.round_dir(run_dir, args.round)
    state = round_driver.load_round(config, rdir, renerf.RoundState(
        params=None, pseudo=None, round_index=args.round - 1))
    per_image = report.read_json(rundir.metrics_path(rundir.eval_dir(rdir)))['per_image']
    centres = jnp.asarray(scene.poses[scene.train_idx][:, :3, 3])
    rows = []
    for i, idx in enumerate(scene.test_idx):
      rays = camera_rays(scene, [idx])
      out_w, near_w, acc = view_weights(cfg, state.params, rays, centres, args.near_dist)
      rows.append({'name': per_image[i]['name'], 'psnr': per_image[i]['psnr'],
                   'outside_box': float(out_w.mean()), 'near_camera': float(near_w.mean()),
                   'opacity': float(acc.mean())})
      print(run_dir, rows[-1], flush=True)
    result[run_dir] = rows
  report.write_json(args.out, result)


if __name__ == '__main__':
  main()
