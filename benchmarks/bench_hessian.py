"""Throughput of the Laplace Hessian pass (renerf_jax.laplace.hessian_diagonal).

Times the Gauss-Newton diagonal over --rays training rays of the configured scene, after
one compile call, keeping the best of --repeats (the CPU is shared), and prints one JSON
object with seconds per 1000 rays. Timings do not depend on the parameter values, so the
field is freshly initialised.

  PYTHONPATH=. python benchmarks/bench_hessian.py \
      --gin_bindings "Config.dataset_loader='procedural'" --rays 1024
"""
import argparse
import json
import time

import jax
import jax.numpy as jnp
import numpy as np

from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene, ray_pool
from renerf_jax.deformation import grid_size
from renerf_jax.fields import init_field_params
from renerf_jax.laplace import hessian_diagonal, subsample_rays


def scene_box(scene, rays):
  """The grid box: the NDC cube, or (bench only) the bounding box of the rays' segments."""
  if scene.use_ndc:
    return -np.ones(3, np.float32), np.ones(3, np.float32)
  ends = [np.asarray(rays.origins + t * rays.directions) for t in (rays.near, rays.far)]
  pts = np.concatenate(ends)
  return pts.min(0), pts.max(0)


def main(argv=None):
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument('--gin_configs', action='append', default=[])
  parser.add_argument('--gin_bindings', action='append', default=[])
  parser.add_argument('--rays', type=int, default=1024, help='training rays timed')
  parser.add_argument('--chunk', type=int, default=1024, help='rays per jitted chunk')
  parser.add_argument('--log2_res', type=int, default=None,
                      help='grid resolution L (default Config.deform_log2_res)')
  parser.add_argument('--repeats', type=int, default=3)
  args = parser.parse_args(argv)
  config = load_config(args.gin_configs, args.gin_bindings)
  log2_res = config.deform_log2_res if args.log2_res is None else args.log2_res
  scene = load_scene(config)
  pool = ray_pool(scene, scene.train_idx)['rays']
  rays = subsample_rays(pool, args.rays, config.seed)
  n_rays = int(rays.origins.shape[0])
  lo, hi = scene_box(scene, rays)
  params = init_field_params(config, jax.random.PRNGKey(config.seed))
  run = lambda r: jax.block_until_ready(hessian_diagonal(
      config, params, r, lo, hi, log2_res, config.hessian_lambda, chunk=args.chunk))
  chunk = min(args.chunk, n_rays)
  t0 = time.perf_counter()
  run(jax.tree_util.tree_map(lambda x: x[:chunk], rays))  # Compiles the chunk step.
  compile_s = time.perf_counter() - t0
  best = float('inf')
  for _ in range(args.repeats):
    t0 = time.perf_counter()
    h = run(rays)
    best = min(best, time.perf_counter() - t0)
  print(json.dumps({
      'gin_configs': args.gin_configs, 'gin_bindings': args.gin_bindings,
      'rays': n_rays, 'chunk': chunk, 'log2_res': log2_res,
      'vertices': grid_size(log2_res), 'num_samples': config.num_samples,
      'num_levels': config.num_levels, 'net': f'{config.net_depth}x{config.net_width}',
      'backend': jax.default_backend(), 'compile_plus_first_chunk_s': compile_s,
      'seconds': best, 's_per_1000_rays': 1000. * best / n_rays,
      'finite': bool(jnp.all(jnp.isfinite(h)))}, indent=1))


if __name__ == '__main__':
  main()
