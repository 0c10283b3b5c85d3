"""Forward+backward throughput of the field backbones (and of grid gather strategies).

Times a jitted value_and_grad of a squared-error loss of the field's raw outputs
w.r.t. all field parameters, for R rays x S samples, repeating and keeping the best
time (the CPU is shared). Prints one JSON object and a markdown table.

  python -m benchmarks.bench_fields --rays 1024 --samples 64 --repeats 7
"""
import argparse
import json
import time

import jax
import jax.numpy as jnp
import numpy as np
import optax

from renerf_jax.nerf.fields.grid import GridField, grid_indices, normalize_points
from renerf_jax.nerf.fields.mlp import MipMLP


def make_inputs(key, rays, samples):
  """Random sample Gaussians in [-1, 1]^3 and unit view directions.

  Returns:
    (means [R, S, 3], covs [R, S, 3], viewdirs [R, 3]).
  """
  k_m, k_c, k_d = jax.random.split(key, 3)
  means = jax.random.uniform(k_m, (rays, samples, 3), minval=-1., maxval=1.)
  covs = jax.random.uniform(k_c, (rays, samples, 3), minval=1e-6, maxval=1e-4)
  viewdirs = jax.random.normal(k_d, (rays, 3))
  viewdirs = viewdirs / jnp.linalg.norm(viewdirs, axis=-1, keepdims=True)
  return means, covs, viewdirs


def field_step_fn(module, with_adam):
  """A jitted (params, opt_state, inputs) -> (loss, params, opt_state) step."""
  opt = optax.adam(1e-3)

  def loss_fn(params, means, covs, viewdirs):
    raw_rgb, raw_density = module.apply(params, means, covs, viewdirs)
    return jnp.mean((raw_rgb - 0.5)**2) + jnp.mean((raw_density - 0.5)**2)

  @jax.jit
  def step(params, opt_state, means, covs, viewdirs):
    loss, grads = jax.value_and_grad(loss_fn)(params, means, covs, viewdirs)
    if with_adam:
      updates, opt_state = opt.update(grads, opt_state, params)
      params = optax.apply_updates(params, updates)
    else:
      params = grads  # Keeps the gradient computation alive.
    return loss, params, opt_state
  return step, opt


def time_fn(fn, repeats):
  """Best wall time of fn() over `repeats` calls after one warm-up (compile) call."""
  jax.block_until_ready(fn())
  best = float('inf')
  for _ in range(repeats):
    t0 = time.perf_counter()
    jax.block_until_ready(fn())
    best = min(best, time.perf_counter() - t0)
  return best


def bench_field(name, module, inputs, repeats, with_adam):
  """Times one field. Returns a result dict."""
  means, covs, viewdirs = inputs
  params = module.init(jax.random.PRNGKey(0), means[:1, :2], covs[:1, :2], viewdirs[:1])
  step, opt = field_step_fn(module, with_adam)
  opt_state = opt.init(params) if with_adam else None
  n_params = sum(int(np.prod(x.shape)) for x in jax.tree_util.tree_leaves(params))
  secs = time_fn(lambda: step(params, opt_state, means, covs, viewdirs), repeats)
  n = means.shape[0] * means.shape[1]
  return {'name': name, 'params': n_params, 'seconds': secs, 'samples_per_s': n / secs}


def gather_one(table, rows, weights):
  """One gather of all levels and corners (what GridField does)."""
  feats = jnp.take(table, rows, axis=0, mode='clip')
  return jnp.einsum('...c,...cf->...f', weights, feats)


def gather_per_level(offsets, sizes):
  """One gather per level, each from its slice of the table."""
  def fn(table, rows, weights):
    out = []
    for l, (off, size) in enumerate(zip(offsets, sizes)):
      feats = jnp.take(table[off:off + size], rows[..., l, :] - off, axis=0, mode='clip')
      out.append(jnp.einsum('...c,...cf->...f', weights[..., l, :], feats))
    return jnp.stack(out, axis=-2)
  return fn


def gather_per_corner(table, rows, weights):
  """One gather per cell corner (all levels at once)."""
  out = 0.
  for c in range(8):
    feats = jnp.take(table, rows[..., c], axis=0, mode='clip')
    out = out + weights[..., c, None] * feats
  return out


def bench_gathers(module, inputs, repeats):
  """Times the grid encoding alone (index computation, gather, backward to the table)
  with the three gather strategies. Returns a list of result dicts."""
  means = inputs[0]
  layout = module.layout
  table = jax.random.uniform(jax.random.PRNGKey(0), (layout.total, module.num_features),
                             minval=-1e-4, maxval=1e-4)
  strategies = {'one gather': gather_one,
                f'per level ({module.num_levels} gathers)':
                    gather_per_level(layout.offsets, layout.sizes),
                'per corner (8 gathers)': gather_per_corner}
  results = []
  for name, gather in strategies.items():
    def loss_fn(table, means, gather=gather):
      x = normalize_points(means, module.bbox_lo, module.bbox_hi)
      rows, weights = grid_indices(x, layout, module.log2_hashmap_size)
      return jnp.sum(gather(table, rows, weights)**2)
    step = jax.jit(jax.value_and_grad(loss_fn))
    secs = time_fn(lambda: step(table, means), repeats)
    n = means.shape[0] * means.shape[1]
    results.append({'name': f'encoding only: {name}', 'params': int(table.size),
                    'seconds': secs, 'samples_per_s': n / secs})
  return results


def markdown(results, rays, samples):
  lines = [f'fwd+bwd, {rays} rays x {samples} samples, best of repeats', '',
           '| field | params | ms / step | samples / s | vs mlp 8x256 |',
           '| --- | ---: | ---: | ---: | ---: |']
  ref = next((r['samples_per_s'] for r in results if r['name'] == 'mlp 8x256'), None)
  for r in results:
    rel = f"{r['samples_per_s'] / ref:.1f}x" if ref else '-'
    lines.append(f"| {r['name']} | {r['params']:,} | {1e3 * r['seconds']:.1f} | "
                 f"{r['samples_per_s']:,.0f} | {rel} |")
  return '\n'.join(lines)


def main(argv=None):
  parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  parser.add_argument('--rays', type=int, default=1024)
  parser.add_argument('--samples', type=int, default=64)
  parser.add_argument('--repeats', type=int, default=7)
  parser.add_argument('--adam', action='store_true',
                      help='include an Adam update of all parameters in the step')
  parser.add_argument('--no_mlp', action='store_true', help='skip the mip-NeRF MLPs')
  parser.add_argument('--no_gathers', action='store_true',
                      help='skip the gather-strategy comparison')
  args = parser.parse_args(argv)
  inputs = make_inputs(jax.random.PRNGKey(1), args.rays, args.samples)
  fields = {}
  if not args.no_mlp:
    fields['mlp 8x256'] = MipMLP(net_depth=8, net_width=256)
    fields['mlp 4x128'] = MipMLP(net_depth=4, net_width=128, skip_layer=2)
  fields['grid (defaults)'] = GridField()
  fields['grid (defaults) + antialias'] = GridField(antialias=True)
  results = [bench_field(name, m, inputs, args.repeats, args.adam)
             for name, m in fields.items()]
  if not args.no_gathers:
    results += bench_gathers(GridField(), inputs, args.repeats)
  print(json.dumps({'rays': args.rays, 'samples': args.samples, 'repeats': args.repeats,
                    'adam': args.adam, 'backend': jax.default_backend(),
                    'devices': jax.device_count(), 'results': results}, indent=1))
  print()
  print(markdown(results, args.rays, args.samples))


if __name__ == '__main__':
  main()
