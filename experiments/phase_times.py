"""Where a Re-Nerfing round's time goes: B and one round R1 of a config, timed by phase.

The round is renerf.round_step itself (trained in memory, nothing but the table written),
with the backbone's functions wrapped in timers: B's steps and D's steps (seconds, seconds
a step after the first logged interval, which holds the compile), the cheap evaluations
during training, the final evaluations of the test and the validation views, and the
pseudo-views (poses, render and masks). For 3DGS the Gaussians' count at every cheap
evaluation. Writes <out>/<name>.json and .md; prints the table.

  python -m experiments.phase_times --config gin_configs/garden30.gin \
    --data_dir ../shared/data/mipnerf360 --scene garden --seed 0 \
    --out experiments/results/paper_table2_360 --name phase_times_grid
"""
import argparse
import contextlib
import dataclasses
import os
import time
from unittest import mock

import numpy as np

from experiments.tables import command_line
from renerf_jax import backbones, jit_cache, renerf, report
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene


class PhaseClock:
  """Seconds per phase label, the records of the cheap evaluations, and the stage ('B'
  or 'R1') the phases being timed belong to."""

  def __init__(self):
    self.seconds, self.evals, self.stage = {}, [], 'B'

  @contextlib.contextmanager
  def phase(self, label):
    t0 = time.perf_counter()
    try:
      yield
    finally:
      self.seconds[label] = self.seconds.get(label, 0.) + time.perf_counter() - t0


def count_gaussians(params):
  """Active Gaussians of a 3DGS model; None for a NeRF's field parameters."""
  active = getattr(params, 'active', None)
  return None if active is None else int(np.sum(np.asarray(active)))


def timed_backbone(backbone, clock, test_scene):
  """`backbone` whose train / synthesize / evaluate / cheap evaluations add their wall
  seconds to `clock` under its current stage; an evaluation of a
  scene other than `test_scene` is the validation views' (renerf.validation_scene)."""

  def train(config, scene, out_dir, pseudo, **kw):
    inner = kw.get('eval_fn')
    if inner is not None:
      def eval_fn(params):
        with clock.phase(f'{clock.stage} cheap evaluations'):
          psnr = inner(params)
        clock.evals.append({'stage': clock.stage, 'gaussians': count_gaussians(params),
                            'psnr': psnr})
        return psnr
      kw['eval_fn'] = eval_fn
    with clock.phase(f'{clock.stage} training (steps, compile, cheap evaluations)'):
      return backbone.train(config, scene, out_dir, pseudo, **kw)

  def synthesize(*args, **kw):
    with clock.phase(f'{clock.stage} pseudo-views'):
      return backbone.synthesize(*args, **kw)

  def evaluate(config, scene, params, **kw):
    which = 'test' if scene is test_scene else 'validation'
    with clock.phase(f'{clock.stage} final evaluation ({which} views)'):
      return backbone.evaluate(config, scene, params, **kw)

  return dataclasses.replace(backbone, train=train, synthesize=synthesize,
                             evaluate=evaluate)


def steady_seconds_per_step(curve):
  """Seconds a step between the first and the last record of a training curve (the
  first record's interval holds the compile); None with fewer than two records."""
  pts = [(c['step'], c['train_seconds']) for c in curve]
  if len(pts) < 2 or pts[-1][0] == pts[0][0]:
    return None
  return (pts[-1][1] - pts[0][1]) / (pts[-1][0] - pts[0][0])


