"""Is the baseline B converged? Validation metrics of B trained for several step counts.

B's length is chosen on validation views (Config.val_views > 0: views neither trained on
nor tested, datasets/split.py), never on test views: the table scores the runs'
val_<metric> means (--score_on val, the default); --score_on test re-tabulates the runs
of the tables made before issue 60 as they were made, on test views.

A converged B is one that 2x more steps no longer improves (issue 18: B trained 2x longer
gains at most 0.1 dB PSNR and 0.005 SSIM, mean over seeds). The lr schedule depends on
max_steps (log-linear decay over the whole run), so "B at N steps" is a run of its own
for every N, not an iterate of a longer run. For every scene, seed and N in --steps it
trains the baseline (round 0 of a run directory <out>/<name>/<scene>/N<N>/seed<k>,
resumable, reused when finished; with the config's other settings unchanged, so that
experiments/renerf_scenes.py --reuse can copy these runs as its B and its B 2x) and reports, per scene and N, the mean +- std over seeds
of PSNR / SSIM / LPIPS and the paired gain of 2N over N (same seed).

Invocations can be split by scene or seed; each writes the table of every finished run
it finds. The converged-regime config on 2 CPU cores (experiments/configs/
table_converged.gin), fern, seed 0 (experiments/results/converged_baseline_llff/converged8.md):

  python -m experiments.convergence --name converged8 \
    --config experiments/configs/table_converged.gin --scenes fern \
    --seeds 0 --steps 250 500 1000 2000

Writes <out>/<name>.json, <name>.md and <name>.png (metrics against steps and against
training seconds, one column per scene, mean +- std over seeds).
"""
import argparse
import os
import sys

from experiments.tables import command_line, mean_std
from renerf_jax import cli, figures, jit_cache, report, round_driver, rundir
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene
from renerf_jax.progress import progress_bar

METRICS = ('psnr', 'ssim', 'lpips_alex')
# Issue 18's convergence criterion: what B trained 2x longer may still gain.
MAX_GAIN = {'psnr': 0.1, 'ssim': 0.005}


def parser():
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--name', required=True)
  p.add_argument('--config', nargs='+', required=True, help='gin config file(s)')
  p.add_argument('--data_dir', default='../shared/data/nerf_llff_data')
  p.add_argument('--scenes', nargs='+', default=['fern'])
  p.add_argument('--seeds', type=int, nargs='+', default=[0])
  p.add_argument('--steps', type=int, nargs='+', required=True, help='max_steps values')
  p.add_argument('--gin_bindings', action='append', default=[])
  p.add_argument('--out', default='experiments/results')
  p.add_argument('--score_on', choices=('val', 'test'), default='val',
                 help='score on validation views (Config.val_views > 0; the rule) or on '
                 'test views (the tables made before issue 60)')
  p.add_argument('--train', action=argparse.BooleanOptionalAction, default=True,
                 help='train missing runs (--no-train: only tabulate finished ones)')
  return p


def run_dir_of(root, scene, steps, seed):
  return os.path.join(root, scene, f'N{steps}', f'seed{seed}')


def finished(root, scene, steps, seed):
  """Metrics and curve of a finished baseline, or None."""
  rdir = rundir.round_dir(run_dir_of(root, scene, steps, seed), 0)
  if not rundir.is_done(rdir):
    return None
  return report.read_json(rundir.result_path(rdir))


def score(result, metric, on, where):
  """A finished run's mean `metric` on validation (on='val') or test views (on='test');
  ValueError naming the run where it has no validation metrics."""
  key = metric if on == 'test' else f'val_{metric}'
  if key not in result['metrics']:
    raise ValueError(f'{where}: no validation metrics (bind Config.val_views > 0, or '
                     '--score_on test for the tables made before issue 60)')
  return result['metrics'][key]


def summarize(root, scenes, seeds, steps, on='val'):
  """Rows per (scene, N): mean +- std and the paired gain of the next N (= 2N if given),
  scored on validation (on='val') or test views."""
  rows = []
  for scene in scenes:
    for i, n in enumerate(steps):
      res = {s: finished(root, scene, n, s) for s in seeds}
      res = {s: r for s, r in res.items() if r is not None}
      if not res:
        continue
      row = {'scene': scene, 'steps': n, 'seeds': len(res)}
      where = lambda s: run_dir_of(root, scene, n, s)
      for k in METRICS:
        row[k], row[k + '_std'] = mean_std([score(r, k, on, where(s))
                                            for s, r in res.items()])
      row['round_seconds'], row['round_seconds_std'] = mean_std(
          [r['metrics']['round_seconds'] for r in res.values()])
      nxt = steps[i + 1] if i + 1 < len(steps) else None
      if nxt == 2 * n:
        more = {s: finished(root, scene, nxt, s) for s in res}
        paired = [s for s, r in more.items() if r is not None]
        if paired:
          row['paired_2x'] = len(paired)
          for k in METRICS:
            row[f'gain_2x_{k}'], row[f'gain_2x_{k}_std'] = mean_std(
                [score(more[s], k, on, where(s)) - score(res[s], k, on, where(s))
                 for s in paired])
          row['converged'] = bool(all(row[f'gain_2x_{k}'] <= v for k, v in MAX_GAIN.items()))
      rows.append(row)
  return rows


