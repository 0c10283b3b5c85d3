"""Uncertainty quality: does U rank where the baseline B is wrong? (sparsification, AUSE)

For every scene and seed it trains B (round 0 of a run directory <out>/<name>/<scene>/
seed<k>, resumable, reused when finished), runs both Hessian passes (config.hessian_rays
subsampled training rays, and all training rays), renders every variant of
renerf_jax.uncertainty.signals along the test views (one render) and one pseudo-view
(--panel_view), and measures each U against B's per-pixel error on the test views
(renerf_jax.uncertainty.quality): RGB squared error everywhere, and on the embedded
procedural scene also the absolute z-depth error (its true depths are exact; the NDC
'distance' is converted to z-depth first). With --views validation the signals are
measured on the capture's validation views instead (Config.val_views): the choice of a
mask signal for a table is made there, never on its test views. --baseline_from copies a
finished B made with the same baseline config from another run directory instead of
training it again. The signals of a run are kept in
<out>/<name>/<scene>/seed<k>_signals.npz and its measures in seed<k>_quality.json
(reused; --recompute redoes them).

Writes <out>/<name>.json and .md (per scene x variant: AUSE, AURG, mask lift at
Config.mask_keep_frac, Hessian and render seconds; means over scenes; per-seed values;
the targets of the issue for the best variant), <out>/<name>_<scene>.png (sparsification
curves of all variants, the oracle and random) and <out>/<name>_<scene>_panel.png
(pseudo-view | U | masked view for the best variant and for 'laplace'; test view | U |
error). Six scenes, two seeds, the hour-budget config:

  python -m experiments.uncertainty_quality --name uq_tiny \
    --scenes procedural fern orchids room trex fortress --seeds 0 1

The grid's mask signal on garden's validation views, B from the paper-setting table:

  python -m experiments.uncertainty_quality --name uq_grid_garden_val \
    --out experiments/results/paper_table2_360 --config gin_configs/garden30.gin \
    --data_dir ../shared/data/mipnerf360 --scenes garden --seeds 0 1 --views validation \
    --baseline_from 'experiments/results/paper_table2_360/grid/{scene}/Re-Nerfing/seed{seed}'
"""
import argparse
import dataclasses
import json
import os
import sys
import time

import numpy as np

from experiments import sharing
from experiments.tables import command_line, mean_std
from renerf_jax import cli, figures, jit_cache, renerf, report, round_driver, rundir
from renerf_jax.errors import ConfigError
from renerf_jax.nerf import contraction
from renerf_jax.configs import load_config
from renerf_jax.datasets import camera_rays, load_scene, ray_pool
from renerf_jax.progress import progress_bar
from renerf_jax.pseudo_views import pseudo_view_poses, side_by_side, uncertainty_heatmap
from renerf_jax.uncertainty import quality as uq
from renerf_jax.uncertainty import signals as us
from renerf_jax.uncertainty.masks import threshold_for_keep_fraction

# The embedded scene at the table config's image size (126 x 94), rendered directly.
PROCEDURAL = ["Config.dataset_loader = 'procedural'", 'Config.procedural_size = (94, 126)',
              'Config.image_downsample = 1']
SIGNALS_VERSION = 2  # Bump when a signal's definition or name changes (cached signals
# are redone; 2: 'ours' became 'laplace').


def parser():
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--name', default='uq')
  p.add_argument('--config', nargs='+', default=['experiments/configs/table_tiny.gin'])
  p.add_argument('--data_dir', default='../shared/data/nerf_llff_data')
  p.add_argument('--scenes', nargs='+', default=['procedural', 'fern'],
                 help="LLFF scene names, or 'procedural' (the embedded scene)")
  p.add_argument('--seeds', type=int, nargs='+', default=[0])
  p.add_argument('--gin_bindings', action='append', default=[])
  p.add_argument('--out', default='experiments/results')
  p.add_argument('--panel_view', type=int, default=3, help='pseudo-view of the panel')
  p.add_argument('--recompute', action='store_true', help='redo cached signals')
  p.add_argument('--views', choices=('test', 'validation'), default='test',
                 help="the views U is measured on ('validation': Config.val_views, for "
                 'choosing a signal without the test views)')
  p.add_argument('--baseline_from', default=None,
                 help="a finished run directory ('{scene}' and '{seed}' filled in) whose B "
                 'was made with the same baseline config: copied instead of trained')
  return p


