"""Gaussian splatting's training step and render against the number of Gaussians and the
image size, beside the grid NeRF's training step (issue 33).

python -m benchmarks.bench_gaussians --out benchmarks/results/gaussians

For each image size (fern's 504x378 downsampled by --downsample) and Gaussian count:
seconds per training step (forward, backward, Adam; median of --repeats after warm-up),
seconds per render (forward only), the fraction of tiles where the tile cap binds, and
the compile time. Gaussians are placed at random in fern's world box (as a fresh run
starts).
The grid NeRF row is `table_converged2.gin`'s step at the same image size. Writes
JSON and a markdown table to --out (.json / .md).
"""
import argparse
import dataclasses
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks.bench_throughput import time_calls
from experiments.tables import command_line
from renerf_jax import report
from renerf_jax.nerf import training
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene
from renerf_jax.gaussians import training as gtrain
from renerf_jax.nerf.pools import make_pools

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def bench_gaussians(config, scene, n, repeats):
  """(train s, render s, cap-bound fraction, compile s) of n random Gaussians."""
  cfg = dataclasses.replace(config, gs_capacity=n, gs_init_points=n)
  extent = gtrain.scene_extent(cfg, scene)
  params = gtrain.init_gaussians(cfg, scene, jax.random.PRNGKey(0))
  state = gtrain.init_state(cfg, params, extent)
  cam = gtrain.Camera.of(scene)
  data = gtrain.training_data(scene)
  extent = jnp.asarray(extent, jnp.float32)
  key = jax.random.PRNGKey(1)
  t = time.perf_counter()
  state, stats = gtrain.train_step(cfg, cam, False, state, data, extent, key)
  jax.block_until_ready(state)
  compile_s = time.perf_counter() - t
  holder = [state]
  bound = []

  def step():
    holder[0], s = gtrain.train_step(cfg, cam, False, holder[0], data, extent, key)
    bound.append(s['cap_bound'])
    return s

  train_s = time_calls(step, repeats, warmups=1)
  pose = jnp.asarray(scene.poses[scene.train_idx[0]], jnp.float32)
  render = lambda: gtrain._render_one(cfg, cam, params, pose)  # pylint: disable=protected-access
  render_s = time_calls(render, repeats, warmups=1)
  return train_s, render_s, float(np.mean(jax.device_get(bound))), compile_s


def bench_grid_nerf(downsample, repeats):
  """Seconds per training step of the grid NeRF table config at this image size."""
  config = load_config([os.path.join(REPO, 'experiments', 'configs',
                                     'table_converged2.gin')],
                       [f'Config.image_downsample = {downsample}'])
  scene = load_scene(config)
  pools = make_pools(config, scene, None)
  cam = training.Camera.of(scene)
  holder = [training.init_state(config, jax.random.PRNGKey(0))]
  key = jax.random.PRNGKey(0)

  def step():
    holder[0], s = training.train_step(config, cam, False, holder[0], pools, key)
    return s
  return time_calls(step, repeats, warmups=2), config.batch_size


def main():
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--downsample', type=int, nargs='+', default=[4, 2])
  p.add_argument('--counts', type=int, nargs='+',
                 default=[1000, 5000, 20000, 50000, 100000])
  p.add_argument('--repeats', type=int, default=10)
  p.add_argument('--tile_cap', type=int, default=None,
                 help='Config.gs_tile_cap (0: no cap)')
  p.add_argument('--out', default=os.path.join(REPO, 'benchmarks', 'results',
                                               'gaussians'))
  args = p.parse_args()
  rows = []
  for k in args.downsample:
    bindings = [f'Config.image_downsample = {k}', "Config.data_dir = '" + os.path.join(
        os.path.dirname(REPO), 'shared', 'data', 'nerf_llff_data') + "'"]
    if args.tile_cap is not None:
      bindings.append(f'Config.gs_tile_cap = {args.tile_cap}')
    config = load_config([os.path.join(REPO, 'gin_configs', 'gaussians_llff3.gin')],
                         bindings)
    scene = load_scene(config)
    size = f'{scene.width}x{scene.height}'
    grid_s, rays = bench_grid_nerf(k, args.repeats)
    rows.append({'model': f'grid NeRF (table_converged2, {rays} rays)', 'image': size,
                 'gaussians': '-', 'train_s': grid_s, 'render_s': float('nan'),
                 'cap_bound': float('nan'), 'compile_s': float('nan')})
    print(rows[-1], flush=True)
    for n in args.counts:
      train_s, render_s, bound, compile_s = bench_gaussians(config, scene, n,
                                                            args.repeats)
      cap = config.gs_tile_cap or 'none'
      rows.append({'model': f'3DGS (tile cap {cap})', 'image': size,
                   'gaussians': n, 'train_s': train_s, 'render_s': render_s,
                   'cap_bound': bound, 'compile_s': compile_s})
      print(rows[-1], flush=True)
  cmd = command_line('benchmarks.bench_gaussians')
  report.write_json(args.out + '.json', {'rows': rows, 'command': cmd,
                                         'cpu_count': os.cpu_count()})
  table = report.markdown_table(rows, [
      ('model', 'model'), ('image', 'image'), ('gaussians', 'Gaussians'),
      ('train_s', 'train step [s]'), ('render_s', 'render [s]'),
      ('cap_bound', 'tiles at the cap'), ('compile_s', 'compile [s]')])
  report.write_markdown(args.out + '.md', '# Gaussian splatting: step time\n\n' + table +
                        f'\n\nCommand:\n\n    {cmd}\n')


if __name__ == '__main__':
  main()