def markdown(rows, command, on='val'):
  fmt = lambda r, k, d=3: (f"{r[k]:.{d}f} +- {r[k + '_std']:.{d}f}" if k in r else '')
  lines = ['| scene | steps | seeds | PSNR | SSIM | LPIPS-alex | train s | 2x gain PSNR '
           '| 2x gain SSIM | 2x gain LPIPS | converged |',
           '|---|---|---|---|---|---|---|---|---|---|---|']
  for r in rows:
    verdict = ('yes' if r['converged'] else 'no') if 'converged' in r else ''
    lines.append(
        f"| {r['scene']} | {r['steps']} | {r['seeds']} | {fmt(r, 'psnr', 2)} | "
        f"{fmt(r, 'ssim')} | {fmt(r, 'lpips_alex')} | {r['round_seconds']:.0f} | "
        f"{fmt(r, 'gain_2x_psnr', 2)} | {fmt(r, 'gain_2x_ssim')} | "
        f"{fmt(r, 'gain_2x_lpips_alex')} | {verdict} |")
  views = 'validation views' if on == 'val' else 'test views (made before issue 60)'
  return ('\n'.join(lines) + f'\n\nScored on {views}. '
          '"2x gain": metric at 2N steps minus at N, paired by seed '
          f'(mean +- std). Converged: PSNR gain <= {MAX_GAIN["psnr"]} dB and SSIM gain <= '
          f'{MAX_GAIN["ssim"]}. "train s": wall seconds of training as logged (they depend '
          'on what else shared the CPU).\n\nCommand:\n\n    ' + command + '\n')


def plot(rows, scenes, path, on='val'):
  fig, axes = figures.subplots(len(METRICS), 2, figsize=(10, 2.6 * len(METRICS)))
  for scene in scenes:
    rs = [r for r in rows if r['scene'] == scene]
    if not rs:
      continue
    for i, k in enumerate(METRICS):
      for j, x in enumerate(('steps', 'round_seconds')):
        axes[i, j].errorbar([r[x] for r in rs], [r[k] for r in rs],
                            yerr=[r[k + '_std'] for r in rs], marker='o', capsize=3,
                            label=scene)
        axes[i, j].set_xscale('log')
        axes[i, j].set_xlabel('max_steps' if x == 'steps' else 'training seconds')
        axes[i, j].set_ylabel(k)
  axes[0, 0].legend()
  fig.suptitle(f'baseline B at N steps (decayed lr): {"validation" if on == "val" else "test"}'
               ' metrics, mean +- std over seeds')
  fig.tight_layout()
  figures.save_figure(fig, path, dpi=100)


def main(argv=None):
  args = parser().parse_args(argv)
  jit_cache.enable_compilation_cache()
  steps = sorted(set(args.steps))
  root = os.path.join(args.out, args.name)
  jobs = [(sc, n, s) for sc in args.scenes for s in args.seeds for n in steps
          if finished(root, sc, n, s) is None] if args.train else []
  bar = progress_bar(total=sum(n for _, n, _ in jobs), unit='step', desc='convergence')
  for scene_name, n, seed in jobs:
    bindings = args.gin_bindings + [
        f"Config.data_dir = {args.data_dir!r}", f"Config.scene = {scene_name!r}",
        'Config.num_rounds = 0', f'Config.max_steps = {n}', f'Config.seed = {seed}']
    config = load_config(args.config, bindings)
    scene = load_scene(config)
    run_dir = run_dir_of(root, scene_name, n, seed)
    cli.check_run_dir(config, run_dir, create=True)
    round_driver.run_rounds(config, scene, run_dir, show_progress=False)
    jit_cache.release_compiled()
    bar.update(n)
  bar.close()
  try:
    rows = summarize(root, args.scenes, args.seeds, steps, args.score_on)
  except ValueError as e:
    print(f'error: {e}', file=sys.stderr)
    sys.exit(2)
  # The command that reproduces the table (the runs are reused, or trained when missing).
  command = command_line('experiments.convergence',
                         [a for a in sys.argv[1:] if a != '--no-train'])
  report.write_json(os.path.join(args.out, args.name + '.json'),
                    {'name': args.name, 'config': args.config, 'bindings': args.gin_bindings,
                     'rows': rows, 'max_gain': MAX_GAIN, 'command': command,
                     'scored_on': args.score_on})
  text = markdown(rows, command, args.score_on)
  report.write_markdown(os.path.join(args.out, args.name + '.md'), text)
  plot(rows, args.scenes, os.path.join(args.out, args.name + '.png'), args.score_on)
  print(text)


if __name__ == '__main__':
  main()
