"""Evaluates a finished run: python eval.py --gin_configs=... [--run_dir=...]

Reads the per-image and mean PSNR / SSIM / LPIPS that every finished round wrote into
round_<r>/eval/ (a finished round's outputs are never rewritten). A round whose metrics
lack one of Config.lpips_nets (a resumable field) is rendered again into
round_<r>/eval_extra/ instead. Prints the rounds table and the error against run time
table, writes eval_rounds.json/.md and plots error_vs_time.png in the run directory.
"""
import os
import sys

from renerf_jax import auto_rounds, cli, distributed, figures, report, rundir
from renerf_jax.backbones import get_backbone
from renerf_jax.datasets import load_scene
from renerf_jax.renerf import initial_state, round_config, rounds_table
from renerf_jax.round_driver import load_round, save_evaluation


def curve_rows(run_dir, n_rounds):
  """Cheap-evaluation points of every round: [{'round', 'step', 'time', 'eval_psnr'}]."""
  rows = []
  for r in range(n_rounds):
    for rec in rundir.read_jsonl(rundir.round_log_path(run_dir, r)):
      if 'eval_psnr' in rec:
        rows.append({'round': r, 'step': rec['step'], 'time': rec['time'],
                     'eval_psnr': rec['eval_psnr']})
  return rows


def round_eval_dir(config, scene, params, rdir, r):
  """The folder of round r's test metrics: eval/ as the round wrote it, or, when those
  lack one of config.lpips_nets, eval_extra/ (rendered here once, then reused)."""
  wanted = {f'lpips_{n}' for n in config.lpips_nets} | {'psnr', 'ssim'}
  for ev_dir in (rundir.eval_dir(rdir), rundir.eval_extra_dir(rdir)):
    path = rundir.metrics_path(ev_dir)
    if os.path.isfile(path) and wanted <= set(report.read_json(path)['mean']):
      return ev_dir
  out = rundir.eval_extra_dir(rdir)
  ev = get_backbone(config).evaluate(round_config(config, r), scene, params,
                                     show_progress=distributed.is_writer())
  if distributed.is_writer():
    save_evaluation(out, ev)
  distributed.sync(f'eval_extra {r}')  # Its metrics are read back by every process.
  return out


@cli.exit_on_error
def main(argv=None):
  config, run_dir = cli.setup(argv, __doc__)
  cli.check_run_dir(config, run_dir, create=False)
  scene = load_scene(config)
  state = initial_state()
  metrics = []
  for r in range(auto_rounds.max_rounds(config) + 1):
    if r > 0 and auto_rounds.stops_after(config, state.metrics):
      break  # 'auto': the run discarded round r - 1 and trained no further round.
    rdir = rundir.round_dir(run_dir, r)
    if not rundir.is_done(rdir):
      print(f'round {r} is not finished in {run_dir}; evaluating rounds 0..{r - 1}',
            file=sys.stderr)
      break
    state = load_round(config, rdir, state)
    ev_dir = round_eval_dir(config, scene, state.params, rdir, r)
    mean = report.read_json(rundir.metrics_path(ev_dir))['mean']
    saved = state.metrics[-1]
    metrics.append(dict(mean, round=r, round_seconds=saved['round_seconds'],
                        cumulative_seconds=saved['cumulative_seconds']))
    if distributed.is_writer():
      with open(rundir.metrics_md_path(ev_dir)) as f:
        print(f'round {r}:\n' + f.read())
  if not metrics:
    raise SystemExit(f'error: no finished round in {run_dir}')
  if not distributed.is_writer():
    return  # Process 0 of a multi-process run writes and prints.
  table = rounds_table(metrics)
  curve = curve_rows(run_dir, len(metrics))
  json_path, md_path = rundir.eval_rounds_paths(run_dir)
  report.write_json(json_path, {'rounds': metrics, 'error_vs_time': curve})
  curve_md = report.markdown_table(curve, [('round', 'round'), ('step', 'step'),
                                           ('time', 'time [s]'), ('eval_psnr', 'test PSNR')])
  report.write_markdown(md_path,
                        table + '\n\nError against run time (cheap test PSNR):\n\n' +
                        curve_md + '\n')
  if curve:
    curves = {}
    for c in curve:
      label = 'baseline' if c['round'] == 0 else f"round {c['round']}"
      curves.setdefault(label, []).append((c['time'], c['eval_psnr']))
    figures.plot_error_vs_time(curves, rundir.error_vs_time_path(run_dir),
                              metric='psnr', title=f'{scene.name}: test PSNR vs time')
  print(table)
  print('\nError against run time (cheap test PSNR):\n' + curve_md)


if __name__ == '__main__':
  main()
