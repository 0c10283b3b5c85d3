"""Where a train step's time goes: its parts timed alone, with XLA's FLOP and byte counts.

python -m benchmarks.bench_step_breakdown --configs experiments/configs/table_converged.gin \
    gin_configs/llff3_fast.gin

For each config, on the same batch shapes as training.train_step (batch rays + random-
pose patch rays, model.level_samples samples a ray), each part is jitted on its own
and timed (median of --repeats after a warm-up):

  step          the whole training.train_step;
  render+grad   value and gradient of the photometric loss (batch rays, both levels);
  patch+grad    value and gradient of the depth TV term (patch rays, both levels);
  encode+grad   the grid encoding alone (normalise, indices, one gather, trilinear
                weights) and its gradient, for every sample of a step;
  mlps+grad     the density and colour MLPs alone on those samples' features;
  proposal+grad the proposal field and its gradient at the proposal samples of a step
                (Config.sampler = 'proposal' only; the grid parts then count the fine
                samples only);
  adam          the optimiser update of all parameters.

The parts overlap (render+grad contains encode and mlps), so they are not meant to sum
to the step; the table gives each part's share of the step, its GFLOP and GB of memory
traffic (XLA cost analysis of the compiled part) and its arithmetic intensity, so the
next optimisation is chosen from data. Variants in one process (--variant 'NAME=binding;
binding') are timed side by side with the base config, and their step ratio is reported
(absolute times drift on shared machines; ratios within one run do not). Writes JSON
and markdown to benchmarks/results/ (or --out).
"""
import argparse
import os

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks.bench_throughput import time_calls, xla_cost
from experiments.tables import command_line
from renerf_jax import report
from renerf_jax.nerf import mip, model, regularizers, training
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene
from renerf_jax.nerf.fields import make_field
from renerf_jax.nerf.fields.proposal import make_proposal
from renerf_jax.nerf.pools import make_pools


def _time(fn, args, repeats):
  """Compile fn(*args) and time it; returns (median seconds, GFLOP, GB accessed)."""
  compiled = jax.jit(fn).lower(*args).compile()
  return (time_calls(lambda: compiled(*args), repeats),) + xla_cost(compiled)


def parts(config, repeats):
  """Timed parts of one config's train step: [{'part', 'seconds', 'gflop', 'gb'}]."""
  scene = load_scene(config)
  pools = make_pools(config, scene, None)
  cam = training.Camera.of(scene)
  key = jax.random.PRNGKey(0)
  state = training.init_state(config, key)
  k_real, k_pseudo, k_patch, k_render = jax.random.split(key, 4)
  batch, _ = training.draw_batch(config, pools, False, k_real, k_pseudo)
  n_patches = max(config.batch_size_random // config.patch_size**2, 1)
  patches = training.random_patch_rays(pools['random_poses'], k_patch, n_patches,
                                       config.patch_size, cam)
  flat = jax.tree_util.tree_map(lambda x: x.reshape((-1,) + x.shape[3:]), patches)
  step = jnp.float32(config.max_steps // 2)
  rows = []

  def add(name, fn, *args):
    sec, gflop, gb = _time(fn, args, repeats)
    rows.append({'part': name, 'seconds': sec, 'gflop': gflop, 'gb': gb})
    print(f'  {name}: {sec * 1e3:.1f} ms, {gflop:.2f} GFLOP, {gb:.3f} GB', flush=True)

  # The whole step (not donated here: the same state is reused every call).
  add('step', lambda s, pl, k: training.train_step.__wrapped__(config, cam, False, s, pl, k),
      state, pools, key)
  grad = jax.value_and_grad(training.loss_fn, has_aux=True)
  add('render+grad', lambda p, b, k: grad(p, config, cam, b, None, step, k), state.params,
      batch, k_render)

  def patch_loss(p, k):
    levels = training.render_rays(config, p, flat, k, train=True)
    return regularizers.depth_tv(levels[-1]['distance'].reshape(patches.origins.shape[:3]))
  add('patch+grad', jax.value_and_grad(patch_loss), state.params, k_render)

  rays = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), batch['rays'], flat)
  if config.field == 'grid':
    field = make_field(config)
    field_params = {'params': state.params['params']}
    # The samples of a step: the coarse samples of its batch and patch rays, once per level
    # that evaluates the scene field (the fine samples lie on the same rays), so that the
    # gather sees ray-coherent points.
    _, (means, covs) = mip.sample_along_rays(
        key, rays.origins, rays.directions, rays.radii, config.num_samples, rays.near,
        rays.far, True, config.lindisp, config.ray_shape)
    means = jnp.tile(means.reshape(-1, 3), (model.colour_levels(config), 1))
    covs = jnp.tile(covs.reshape(-1, 3), (model.colour_levels(config), 1))
    n = means.shape[0]
    enc = lambda p, m: jnp.sum(field.apply(p, m, covs, method=field.encode)**2)
    add('encode+grad', jax.value_and_grad(enc), field_params, means)
    feats = field.apply(field_params, means, covs, method=field.encode)
    viewdirs = jnp.zeros((n, 3)).at[:, 2].set(-1.)

    def mlps(p, f):
      rgb, dens = field.apply(p, f[:, None], viewdirs, method=field.decode)
      return jnp.sum(rgb**2) + jnp.sum(dens**2)
    add('mlps+grad', jax.value_and_grad(mlps), field_params, feats)
  if config.sampler == 'proposal':
    proposal = make_proposal(config)
    _, (p_means, _) = mip.sample_along_rays(
        key, rays.origins, rays.directions, rays.radii, config.proposal_samples,
        rays.near, rays.far, True, config.lindisp, config.ray_shape)
    prop = lambda p, m: jnp.sum(proposal.apply({'params': p}, m)**2)
    add('proposal+grad', jax.value_and_grad(prop), state.params['proposal'],
        p_means.reshape(-1, 3))

  opt = training.make_optimizer(config)
  grads = jax.tree_util.tree_map(jnp.ones_like, state.params)
  add('adam', lambda g, o, p: opt.update(g, o, p), grads, state.opt_state, state.params)
  total = rows[0]['seconds']
  for r in rows:
    r['share_of_step'] = r['seconds'] / total
    r['flop_per_byte'] = r['gflop'] / r['gb'] if r['gb'] > 0 else np.nan
    r['gflop_per_s'] = r['gflop'] / r['seconds']
    r['gb_per_s'] = r['gb'] / r['seconds']
  return rows


