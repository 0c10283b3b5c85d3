"""The Gaussian rasteriser before and after issue 51, in the same run: a per-stage profile
of one training step and the whole step's time against the number of Gaussians.

python -m benchmarks.bench_raster --out benchmarks/results/gaussians_raster

'old' is the rasteriser and image loss of commit 7346aa4 (benchmarks/raster_old,
verbatim), 'new' the package's (renerf_jax/gaussians). Both run the same scene: n random Gaussians in fern's
world box (as a fresh run starts, bench_gaussians.py), fern at 1/4 (126x94), the config
gaussians_llff3.gin (no tile cap). Every time is the median of --repeats calls after a
warm-up, each call waited for with jax.block_until_ready; compile time is the first
call's (trace, compile and one run).

Stages (each its own jitted function, at --stage_count Gaussians):
  project   projection, SH colours and opacities (forward);
  bin       tile lists (depth order, per tile);
  blend     alpha blending of the lists (forward);
  blend+vjp blending, forward and backward (custom VJP) of a weighted sum of its outputs;
  loss+grad the image loss (L1 + SSIM) and its gradient;
  render+grad  the step's render, loss and gradients of all fields;
  adam      the per-field Adam update;
  step      the whole train_step (render+grad, Adam, density statistics).
"""
import argparse
import contextlib
import dataclasses
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks.bench_throughput import time_calls
from benchmarks.raster_old import loss as old_loss
from benchmarks.raster_old import rasterize as old_rasterize
from benchmarks.raster_old import render as old_render
from experiments.tables import command_line
from renerf_jax import report
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene
from renerf_jax.gaussians import blocks
from renerf_jax.gaussians import loss as new_loss
from renerf_jax.gaussians import params as params_lib
from renerf_jax.gaussians import projection
from renerf_jax.gaussians import rasterize as new_rasterize
from renerf_jax.gaussians import render as new_render
from renerf_jax.gaussians import schedule
from renerf_jax.gaussians import tiles
from renerf_jax.gaussians import training as gtrain

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TILE = gtrain.TILE


def _old_bin(proj, opac, h, w, cap):
  del opac
  return tiles.tile_intersect(proj.means2d, proj.radius, proj.depths, proj.valid, h, w,
                              TILE, cap)[0]


def _old_blend(lists, means2d, conics, colours, opac, depths, h, w, bg):
  return old_rasterize.rasterize(lists, means2d, conics, colours, opac, depths, h, w, bg,
                                 TILE)


def _new_bin(proj, opac, h, w, cap):
  del cap  # The configs' 0: the block lists of every overlap (up to the capacity).
  return blocks.pair_lists(proj.means2d, proj.radius, proj.conics, opac, proj.depths,
                           proj.valid, h, w, TILE, new_rasterize.BLOCK,
                           new_render.CAPACITY)[:2]


def _new_blend(lists, means2d, conics, colours, opac, depths, h, w, bg):
  return new_rasterize.rasterize_blocks(*lists, means2d, conics, colours, opac, depths,
                                        h, w, bg, TILE)


def _old_render(*args, capacity=None, **kwargs):
  del capacity  # The old render had no capacity (its uncapped lists were [T, N]).
  return old_render.render(*args, **kwargs)


IMPLS = {'old': (_old_render, _old_bin, _old_blend, old_loss.image_loss),
         'new': (new_render.render, _new_bin, _new_blend, new_loss.image_loss)}


@contextlib.contextmanager
def renderer(impl):
  """The package's render and image loss (what train_step calls) replaced by the
  implementation's meanwhile."""
  saved = new_render.render, gtrain.image_loss
  new_render.render, gtrain.image_loss = IMPLS[impl][0], IMPLS[impl][3]
  try:
    yield
  finally:
    new_render.render, gtrain.image_loss = saved


def setup(config, scene, n):
  """(config, camera, state, data, extent) of n random Gaussians in the scene's box."""
  cfg = dataclasses.replace(config, gs_capacity=n, gs_init_points=n)
  extent = gtrain.scene_extent(cfg, scene)
  params = gtrain.init_gaussians(cfg, scene, jax.random.PRNGKey(0))
  state = gtrain.init_state(cfg, params, extent)
  return (cfg, gtrain.Camera.of(scene), state, gtrain.training_data(scene),
          jnp.asarray(extent, jnp.float32))


def fresh_step():
  """A new jit of train_step's function, with no cache shared with an earlier one (so
  it traces the renderer in place now, and its compile time is a cold compile's)."""
  jax.clear_caches()

  def step(*args):
    return gtrain.train_step.__wrapped__(*args)
  return jax.jit(step, static_argnums=(0, 1, 2), donate_argnums=(3,))


