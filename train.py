"""Trains the baseline and Re-Nerfing rounds: python train.py --gin_configs=gin_configs/demo.gin

On several machines: the same command on each, with --coordinator_address,
--num_processes and --process_id (docs/multi_host.md).
"""
import sys

from renerf_jax import auto_rounds, cli, distributed, report, round_driver, rundir
from renerf_jax.datasets import load_scene
from renerf_jax.renerf import check_rounds_config, deltas_vs_baseline, rounds_table


def auto_decision_lines(config, metrics):
  """With Config.num_rounds = 'auto': each round's decision and the model the run
  keeps (none otherwise)."""
  if not auto_rounds.is_auto(config):
    return []
  lines = [m['auto']['line'] if m.get('auto') else
           f"round {m['round']} kept: trained before Config.num_rounds was 'auto' (no decision)"
           for m in metrics[1:]]
  sel = auto_rounds.selected_round(metrics)
  last = metrics[-1]
  if len(metrics) - 1 == config.auto_max_rounds and (last.get('auto') or {}).get('take'):
    lines.append(f'no round after round {len(metrics) - 1}: Config.auto_max_rounds = '
                 f'{config.auto_max_rounds}')
  return lines + [f"the run keeps {'B' if sel == 0 else f'R{sel}'} (round {sel}; "
                  'auto_rounds.selected_round)']


@cli.exit_on_error
def main(argv=None):
  config, run_dir = cli.setup(argv, __doc__)
  scene = load_scene(config)
  check_rounds_config(config, scene)  # Before anything is written.
  cli.check_run_dir(config, run_dir, create=True)
  writer = distributed.is_writer()  # Process 0 of a multi-process run prints and writes.
  if writer:
    print(f'scene {scene.name}: {len(scene.train_idx)} train / {len(scene.test_idx)} test '
          f'views at {scene.width}x{scene.height}; run directory {run_dir}', file=sys.stderr)
  state = round_driver.run_rounds(config, scene, run_dir, show_progress=writer)
  control = None
  if config.seed_control and config.num_rounds:
    control = round_driver.run_control(config, scene, run_dir, state, show_progress=writer)
  if not writer:
    return
  table = rounds_table(state.metrics, control)
  json_path, md_path = rundir.rounds_table_paths(run_dir)
  report.write_json(json_path, list(state.metrics))  # With 'auto': each decision too.
  deltas = deltas_vs_baseline(state.metrics, control)
  decisions = auto_decision_lines(config, state.metrics)
  report.write_markdown(md_path, table + '\n' + ''.join(f'\n{d}\n' for d in decisions + deltas))
  rows = [('B', rundir.round_dir(run_dir, 0))]
  if control is not None:
    rows.append(('control', rundir.round_dir(round_driver.control_run_dir(config, run_dir),
                                             0)))
  rows += [(f'R{r}', rundir.round_dir(run_dir, r)) for r in range(1, len(state.metrics))]
  round_driver.save_comparison(run_dir, scene, rows)
  print(table)
  for line in decisions:
    print(line)
  for line in deltas:
    print(line)
  print('the test view farthest from the training cameras, photo then each row: '
        f'{rundir.comparison_path(run_dir)}')


if __name__ == '__main__':
  main()