def main(argv=None):
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--configs', nargs='+', default=['experiments/configs/table_converged.gin'])
  p.add_argument('--data_dir', default='../shared/data/nerf_llff_data')
  p.add_argument('--variant', action='append', default=[],
                 help="'NAME=binding;binding': the first config with these bindings, "
                      'timed in the same process')
  p.add_argument('--repeats', type=int, default=7)
  p.add_argument('--out', default='benchmarks/results/step_breakdown')
  args = p.parse_args(argv)
  base = [f'Config.data_dir = {args.data_dir!r}']
  runs = [(os.path.basename(c), c, base) for c in args.configs]
  for spec in args.variant:
    name, _, extra = spec.partition('=')
    runs.append((name, args.configs[0], base + [b for b in extra.split(';') if b.strip()]))
  rows = []
  for name, path, bindings in runs:
    print(name, flush=True)
    for r in parts(load_config([path], bindings), args.repeats):
      rows.append(dict(r, config=name))
  step = {r['config']: r['seconds'] for r in rows if r['part'] == 'step'}
  first = runs[0][0]
  for r in rows:
    r['step_vs_first'] = step[first] / step[r['config']] if r['part'] == 'step' else np.nan
  table = report.markdown_table(rows, [
      ('config', 'config'), ('part', 'part'), ('seconds', 's'),
      ('share_of_step', 'of step'), ('gflop', 'GFLOP'), ('gb', 'GB accessed'),
      ('flop_per_byte', 'FLOP/byte'), ('gflop_per_s', 'GFLOP/s'), ('gb_per_s', 'GB/s'),
      ('step_vs_first', f'speed-up vs {first}')], floatfmt={
          'seconds': '.4f', 'share_of_step': '.0%', 'gflop': '.2f', 'gb': '.3f',
          'flop_per_byte': '.2f', 'gflop_per_s': '.1f', 'gb_per_s': '.1f',
          'step_vs_first': '.2f'})
  command = command_line('benchmarks.bench_step_breakdown', argv)
  text = (f'{table}\n\nParts overlap (render+grad contains encode and mlps); "of step" is '
          f'each part\'s time over the whole step\'s. Device: {jax.devices()[0]}, '
          f'{os.cpu_count()} CPUs.\n\nCommand:\n\n    {command}\n')
  report.write_json(args.out + '.json', {'rows': rows, 'command': command})
  report.write_markdown(args.out + '.md', text)
  print(text)


if __name__ == '__main__':
  main()