def time_step(impl, config, scene, n, repeats):
  """(seconds per train step, compile seconds, cap-bound fraction) of n Gaussians."""
  cfg, cam, state, data, extent = setup(config, scene, n)
  key = jax.random.PRNGKey(1)
  with renderer(impl):
    step = fresh_step()
    t = time.perf_counter()
    state, _ = step(cfg, cam, False, state, data, extent, key)
    jax.block_until_ready(state)
    compile_s = time.perf_counter() - t
    holder, bound = [state], []

    def call():
      holder[0], s = step(cfg, cam, False, holder[0], data, extent, key)
      bound.append(s['cap_bound'])
      return s
    step_s = time_calls(call, repeats, warmups=1)
  return step_s, compile_s, float(np.mean(jax.device_get(bound)))


def timed(fn, args, repeats):
  """(median seconds, compile seconds) of a jitted fn(*args)."""
  t = time.perf_counter()
  jax.block_until_ready(fn(*args))
  compile_s = time.perf_counter() - t
  return time_calls(lambda: fn(*args), repeats, warmups=1), compile_s


def stage_profile(impl, config, scene, n, repeats):
  """{stage: (median s, compile s)} of one training step's stages (module docstring)."""
  _, bin_fn, blend_fn, _ = IMPLS[impl]
  cfg, cam, state, data, extent = setup(config, scene, n)
  h, w, cap = cam.h, cam.w, cfg.gs_tile_cap
  g = new_render.sanitise(state.params)
  pose, image = data['poses'][0], data['images'][0]
  bg = gtrain.background(cfg)

  @jax.jit
  def project(g, pose):
    proj = projection.project(g.means, g.log_scales, g.quats, g.active, pose, cam.focal,
                              h, w, gtrain.NEAR)
    return (proj, params_lib.eval_sh(3, g.sh, g.means - pose[:3, 3]),
            jax.nn.sigmoid(g.opacity_logits))

  proj, colours, opac = project(g, pose)
  bins = jax.jit(lambda p, o: bin_fn(p, o, h, w, cap))
  lists = bins(proj, opac)
  screen = (proj.means2d, proj.conics, colours, opac, proj.depths)
  blend = jax.jit(lambda lists, *s: blend_fn(lists, *s, h, w, bg))
  rng = np.random.default_rng(0)
  wts = [jnp.asarray(rng.normal(size=s), jnp.float32) for s in [(h, w, 3), (h, w), (h, w)]]

  @jax.jit
  def blend_vjp(lists, *s):
    f = lambda *s: sum(jnp.sum(o * wt) for o, wt in zip(blend_fn(lists, *s, h, w, bg),
                                                         wts))
    return jax.value_and_grad(f, argnums=range(5))(*s)

  with renderer(impl):
    grads = jax.jit(lambda p: gtrain.loss_and_grads(cfg, cam, p, image, pose,
                                                    data['masks'][0], 3))
    loss_grad = jax.jit(jax.value_and_grad(lambda rgb: IMPLS[impl][3](
        rgb, image, data['masks'][0], cfg.gs_lambda_dssim)[0]))
    opt = schedule.make_optimizer(cfg, extent)
    adam = jax.jit(lambda gr, st, f: opt.update(gr, st, f))
    out = {'project': timed(project, (g, pose), repeats),
           'bin': timed(bins, (proj, opac), repeats),
           'blend': timed(blend, (lists,) + screen, repeats),
           'blend+vjp': timed(blend_vjp, (lists,) + screen, repeats),
           'loss+grad': timed(loss_grad, (blend(lists, *screen)[0],), repeats),
           'render+grad': timed(grads, (state.params,), repeats)}
    fields = gtrain.to_fields(state.params)
    out['adam'] = timed(adam, (grads(state.params)[3], state.opt_state, fields), repeats)
  step_s, compile_s, _ = time_step(impl, config, scene, n, repeats)
  out['step'] = (step_s, compile_s)
  return out