def bindings_of(args, scene_name, seed):
  base = PROCEDURAL if scene_name == 'procedural' else [
      f'Config.data_dir = {args.data_dir!r}', f'Config.scene = {scene_name!r}']
  return base + args.gin_bindings + ['Config.num_rounds = 0', f'Config.seed = {seed}']


def test_errors(scene, out):
  """Per-pixel RGB squared error and (with true depths) |z-depth error| [views, H, W]."""
  idx = scene.test_idx
  err = uq.rgb_squared_error(out['rgb'], scene.images[idx])
  if scene.depths is None:
    return err, None
  if scene.use_ndc:
    world = camera_rays(dataclasses.replace(scene, use_ndc=False), idx)
    depth = uq.ndc_t_to_z_depth(out['distance'], world.origins, world.directions)
  else:  # Directions have unit camera z: t is the z-depth.
    depth = out['distance']
  cap = 2. * float(scene.depths.max())
  return err, uq.depth_abs_error(depth, scene.depths[idx], cap)


def compute_run(config, scene, params, panel_view, pose_scene=None):
  """Both Hessian passes, then every signal on the scene's test views (the validation
  views' scene with --views validation) and one pseudo-view of pose_scene (default scene:
  the capture as trained, whose test views stay test views)."""
  box = contraction.CONTRACTED_BOX if config.contraction else scene.bbox  # as renerf.py
  lo, hi = (np.asarray(b, np.float32) for b in box)
  tables, info = us.hessian_tables(config, params, ray_pool(scene, scene.train_idx)['rays'],
                                   lo, hi, show_progress=True)
  t0 = time.perf_counter()
  test = us.render_signals(config, params, camera_rays(scene, scene.test_idx), lo, hi,
                           tables, show_progress=True, desc='test views')
  info['render_seconds'] = time.perf_counter() - t0
  poses, _ = pseudo_view_poses(config, pose_scene or scene)
  pose = poses[min(panel_view, len(poses) - 1)][None]
  pv = us.render_signals(config, params, camera_rays(scene, None, pose), lo, hi, tables)
  err, derr = test_errors(scene, test)
  arrays = {f'test_{k}': v for k, v in test.items()}
  arrays.update({f'pv_{k}': v[0] for k, v in pv.items()}, err=err)
  if derr is not None:
    arrays['depth_err'] = derr
  return arrays, info


def measure(arrays, keep_frac):
  """quality() of every variant against the RGB error (and the depth error)."""
  res = {}
  for v in us.VARIANTS:
    q = uq.quality(arrays[f'test_{v}'], arrays['err'], keep_frac)
    if 'depth_err' in arrays:
      d = uq.quality(arrays[f'test_{v}'], arrays['depth_err'], keep_frac)
      q.update({f'depth_{k}': x for k, x in d.items()})
    res[v] = q
  return res