def measure(config, scene):
  """B and R1 of `config` on `scene` by round_step, timed by phase.

  Returns:
    dict: 'phases' {label: seconds}, 'rounds' [per round: steps, train_seconds,
    seconds_per_step (steady), psnr, val_psnr], 'gaussians' [counts at the cheap
    evaluations, by stage], 'pseudo_views' ({'views': count} of R1's pseudo-views).
  """
  clock = PhaseClock()
  backbone = timed_backbone(backbones.get_backbone(config), clock, scene)
  state = renerf.initial_state()
  rounds, pseudo = [], None
  with mock.patch.object(backbones, 'get_backbone', lambda cfg: backbone):
    for stage in ('B', 'R1'):
      clock.stage = stage
      with clock.phase(f'{stage} round (all of it)'):
        state = renerf.round_step(config, scene, state)
      m, curve = state.metrics[-1], state.curves[-1]
      rounds.append({'round': stage, 'steps': curve[-1]['step'],
                     'train_seconds': curve[-1]['train_seconds'],
                     'seconds_per_step': steady_seconds_per_step(curve),
                     'psnr': m['psnr'], 'val_psnr': m.get('val_psnr')})
      if stage == 'R1' and state.pseudo is not None:
        pseudo = {'views': int(state.pseudo.images.shape[0])}
  return {'phases': clock.seconds, 'rounds': rounds, 'gaussians': clock.evals,
          'pseudo_views': pseudo}


def markdown(result, title, command):
  """The phase table of measure()'s result."""
  lines = [f'## {title}', '', '| phase | seconds | share of the round |', '|---|---|---|']
  for stage in ('B', 'R1'):
    total = result['phases'].get(f'{stage} round (all of it)', float('nan'))
    for label, s in result['phases'].items():
      if label.startswith(stage + ' '):
        lines.append(f'| {label} | {s:.1f} | {s / total:.0%} |')
  lines += ['', '| round | steps | training s (steps only) | s a step (steady) | test PSNR '
            '| val PSNR |', '|---|---|---|---|---|---|']
  for r in result['rounds']:
    sps = 'n/a' if r['seconds_per_step'] is None else f"{r['seconds_per_step']:.4f}"
    val = 'n/a' if r['val_psnr'] is None else f"{r['val_psnr']:.2f}"
    lines.append(f"| {r['round']} | {r['steps']} | {r['train_seconds']:.1f} | {sps} | "
                 f"{r['psnr']:.2f} | {val} |")
  counts = [e for e in result['gaussians'] if e['gaussians'] is not None]
  if counts:
    lines += ['', 'Gaussians at the cheap evaluations: ' + '; '.join(
        f"{stage}: " + ', '.join(str(e['gaussians']) for e in counts if e['stage'] == stage)
        for stage in ('B', 'R1'))]
  if result['pseudo_views']:
    lines += ['', f"Pseudo-views: {result['pseudo_views']['views']}."]
  lines += ['', 'Command:', '', '    ' + command, '']
  return '\n'.join(lines)


def parser():
  p = argparse.ArgumentParser(description=__doc__.split('\n')[0])
  p.add_argument('--config', nargs='+', required=True, help='gin config file(s)')
  p.add_argument('--data_dir', required=True)
  p.add_argument('--scene', required=True)
  p.add_argument('--seed', type=int, default=0)
  p.add_argument('--gin_bindings', action='append', default=[])
  p.add_argument('--out', required=True)
  p.add_argument('--name', required=True)
  return p


def main(argv=None):
  args = parser().parse_args(argv)
  jit_cache.enable_compilation_cache()
  bindings = args.gin_bindings + [
      f'Config.data_dir = {args.data_dir!r}', f'Config.scene = {args.scene!r}',
      'Config.num_rounds = 1', f'Config.seed = {args.seed}']
  config = load_config(args.config, bindings)
  scene = load_scene(config)
  result = measure(config, scene)
  command = command_line('experiments.phase_times', argv)
  title = (f'{args.scene}, {config.backbone} ({" ".join(args.config)}), seed '
           f'{args.seed}, {scene.width}x{scene.height}: one round by phase')
  os.makedirs(args.out, exist_ok=True)
  report.write_json(os.path.join(args.out, args.name + '.json'),
                    dict(result, config=args.config, bindings=args.gin_bindings,
                         scene=args.scene, seed=args.seed, command=command,
                         resolution=[scene.width, scene.height]))
  text = markdown(result, title, command)
  report.write_markdown(os.path.join(args.out, args.name + '.md'), text)
  print(text)


if __name__ == '__main__':
  main()