def compare(config, scene, n, views=3):
  """Old against new on n random Gaussians at the first training views: the largest
  |difference| of rgb, depth, acc (render at SH degree 3), and per field of the step's
  gradients (loss_and_grads) the largest |difference| over the largest |gradient|."""
  cfg, cam, state, data, _ = setup(config, scene, n)
  out = {'gaussians': n}
  grads = {}
  for impl in ('old', 'new'):
    with renderer(impl):
      fn = jax.jit(lambda p, pose, image, mask: gtrain.loss_and_grads(
          cfg, cam, p, image, pose, mask, 3))
      grads[impl] = [jax.device_get(fn(state.params, data['poses'][v], data['images'][v],
                                       data['masks'][v])) for v in range(views)]
  for k in ('rgb', 'depth', 'acc'):
    out[k] = max(float(np.abs(a[2][k] - b[2][k]).max())
                 for a, b in zip(grads['old'], grads['new']))
  out['loss'] = max(abs(float(a[0] - b[0])) for a, b in zip(grads['old'], grads['new']))
  for k in gtrain.to_fields(state.params):
    out['grad_' + k] = max(float(np.abs(a[3][k] - b[3][k]).max() /
                                 max(np.abs(a[3][k]).max(), 1e-30))
                           for a, b in zip(grads['old'], grads['new']))
  out['grad2d'] = max(float(np.abs(a[4] - b[4]).max() / max(np.abs(a[4]).max(), 1e-30))
                      for a, b in zip(grads['old'], grads['new']))
  return out


def load(downsample):
  data_dir = os.path.join(os.path.dirname(REPO), 'shared', 'data', 'nerf_llff_data')
  config = load_config([os.path.join(REPO, 'gin_configs', 'gaussians_llff3.gin')],
                       [f'Config.image_downsample = {downsample}',
                        f"Config.data_dir = '{data_dir}'"])
  return config, load_scene(config)


def main():
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--downsample', type=int, default=4)
  p.add_argument('--counts', type=int, nargs='+', default=[1000, 5000, 20000, 100000])
  p.add_argument('--stage_count', type=int, default=20000)
  p.add_argument('--impls', nargs='+', default=['old', 'new'])
  p.add_argument('--repeats', type=int, default=10)
  p.add_argument('--no_stages', action='store_true')
  p.add_argument('--check_counts', type=int, nargs='*', default=[1000, 20000],
                 help='Gaussian counts of the old-against-new numeric check')
  p.add_argument('--out', default=os.path.join(REPO, 'benchmarks', 'results',
                                               'gaussians_raster'))
  args = p.parse_args()
  config, scene = load(args.downsample)
  size = f'{scene.width}x{scene.height}'
  stages = {}
  if not args.no_stages:
    for impl in args.impls:
      stages[impl] = stage_profile(impl, config, scene, args.stage_count, args.repeats)
      print(impl, stages[impl], flush=True)
  rows = []
  for n in args.counts:
    row = {'image': size, 'gaussians': n}
    for impl in args.impls:
      step_s, compile_s, bound = time_step(impl, config, scene, n, args.repeats)
      row.update({f'{impl}_step_s': step_s, f'{impl}_compile_s': compile_s,
                  f'{impl}_cap_bound': bound})
    if 'old' in args.impls and 'new' in args.impls:
      row['speedup'] = row['old_step_s'] / row['new_step_s']
    rows.append(row)
    print(row, flush=True)
  checks = [compare(config, scene, n) for n in args.check_counts]
  for c in checks:
    print(c, flush=True)
  cmd = command_line('benchmarks.bench_raster')
  report.write_json(args.out + '.json', {'command': cmd, 'rows': rows, 'stages': {
      impl: {k: {'median_s': v[0], 'compile_s': v[1]} for k, v in s.items()}
      for impl, s in stages.items()}, 'stage_count': args.stage_count, 'image': size,
      'repeats': args.repeats, 'checks': checks})
  cols = [('image', 'image'), ('gaussians', 'Gaussians')]
  for impl in args.impls:
    cols += [(f'{impl}_step_s', f'{impl} step [s]'),
             (f'{impl}_compile_s', f'{impl} compile [s]'),
             (f'{impl}_cap_bound', f'{impl} tiles at the cap')]
  if 'speedup' in rows[0]:
    cols.append(('speedup', 'old / new'))
  text = f'# Gaussian rasteriser: old (7346aa4) and new\n\nCommand:\n\n    {cmd}\n\n'
  text += '## Train step\n\n' + report.markdown_table(rows, cols) + '\n'
  if stages:
    srows = [dict({'stage': k}, **{f'{impl}_{j}': stages[impl][k][i]
                                   for impl in stages for i, j in enumerate(('s', 'c'))})
             for k in next(iter(stages.values()))]
    scols = [('stage', 'stage')] + [c for impl in stages for c in (
        (f'{impl}_s', f'{impl} [s]'), (f'{impl}_c', f'{impl} compile [s]'))]
    text += (f'\n## Stages at {args.stage_count} Gaussians, {size}\n\n' +
             report.markdown_table(srows, scols) + '\n')
  if checks:
    text += ('\n## Old against new (max |difference|; gradients: over max |gradient|, '
             'per field, 3 training views)\n\n' +
             report.markdown_table(checks, floatfmt='.2e') + '\n')
  report.write_markdown(args.out + '.md', text)


if __name__ == '__main__':
  main()