def run_one(args, root, scene_name, seed):
  """Trains (or reuses) B and measures its signals; returns the run's quality dict."""
  config = load_config(args.config, bindings_of(args, scene_name, seed))
  scene = load_scene(config)
  run_dir = os.path.join(root, scene_name, f'seed{seed}')
  qpath, npath = run_dir + '_quality.json', run_dir + '_signals.npz'
  measured = scene
  if args.views == 'validation':
    if not len(scene.val_idx):
      raise ConfigError(f'--views validation: scene {scene_name!r} has no validation '
                        'views (set Config.val_views)')
    measured = renerf.validation_scene(scene)
  cli.check_run_dir(config, run_dir, create=True)
  if os.path.isfile(qpath) and os.path.isfile(npath) and not args.recompute:
    q = report.read_json(qpath)
    if (q.get('version') == SIGNALS_VERSION and q.get('views', 'test') == args.views
        and rundir.is_done(rundir.round_dir(run_dir, 0))):
      print(f'{scene_name} seed{seed}: reused {qpath}', file=sys.stderr)
      return q
  if args.baseline_from and not os.path.exists(rundir.round_dir(run_dir, 0)):
    src = args.baseline_from.format(scene=scene_name, seed=seed)
    sharing.copy_baseline(config, src, run_dir)
    report.write_json(rundir.shared_baseline_path(run_dir), {'from': src})  # as tables
  state = round_driver.run_rounds(config, scene, run_dir, show_progress=False)
  arrays, info = compute_run(config, measured, state.params, args.panel_view, scene)
  with report.atomic_open(npath, 'wb') as f:
    np.savez_compressed(f, **arrays)
  round_s = float(state.metrics[0]['round_seconds'])
  q = dict(info, version=SIGNALS_VERSION, scene=scene_name, seed=seed, views=args.views,
           keep_frac=config.mask_keep_frac, round_seconds=round_s,
           psnr=float(state.metrics[0]['psnr']),
           deform_log2_res=config.deform_log2_res, variants=measure(arrays, config.mask_keep_frac))
  report.write_json(qpath, q)  # Last: marks the run's signals as complete.
  jit_cache.release_compiled()
  return q


def summarize(runs):
  """Rows per (scene, variant) over seeds, means over scenes, the best variant, targets."""
  rows, scenes = [], list(dict.fromkeys(r['scene'] for r in runs))
  keys = ['ause', 'aurg', 'lift']
  if any('depth_ause' in r['variants']['laplace'] for r in runs):
    keys += ['depth_ause', 'depth_aurg', 'depth_lift']
  for sc in scenes:
    rs = [r for r in runs if r['scene'] == sc]
    for v in us.VARIANTS:
      row = {'scene': sc, 'variant': v, 'seeds': len(rs)}
      for k in keys:
        if k in rs[0]['variants'][v]:
          row[k], row[k + '_std'] = mean_std([r['variants'][v][k] for r in rs])
      kind = us.HESSIAN_OF.get(v)
      row['hessian_seconds'] = mean_std([r['hessian_seconds'][kind] for r in rs])[0] if kind else 0.
      row['hessian_rays'] = rs[0]['hessian_rays'][kind] if kind else 0
      row['render_seconds'] = mean_std([r['render_seconds'] for r in rs])[0]
      row['round_seconds'] = mean_std([r['round_seconds'] for r in rs])[0]
      row['per_seed'] = {str(r['seed']): {k: r['variants'][v].get(k) for k in keys}
                         for r in rs}
      rows.append(row)
  means = []
  winner = {sc: min((r for r in rows if r['scene'] == sc), key=lambda r: r['ause'])['variant']
            for sc in scenes}
  for v in us.VARIANTS:
    vr = [r for r in rows if r['variant'] == v]
    means.append({'variant': v, 'scenes': len(vr), **{
        k: float(np.mean([r[k] for r in vr])) for k in ('ause', 'aurg', 'lift',
                                                         'hessian_seconds')},
                  'scenes_best': sum(w == v for w in winner.values()),
                  'scenes_aurg_above_0': sum(r['aurg'] > 0. for r in vr)})
  best = min(means, key=lambda m: m['ause'])['variant']
  br = [r for r in rows if r['variant'] == best]
  free = {m['variant']: m['ause'] for m in means if m['variant'] in us.HESSIAN_FREE}
  targets = {
      'aurg_above_0_every_scene': bool(all(r['aurg'] > 0. for r in br)),
      'mean_ause_below_every_hessian_free': bool(all(
          next(m['ause'] for m in means if m['variant'] == best) < a
          for v, a in free.items() if v != best)),
      'lift_at_least_1.5_every_scene': bool(all(r['lift'] >= 1.5 for r in br)),
      'mean_lift': next(m['lift'] for m in means if m['variant'] == best),
      'scenes_aurg_not_above_0': [r['scene'] for r in br if not r['aurg'] > 0.],
      'scenes_lift_below_1.5': [r['scene'] for r in br if not r['lift'] >= 1.5]}
  return rows, means, best, targets


