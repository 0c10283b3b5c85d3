"""Pairs one row of a renerf_scenes table with a row of another, by (scene, seed).

For rows that no single table holds: e.g. B with DropGaussian (one config) against B
without it (another config), the same scenes and seeds. Per metric and per scene:
mean +- std of row - reference, wins, the paired t-test's p, its Holm adjustment over
the table's rows (the scenes, and the pooled row when there are several scenes) and the
bootstrap 95% interval (experiments/paired.py); pooled over every common (scene, seed)
too. A gain is shown where the interval excludes 0 and the Holm p < 0.05.

  python -m experiments.compare_tables --a runs_drop.json --a_row B --a_label "3DGS + dropout" \
      --b runs_plain.json --b_row B --b_label 3DGS --out .../dropout_vs_plain

Writes <out>.json and <out>.md; trains nothing.
"""
import argparse
import json
import os
import shlex
import sys

from experiments import paired, renerf_scenes
from renerf_jax import report


def read_rows(path):
  """{scene: {row: {seed (str): metrics}}} of a renerf_scenes table JSON; ValueError
  naming the file otherwise."""
  try:
    with open(path) as f:
      table = json.load(f)
    return table['rows']
  except (OSError, ValueError, KeyError, TypeError) as e:
    raise ValueError(f'{path}: not a renerf_scenes table ({e})') from None


def compare(rows_a, row_a, rows_b, row_b):
  """Paired deltas of rows_a[scene][row_a] - rows_b[scene][row_b] over common seeds
  (renerf_scenes.pair_stats, per scene and pooled).

  Returns:
    {'pairs': [(scene, seed)], 'scenes': {scene: {metric: paired_summary}},
    'pooled': {metric: paired_summary}, 'means': {'a'|'b': {metric: mean}}}.
    ValueError when no (scene, seed) is in both.
  """
  keys, by_scene = [], {}
  for scene in sorted(set(rows_a) & set(rows_b)):
    a, b = rows_a[scene].get(row_a, {}), rows_b[scene].get(row_b, {})
    for s in sorted(set(a) & set(b), key=int):
      keys.append((scene, int(s)))
      by_scene.setdefault(scene, []).append((a[s], b[s]))
  if not keys:
    raise ValueError(f'no (scene, seed) has both row {row_a!r} and row {row_b!r}')
  pooled = [p for pairs in by_scene.values() for p in pairs]
  scenes = {sc: renerf_scenes.pair_stats(pairs) for sc, pairs in by_scene.items()}
  # One family per metric: the scenes' rows and, over several scenes, the pooled row (over
  # one scene the pooled row is that scene's comparison again: the same test, counted once).
  pooled_stats = renerf_scenes.pair_stats(pooled)
  renerf_scenes.holm(list(scenes.values()) + ([pooled_stats] if len(scenes) > 1 else []))
  if len(scenes) == 1:
    pooled_stats = {k: dict(v) for k, v in next(iter(scenes.values())).items()}
  return {'pairs': keys,
          'scenes': scenes,
          'pooled': pooled_stats,
          'means': {side: {m: sum(p[i][m] for p in pooled) / len(pooled)
                           for m in renerf_scenes.METRICS}
                    for i, side in enumerate(('a', 'b'))}}


def markdown(result, label_a, label_b, command):
  """The comparison as a markdown table: a row per scene and the pooled row."""
  head = (f'# {label_a} - {label_b}, paired by (scene, seed)\n\n'
          f'Mean over the {len(result["pairs"])} pairs: {label_a} '
          + ' / '.join(f'{result["means"]["a"][m]:.3f}' for m in renerf_scenes.METRICS)
          + f', {label_b} '
          + ' / '.join(f'{result["means"]["b"][m]:.3f}' for m in renerf_scenes.METRICS)
          + ' (PSNR / SSIM / LPIPS-alex). Cells: mean +- std (wins/pairs), paired '
          't-test p, its Holm adjustment over the rows of the column (the pooled row '
          'counted where there are several scenes), bootstrap 95% interval; bold where a '
          'gain is shown (the interval excludes 0 and the Holm p < 0.05).\n\n'
          '| scene | dPSNR | dSSIM | dLPIPS-alex |\n|---|---|---|---|\n')
  line = lambda name, s: (f'| {name} | ' + ' | '.join(
      paired.format_cell(s[m], 3 if m != 'psnr' else 2) for m in renerf_scenes.METRICS)
      + ' |\n')
  body = ''.join(line(sc, s) for sc, s in result['scenes'].items())
  return head + body + line('**all**', result['pooled']) + f'\n    {command}\n'


def main(argv=None):
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--a', required=True, help='renerf_scenes table JSON of the row')
  p.add_argument('--a_row', default='B')
  p.add_argument('--a_label', required=True)
  p.add_argument('--b', required=True, help='renerf_scenes table JSON of the reference')
  p.add_argument('--b_row', default='B')
  p.add_argument('--b_label', required=True)
  p.add_argument('--out', required=True, help='output path without extension')
  args = p.parse_args(argv)
  try:
    result = compare(read_rows(args.a), args.a_row, read_rows(args.b), args.b_row)
  except ValueError as e:
    sys.exit(f'compare_tables: {e}')
  command = 'python -m experiments.compare_tables ' + shlex.join(
      sys.argv[1:] if argv is None else argv)
  os.makedirs(os.path.dirname(args.out) or '.', exist_ok=True)
  report.write_json(args.out + '.json', dict(result, a=args.a, a_row=args.a_row,
                                             b=args.b, b_row=args.b_row, command=command))
  report.write_markdown(args.out + '.md', markdown(result, args.a_label, args.b_label,
                                                   command))
  print(markdown(result, args.a_label, args.b_label, command))


if __name__ == '__main__':
  main()
