"""What turning XLA:CPU's YNNPACK fusions off costs (renerf_jax.xla_cpu), per config.

python -m benchmarks.bench_ynn --configs experiments/configs/table_tiny.gin \
    experiments/configs/table_lego200.gin --rounds 2

Runs benchmarks/bench_throughput.py (train and render stages) in a fresh process per
setting, since XLA reads its flags once per process: 'off' (the project's default,
--xla_cpu_experimental_ynn_fusion_type=) and 'on' (=individual_dot,reduce, jaxlib 0.10.2's own
default), alternating --rounds times so that a drift in the machine's load falls on
both. Reports each setting's median rays/s and off / on. Run it on an idle machine.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

from experiments.tables import command_line
from renerf_jax import report
from renerf_jax.xla_cpu import FLAG

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SETTINGS = {'off': f'{FLAG}=', 'on': f'{FLAG}=individual_dot,reduce'}


def run_setting(flags, configs, stages, repeats):
  """bench_throughput's rows in a fresh process with XLA_FLAGS=flags."""
  with tempfile.TemporaryDirectory() as tmp:
    out = os.path.join(tmp, 'throughput')
    cmd = [sys.executable, '-m', 'benchmarks.bench_throughput', '--configs', *configs,
           '--stages', *stages, '--repeats', str(repeats), '--out', out]
    subprocess.run(cmd, cwd=REPO, env=dict(os.environ, XLA_FLAGS=flags), check=True,
                   stdout=subprocess.DEVNULL)
    with open(out + '.json', encoding='utf-8') as f:
      return json.load(f)['rows']


def main(argv=None):
  p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
  p.add_argument('--configs', nargs='+', required=True)
  p.add_argument('--stages', nargs='+', default=['train', 'render'])
  p.add_argument('--repeats', type=int, default=5)
  p.add_argument('--rounds', type=int, default=2)
  p.add_argument('--out', default='benchmarks/results/ynn_fusions')
  args = p.parse_args(argv)
  rates = {}  # (config, stage) -> setting -> [rays/s]
  for r in range(args.rounds):
    for name, flags in SETTINGS.items():
      print(f'round {r + 1}/{args.rounds}: YNN fusions {name}', flush=True)
      for row in run_setting(flags, args.configs, args.stages, args.repeats):
        rates.setdefault((row['config'], row['stage']), {}).setdefault(
            name, []).append(row['rays_per_s'])
  rows = []
  for (config, stage), by in rates.items():
    off, on = float(np.median(by['off'])), float(np.median(by['on']))
    rows.append({'config': config, 'stage': stage, 'off': off, 'on': on,
                 'ratio': off / on, 'n': len(by['off'])})
  command = command_line('benchmarks.bench_ynn', argv)
  table = report.markdown_table(rows, [
      ('config', 'config'), ('stage', 'stage'), ('on', 'rays/s, YNN fusions on'),
      ('off', 'rays/s, off (default)'), ('ratio', 'off / on'), ('n', 'runs each')],
      floatfmt={'on': '.0f', 'off': '.0f', 'ratio': '.2f'})
  os.makedirs(os.path.dirname(args.out) or '.', exist_ok=True)
  report.write_json(args.out + '.json', {'rows': rows, 'command': command})
  text = f'{table}\n\nCommand:\n\n    {command}\n'
  report.write_markdown(args.out + '.md', text)
  print(text)
  return rows


if __name__ == '__main__':
  main()