def markdown(name, rows, means, best, targets, keep_frac, invocations, views='test'):
  f = lambda r, k, d=3: (f"{r[k]:.{d}f} +- {r[k + '_std']:.{d}f}" if k in r else '')
  lines = [f'# {name}', '', 'Uncertainty U of the baseline B against its per-pixel error on '
           f'the {views} views (renerf_jax.uncertainty.quality). AUSE: area between the '
           'sparsification curve and the oracle (lower is better); AURG: area between '
           'random and the curve (> 0 better than random); curves normalised by the mean '
           f'error of all pixels, removed fraction 0..0.99. Lift: mean error of the masked '
           f'pixels / of the kept ones at keep fraction {keep_frac}. Mean +- std over seeds. '
           'Hessian s: the pass the variant needs (render s: the one render of the '
           f'{views} views that gives every variant, shared).', '',
           '| scene | variant | AUSE (RGB) | AURG (RGB) | lift | AUSE (depth) | AURG (depth) '
           '| Hessian rays | Hessian s | render s | B round s |', '|---|' * 1 + '---|' * 10]
  for r in rows:
    lines.append(f"| {r['scene']} | {r['variant']} | {f(r, 'ause')} | {f(r, 'aurg')} | "
                 f"{f(r, 'lift', 2)} | {f(r, 'depth_ause')} | {f(r, 'depth_aurg')} | "
                 f"{r['hessian_rays']} | {r['hessian_seconds']:.1f} | "
                 f"{r['render_seconds']:.1f} | {r['round_seconds']:.0f} |")
  lines += ['', '## Mean over scenes', '', '| variant | scenes | AUSE | AURG | lift | '
            'Hessian s | best AUSE on | AURG > 0 on |', '|---|---|---|---|---|---|---|---|']
  for m in sorted(means, key=lambda m: m['ause']):
    lines.append(f"| {m['variant']} | {m['scenes']} | {m['ause']:.4f} | {m['aurg']:.4f} | "
                 f"{m['lift']:.2f} | {m['hessian_seconds']:.1f} | {m['scenes_best']} | "
                 f"{m['scenes_aurg_above_0']} |")
  lines += ['', f'Best on mean AUSE: **{best}**. Targets for it: ' + ', '.join(
      f'{k}: {v:.2f}' if isinstance(v, float) else f'{k}: {v}' for k, v in targets.items())
            + (' (the best is itself Hessian-free: compared with the other two)'
               if best in us.HESSIAN_FREE else ''),
            '', '## Per seed (AUSE / AURG / lift)', '', '| scene | variant | ' + ' | '.join(
                f'seed {s}' for s in rows[0]['per_seed']) + ' |',
            '|---|---|' + '---|' * len(rows[0]['per_seed'])]
  for r in rows:
    lines.append(f"| {r['scene']} | {r['variant']} | " + ' | '.join(
        f"{q['ause']:.3f} / {q['aurg']:.3f} / {q['lift']:.2f}" for q in r['per_seed'].values())
                 + ' |')
  lines += ['', 'Commands (wall time of each invocation):', '']
  lines += [f"    {i['command']}    # {i['wall_seconds'] / 60.:.1f} min" for i in invocations]
  return '\n'.join(lines) + '\n'


def plot_curves(runs, scene, path):
  rs = [r for r in runs if r['scene'] == scene]
  kinds = [('', 'RGB squared error')] + (
      [('depth_', '|depth error|')] if 'depth_curve' in rs[0]['variants']['laplace'] else [])
  fig, axes = figures.subplots(1, len(kinds), figsize=(6 * len(kinds), 4.2))
  x = uq.DEFAULT_FRACTIONS
  for ax, (p, title) in zip(axes[0], kinds):
    for v in us.VARIANTS:
      c = np.mean([r['variants'][v][p + 'curve'] for r in rs], axis=0)
      ause = np.mean([r['variants'][v][p + 'ause'] for r in rs])
      ax.plot(x, c, ls='--' if v in us.HESSIAN_FREE else '-', label=f'{v} ({ause:.3f})')
    ax.plot(x, np.mean([r['variants']['laplace'][p + 'oracle'] for r in rs], axis=0), 'k',
            lw=2, label='oracle')
    ax.axhline(1., color='gray', ls=':', label='random')
    ax.set_xlabel('fraction of pixels removed (most uncertain first)')
    ax.set_ylabel('mean error of kept pixels / mean error')
    ax.set_title(f'{scene}: {title}, {len(rs)} seed(s); legend: AUSE')
    ax.legend(fontsize=7)
  fig.tight_layout()
  figures.save_figure(fig, path, dpi=100)


