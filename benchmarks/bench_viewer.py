"""How much the web viewer slows a training it follows (issue 37).

python -m benchmarks.bench_viewer --out experiments/results/viewer/bench_viewer

Trains the demo's baseline (`gin_configs/demo_llff.gin`, --steps steps, a checkpoint every
--checkpoint_every) once per condition, each in a fresh run directory:
- alone;
- followed by the viewer (renerf_jax/viewer.py, "Follow training" on) with a headless
  Chromium page (benchmarks/browser.py) whose camera sits still (frames only when a new
  checkpoint arrives);
- the same with the page's camera orbiting without pause (a mouse drag every
  --drag_seconds: previews while it moves, a full frame each time it stops);
- orbiting with the viewer capped at --max_fps frames a second (view.py --max_fps).

The training rate is its steps per second of step time (log.jsonl's `time` counts the
training steps only) from step --from_step on, so compilation is left out. Training runs
as a subprocess; the viewer and the browser run in this process and its children, all on
the CPUs of --cpus. Writes --out.json / .md and a screenshot of the orbiting page
(--out_screenshot.png).
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from benchmarks.browser import drag, launch
from benchmarks.ports import free_port
from experiments.tables import command_line
from renerf_jax import report, rundir

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONDITIONS = ('alone', 'viewer, camera still', 'viewer, orbiting', 'viewer, orbiting, capped')


def train_command(run_dir, args):
  return [sys.executable, os.path.join(REPO, 'train.py'),
          '--gin_configs=' + os.path.join(REPO, 'gin_configs', 'demo_llff.gin'),
          '--gin_bindings=Config.num_rounds = 0',
          f'--gin_bindings=Config.max_steps = {args.steps}',
          f'--gin_bindings=Config.checkpoint_every = {args.checkpoint_every}',
          '--run_dir', run_dir]


def step_rate(run_dir, from_step):
  """Steps a second of step time between the first logged step >= from_step and the
  last (log.jsonl)."""
  recs = [r for r in rundir.read_jsonl(rundir.round_log_path(run_dir, 0))
          if r.get('step', 0) >= from_step and 'time' in r]
  if len(recs) < 2:
    raise RuntimeError(f'{run_dir}: fewer than two log records after step {from_step}')
  return (recs[-1]['step'] - recs[0]['step']) / (recs[-1]['time'] - recs[0]['time'])


def run_condition(name, run_dir, args, shot_path=None):
  """Trains once under one condition; returns its row."""
  cpus = {int(c) for c in args.cpus.split(',')}
  os.sched_setaffinity(0, cpus)
  t0 = time.perf_counter()
  proc = subprocess.Popen(train_command(run_dir, args), cwd=REPO, stdout=subprocess.DEVNULL,
                          stderr=subprocess.DEVNULL)
  row = {'condition': name}
  viewer = None
  try:
    if name != 'alone':
      from playwright.sync_api import sync_playwright  # pylint: disable=g-import-not-at-top
      from renerf_jax.viewer import Viewer, ViewerOptions  # pylint: disable=g-import-not-at-top
      ckpt = rundir.round_checkpoints_dir(run_dir, 0)
      while not rundir.list_checkpoints(ckpt):
        if proc.poll() is not None:
          raise RuntimeError(f'training ended before its first checkpoint ({run_dir})')
        time.sleep(.5)
      viewer = Viewer(run_dir, port=free_port(), options=ViewerOptions(
          max_fps=args.max_fps if 'capped' in name else 0., poll_seconds=2.))
      with sync_playwright() as p:
        browser = launch(p)
        page = browser.new_page(viewport={'width': 1000, 'height': 700})
        page.goto(f'http://127.0.0.1:{viewer.server.get_port()}')
        k = 0
        while proc.poll() is None:
          if 'orbiting' in name:
            drag(page, 60 if k % 2 == 0 else -60, 10, steps=8)
            k += 1
          page.wait_for_timeout(int(args.drag_seconds * 1e3))
        if shot_path is not None:
          drag(page, 40, 0)
          page.wait_for_timeout(3000)
          page.screenshot(path=shot_path)
        browser.close()
      row.update(frames=viewer.stats.frames, reloads=viewer.stats.reloads,
                 render_seconds=viewer.stats.render_seconds)
    proc.wait()
  finally:
    if proc.poll() is None:
      proc.kill()
    if viewer is not None:
      viewer.stop()
  if proc.returncode != 0:
    raise RuntimeError(f'training failed under {name!r} (exit {proc.returncode})')
  row.update(steps_per_second=step_rate(run_dir, args.from_step),
             wall_seconds=time.perf_counter() - t0)
  return row


def main():
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--out', help='output path without extension')
  p.add_argument('--retabulate', metavar='JSON',
                 help="rewrite the tables of a finished run's JSON, measuring nothing")
  p.add_argument('--steps', type=int, default=400)
  p.add_argument('--checkpoint_every', type=int, default=50)
  p.add_argument('--from_step', type=int, default=100)
  p.add_argument('--drag_seconds', type=float, default=.5)
  p.add_argument('--max_fps', type=float, default=2.)
  p.add_argument('--cpus', default=','.join(str(c) for c in sorted(os.sched_getaffinity(0))),
                 help='CPUs for training, viewer and browser (default: all of this process)')
  p.add_argument('--repeats', type=int, default=1, help='runs per condition (interleaved)')
  args = p.parse_args()
  if args.retabulate:
    return retabulate(args.retabulate)
  if not args.out:
    p.error('--out is required')
  rows = []
  with tempfile.TemporaryDirectory(prefix='bench-viewer-') as tmp:
    # One unreported run fills the compilation cache, so every condition starts alike.
    subprocess.run(train_command(os.path.join(tmp, 'warmup'), args), cwd=REPO, check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    for rep in range(args.repeats):
      for i, name in enumerate(CONDITIONS):
        shot = args.out + '_screenshot.png' if (rep == 0 and name == 'viewer, orbiting') \
            else None
        row = run_condition(name, os.path.join(tmp, f'{rep}_{i}'), args, shot)
        row['repeat'] = rep
        rows.append(row)
        print(row, flush=True)
  write_tables(args.out, rows, command_line(), args.cpus, vars(args))


def write_tables(out, rows, cmd, cpus, args):
  """--out.json (rows, summary) and --out.md (the summary table) of the runs' rows."""
  alone = np.mean([r['steps_per_second'] for r in rows if r['condition'] == 'alone'])
  summary = []
  for name in CONDITIONS:
    rs = [r for r in rows if r['condition'] == name]
    rate = float(np.mean([r['steps_per_second'] for r in rs]))
    frames = float(np.mean([r.get('frames', 0) for r in rs]))
    render_s = float(np.mean([r.get('render_seconds', 0.) for r in rs]))
    summary.append({'condition': name, 'steps_per_second': rate,
                    'slowdown_percent': 100. * (1. - rate / alone), 'frames': frames,
                    'render_seconds': render_s,
                    'seconds_per_frame': render_s / frames if frames else None,
                    'wall_seconds': float(np.mean([r['wall_seconds'] for r in rs]))})
  report.write_json(out + '.json', {'command': cmd, 'cpus': cpus, 'args': args,
                                    'rows': rows, 'summary': summary})
  table = report.markdown_table(summary, [
      ('condition', 'condition'), ('steps_per_second', 'training steps/s'),
      ('slowdown_percent', 'slow-down %'), ('frames', 'frames sent'),
      ('seconds_per_frame', 's per frame'), ('wall_seconds', 'wall s')],
      floatfmt={'steps_per_second': '.2f', 'slowdown_percent': '.1f', 'frames': '.1f',
                'seconds_per_frame': '.2f', 'wall_seconds': '.0f'})
  report.write_markdown(out + '.md', (
      f'Training the demo baseline ({args["steps"]} steps) with and without the viewer '
      f'following it; CPUs {cpus} (training, viewer and browser); rate from step '
      f'{args["from_step"]} on; mean of {args["repeats"]} run(s) per condition; the capped '
      f'viewer at {args["max_fps"]} frames a second.\n\n{table}\n\nCommand: `{cmd}`\n'))
  print(table)


def retabulate(path):
  """Rewrites the tables of a finished benchmark from its JSON (e.g. after a format
  change), keeping the command that measured it."""
  rec = report.read_json(path)
  write_tables(path[:-len('.json')], rec['rows'], rec['command'], rec['cpus'], rec['args'])


if __name__ == '__main__':
  main()