def plot_panel(npz_path, variants, keep_frac, path, views='test'):
  """Rows: pseudo-view | U | masked view per variant; test view | U | error (first)."""
  with np.load(npz_path) as z:
    a = dict(z)
  rgb = np.clip(a['pv_rgb'], 0., 1.)
  rows, titles = [], []
  for v in variants:
    u = a[f'pv_{v}']
    mask = u <= threshold_for_keep_fraction(u, keep_frac)
    rows.append(side_by_side(rgb, uncertainty_heatmap(u), mask))
    titles.append(f'pseudo-view | U = {v} (quantiles) | masked view (keep {keep_frac})')
  u = a[f'test_{variants[0]}'][0]
  rows.append(side_by_side(np.clip(a['test_rgb'][0], 0., 1.), uncertainty_heatmap(u),
                           np.ones(u.shape)))
  rows[-1][:, -u.shape[1]:] = uncertainty_heatmap(a['err'][0])
  titles.append(f'{views} view (B) | U = {variants[0]} | RGB error (quantiles)')
  fig, axes = figures.subplots(len(rows), 1, figsize=(9, 2.6 * len(rows)))
  for ax, img, t in zip(axes[:, 0], rows, titles):
    ax.imshow(np.clip(img, 0., 1.), interpolation='nearest')
    ax.set_title(t, fontsize=9)
    ax.axis('off')
  fig.tight_layout()
  figures.save_figure(fig, path, dpi=100)


@cli.exit_on_error
def main(argv=None):
  t0 = time.perf_counter()
  args = parser().parse_args(argv)
  jit_cache.enable_compilation_cache()
  root = os.path.join(args.out, args.name)
  jobs = [(sc, s) for sc in args.scenes for s in args.seeds]
  bar = progress_bar(total=len(jobs), unit='run', desc='uncertainty quality')
  runs = []
  try:
    for scene_name, seed in jobs:
      runs.append(run_one(args, root, scene_name, seed))
      bar.update(1)
  finally:  # An error's line then starts a line of its own.
    bar.close()
  rows, means, best, targets = summarize(runs)
  keep_frac = runs[0]['keep_frac']
  command = command_line('experiments.uncertainty_quality', argv)
  log = os.path.join(root, 'invocations.jsonl')
  rundir.append_jsonl(log, {'command': command, 'wall_seconds': time.perf_counter() - t0})
  invocations = rundir.read_jsonl(log)
  report.write_json(os.path.join(args.out, args.name + '.json'), {
      'name': args.name, 'config': args.config, 'bindings': args.gin_bindings,
      'scenes': args.scenes, 'seeds': args.seeds, 'views': args.views,
      'variants': list(us.VARIANTS),
      'rows': rows, 'means': means, 'best': best, 'targets': targets,
      'keep_frac': keep_frac, 'fractions': uq.DEFAULT_FRACTIONS.tolist(),
      'runs': [{k: v for k, v in r.items() if k != 'variants'} for r in runs],
      'command': command, 'invocations': invocations})
  md = markdown(args.name, rows, means, best, targets, keep_frac, invocations, args.views)
  report.write_markdown(os.path.join(args.out, args.name + '.md'), md)
  panel_variants = [best] + (['laplace'] if best != 'laplace' else [])
  for sc in dict.fromkeys(args.scenes):
    plot_curves(runs, sc, os.path.join(args.out, f'{args.name}_{sc}.png'))
    seed = min(r['seed'] for r in runs if r['scene'] == sc)
    plot_panel(os.path.join(root, sc, f'seed{seed}_signals.npz'), panel_variants,
               keep_frac, os.path.join(args.out, f'{args.name}_{sc}_panel.png'), args.views)
  print(md)
  print(json.dumps({'best': best, 'targets': targets}))


if __name__ == '__main__':
  main()
