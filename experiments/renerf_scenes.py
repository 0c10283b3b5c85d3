"""Table 1 across scenes with paired seeds (issue 18): does D beat B, and beat more compute?

For every scene and seed: the baseline B, Re-Nerfing R1 (D trained from scratch on the
real views plus B's pseudo-views), B trained 2x longer (for R1 also the equal-time
control; --scenes_2x limits it to some scenes), and the seed-matched controls of issue 49
(--no_controls skips them): B's training at D's seed (Config.d_seed, renerf.round_config)
at B's steps ("D's seed, no pseudo-views": it differs from R1 in the pseudo-views
alone) and at 2x B's steps. Every row is paired with B, with both controls, with B 2x and
with R1: mean +- std, wins, a paired t-test p-value, its Holm adjustment over the rows
compared with the same reference in the table, and a paired bootstrap 95% interval
(experiments/paired.py); a gain is shown (bold) only when the interval excludes 0 and
the Holm p < 0.05. With --rounds_scenes, those scenes also
get R2, R3 and B trained for the rounds' total time. Extra rows (--variant
'LABEL=bindings', e.g. R1 with the masks or an attribution of K, the mix or the factors)
train R1 from the same B (copied bit for bit).
Every number is paired by seed: D minus B of the same (scene, seed), as mean +- std over
pairs and the count of pairs where D beats B in PSNR, SSIM and LPIPS; the paper's
per-scene R1 deltas (RegNeRF base, full scale) stand beside ours.

Runs live in <out>/<name>/<scene>/<row>/seed<k> (resumable; finished runs are reused, so
invocations can be split by scene, seed and variant, each rewriting the table from every
finished run it finds; --table writes a subset of them to other files). The
converged-regime table on 2 CPU cores (five scenes x 3 seeds, run split by scene;
experiments/results/renerf_r1_converged_llff/scenes_conv2.md), and its attribution rows on
seed 0 (further --variant rows, the mix and the factors, as in
experiments/results/renerf_attribution_converged_llff/README.md):

  python -m experiments.renerf_scenes --name scenes_conv2 \
    --config experiments/configs/table_converged2.gin \
    --scenes fern orchids room trex fortress --seeds 0 1 2 \
    --reuse experiments/results/conv2
  python -m experiments.renerf_scenes --name scenes_conv2 --table scenes_conv2_attribution \
    --config experiments/configs/table_converged2.gin --scenes fern trex --seeds 0 --no_2x \
    --variant 'K 0.12=Config.pseudo_until_frac = 0.12' \
    --variant 'K 0.5=Config.pseudo_until_frac = 0.5'

Tables made separately (e.g. one per scene, in parallel) are put into one with --merge,
which reads their .json rows and trains nothing
(experiments/results/renerf_r1_converged_llff/scenes_conv3.md):

  python -m experiments.renerf_scenes --name scenes_conv3 --merge \
    experiments/results/renerf_r1_converged_llff/scenes_conv3_{fern,orchids,room,trex,fortress}.json

Writes <out>/<name>.json, <name>.md and <name>.png (paired deltas per scene; --table
names them otherwise). --refresh recomputes the statistics and the markdown of finished
tables from their rows (e.g. after the statistics changed), keeping their recorded
commands; it trains nothing and leaves their .png as it is:

  python -m experiments.renerf_scenes --name refresh --refresh experiments/results/*/lego.json
"""
import argparse
import copy
import dataclasses
import os
import shlex

import numpy as np

from experiments import paired, tables
from renerf_jax import figures, jit_cache, renerf, report, rundir
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene
from renerf_jax.errors import ConfigError

METRICS = ('psnr', 'ssim', 'lpips_alex')
TWO_X = 'B 2x steps'  # the row of B trained 2x longer (the control for more compute)
# The seed-matched controls (issue 49): B's training at D's seed (renerf.round_config),
# at B's steps (D without pseudo-views: it differs from R1 in the pseudo-views alone) and
# at 2x B's steps (more compute at D's seed). With Config.d_seed = 'same' they are B and
# B 2x themselves (copied bit for bit, nothing trained).
# (Issue 34's tables made the first as a --variant, "D's seed, no pseudo-views (K 0)": R1
# at K 0, the same model bit for bit, in a run directory of its own layout.)
CONTROL = "D's seed, no pseudo-views"
CONTROL_2X = "D's seed, B 2x steps"
# Every row is paired with each of these rows of the same (scene, seed): summary key,
# row label, the short name in the tables.
REFERENCES = (('paired', 'B', 'B'), ('paired_ctrl', CONTROL, "D's seed K 0"),
              ('paired_ctrl2x', CONTROL_2X, "D's seed 2x"), ('paired_2x', TWO_X, 'B 2x'),
              ('paired_R1', 'R1', 'R1'))
BETTER = {'psnr': 1., 'ssim': 1., 'lpips_alex': -1.}  # sign of "D beats B"
# ../shared/REFERENCE_NUMBERS.md: RegNeRF and + R1 (PSNR, SSIM, LPIPS), LLFF 3 views.
PAPER = {'fern': ((19.87, .697, .202), (19.96, .709, .191)),
         'flower': ((19.93, .688, .156), (20.28, .711, .143)),
         'fortress': ((23.32, .743, .065), (23.69, .789, .054)),
         'horns': ((15.65, .610, .200), (15.75, .654, .179)),
         'leaves': ((16.60, .612, .132), (16.92, .654, .116)),
         'orchids': ((15.56, .502, .177), (15.77, .526, .162)),
         'room': ((21.53, .861, .116), (21.84, .873, .105)),
         'trex': ((20.16, .766, .133), (20.55, .788, .117))}


def paper_delta(scene):
  if scene not in PAPER:
    return None
  b, r1 = PAPER[scene]
  return dict(zip(METRICS, (round(x - y, 3) for x, y in zip(r1, b))))


def parser():
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--name', required=True)
  p.add_argument('--config', nargs='+', default=None,
                 help='gin config file(s) (required unless --merge)')
  p.add_argument('--data_dir', default='../shared/data/nerf_llff_data')
  p.add_argument('--scenes', nargs='+', default=['fern'])
  p.add_argument('--seeds', type=int, nargs='+', default=[0, 1, 2])
  p.add_argument('--rounds_scenes', nargs='*', default=[],
                 help='scenes that also get R2, R3 and B at the rounds\' total time')
  p.add_argument('--variant', action='append', default=[],
                 help="extra R1 row 'LABEL=binding;binding' trained from the same B")
  p.add_argument('--no_2x', action='store_true',
                 help="skip B trained 2x longer (and the control at 2x steps at D's seed)")
  p.add_argument('--no_b2x', action='store_true',
                 help="skip B trained 2x longer at B's seed but keep the control at 2x "
                      "steps at D's seed (the more-compute control that differs from R1 in "
                      "the pseudo-views alone; B 2x at B's seed shares B's seed luck)")
  p.add_argument('--no_controls', action='store_true',
                 help="skip the seed-matched controls (B's training at D's seed, at B's "
                      "steps and, unless --no_2x, at 2x B's steps; with Config.d_seed="
                      "'same' they are B and B 2x copied, nothing trained)")
  p.add_argument('--no_r1', action='store_true',
                 help='train B but not R1 (e.g. the oracle table, whose rows are --variant '
                      'rows from the same B); a later call without it adds R1 to the same run')
  p.add_argument('--scenes_2x', nargs='*', default=None,
                 help='only these scenes get B trained 2x longer (default: all of '
                      '--scenes; given with no scene: none, as --no_2x)')
  p.add_argument('--reuse', default=None,
                 help='a convergence.py results folder (<out>/<name>): its finished runs '
                      '<scene>/N<steps>/seed<k> made with the same config (and --data_dir) '
                      'are copied as B and as B 2x instead of training them again')
  p.add_argument('--gin_bindings', action='append', default=[])
  p.add_argument('--out', default='experiments/results')
  p.add_argument('--table', default=None,
                 help='name of the written table files (default --name): tabulate a subset '
                      'of the runs under <out>/<name> without overwriting the full table')
  p.add_argument('--refresh', nargs='+', default=None, metavar='JSON',
                 help='rewrite finished tables (.json summary and .md) from their own rows '
                      'with the current statistics, keeping their commands; trains nothing')
  p.add_argument('--merge', nargs='+', default=None, metavar='JSON',
                 help='build the table from the rows of finished tables (their .json, e.g. '
                      'one per scene) instead of running: all must come from the same '
                      '--config, --gin_bindings and --data_dir; trains nothing')
  return p


def command_args(command):
  """The arguments of a table's recorded command: `python -m experiments.renerf_scenes ARGS`
  or, in tables made before it ran as a module, `python experiments/renerf_scenes.py ARGS`."""
  words = shlex.split(command)
  return words[3:] if words[1:2] == ['-m'] else words[2:]


def merged_rows(paths):
  """Rows of finished tables, merged: ({scene: {label: {seed: metrics}}}, seeds, their
  commands, (config, gin_bindings, data_dir), backbone). Raises SystemExit with one line
  on a missing/unreadable file, on tables of different settings, or on one (scene, row,
  seed) with two different results."""
  rows, seeds, commands, setting, backbone = {}, [], [], None, 'nerf'
  for path in paths:
    try:
      table = report.read_json(path)
      src = parser().parse_args(command_args(table['command']))
      table_rows = table['rows']
    except (OSError, ValueError, KeyError, SystemExit) as e:
      raise SystemExit(f'--merge: {path} is not a renerf_scenes table ({e})') from None
    this = (src.config, src.gin_bindings, src.data_dir)
    if setting is not None and this != setting:
      raise SystemExit(f'--merge: {path} was made with --config/--gin_bindings/--data_dir '
                       f'{this}, not {setting} as {paths[0]}')
    setting = this
    backbone = table.get('backbone', 'nerf')  # tables made before it was stored: NeRF
    commands.append(table['command'])
    for scene, labels in table_rows.items():
      for label, by_seed in labels.items():
        for seed, m in by_seed.items():
          have = rows.setdefault(scene, {}).setdefault(label, {})
          if int(seed) in have and have[int(seed)] != m:
            raise SystemExit(f'--merge: {path} holds another result for {scene} / {label} '
                             f'/ seed {seed} than an earlier table')
          have[int(seed)] = m
          if int(seed) not in seeds:
            seeds.append(int(seed))
  return rows, sorted(seeds), commands, setting, backbone


def run(config, scene, run_dir, share=()):
  """Per-round metrics of one run (tables.run_seed: resumable, baselines shared)."""
  return tables.run_seed(config, scene, run_dir, share)[0]


def pair_stats(pairs):
  """pairs: [(row metrics, reference metrics)] -> {metric: paired.paired_summary of the
  deltas row - reference (mean, std, wins, n, p, ci, shown)}."""
  out = {}
  for k in METRICS:
    d = [dm[k] - bm[k] for dm, bm in pairs if k in dm and k in bm]
    if d:
      out[k] = paired.paired_summary(d, BETTER[k])
  return out


def finished_rounds(run_dir):
  """The rounds of a run whose every round is finished (read as it is: --no_r1 neither
  trains R1 nor rewrites such a run's config), else 0 (B alone)."""
  path = rundir.config_json_path(run_dir)
  if not os.path.isfile(path):
    return 0
  n = report.read_json(path).get('num_rounds', 0)
  if not isinstance(n, int):  # 'auto' (train.py's): the table's rows are fixed rounds.
    raise ConfigError(f"{path}: num_rounds={n!r}; a table reads runs of integer rounds")
  done = all(rundir.is_done(rundir.round_dir(run_dir, r)) for r in range(n + 1))
  return n if done else 0


def scene_runs(args, scene_name, base_bindings):
  """Runs every row of one scene; returns {row label: {seed: metrics of that row}}, B's
  metrics under 'B' and per-row seconds."""
  root = os.path.join(args.out, args.name, scene_name)
  bindings = base_bindings + [f'Config.scene = {scene_name!r}']
  config = load_config(args.config, bindings)
  scene = load_scene(config)
  rounds = 0 if args.no_r1 else 3 if scene_name in args.rounds_scenes else 1
  rows = {}
  renerf_runs = {}
  reuse = lambda steps, seed: ([os.path.join(args.reuse, scene_name, f'N{steps}',
                                             f'seed{seed}')] if args.reuse else [])
  for seed in args.seeds:
    run_dir = os.path.join(root, 'Re-Nerfing', f'seed{seed}')
    cfg = dataclasses.replace(config, seed=seed,
                              num_rounds=finished_rounds(run_dir) if args.no_r1 else rounds)
    ms = run(cfg, scene, run_dir, reuse(config.max_steps, seed))
    renerf_runs[seed] = ms
    for m in ms[:rounds + 1]:
      rows.setdefault('B' if m['round'] == 0 else f"R{m['round']}", {})[seed] = m
  for spec in args.variant:
    label, extra = tables.variant_spec(spec)
    cfg0 = load_config(args.config, bindings + extra)
    for seed in args.seeds:
      cfg = dataclasses.replace(cfg0, seed=seed, num_rounds=1)
      ms = run(cfg, scene, os.path.join(root, label, f'seed{seed}'),
               [os.path.join(root, 'Re-Nerfing', f'seed{seed}')])
      rows.setdefault(label, {})[seed] = ms[1]
  two_x = not args.no_2x and (args.scenes_2x is None or scene_name in args.scenes_2x)
  if two_x and not args.no_b2x:
    for seed in args.seeds:
      cfg = dataclasses.replace(config, seed=seed, num_rounds=0,
                                max_steps=2 * config.max_steps)
      rows.setdefault(TWO_X, {})[seed] = run(
          cfg, scene, os.path.join(root, TWO_X, f'seed{seed}'),
          reuse(2 * config.max_steps, seed))[0]
  if not args.no_controls:
    controls = [(CONTROL, config.max_steps, 'Re-Nerfing')]
    if two_x:
      controls.append((CONTROL_2X, 2 * config.max_steps, TWO_X))
    for label, steps, twin in controls:
      for seed in args.seeds:
        # Its twin at B's seed: with Config.d_seed='same' the control is that run's B,
        # found by the sharing rules (the same baseline config) and copied, not trained.
        rows.setdefault(label, {})[seed] = run(
            renerf.control_config(dataclasses.replace(config, seed=seed), steps), scene,
            os.path.join(root, label, f'seed{seed}'),
            [os.path.join(root, twin, f'seed{seed}')])[0]
  if rounds > 1:
    runs = [renerf_runs[s] for s in args.seeds]
    dirs = [os.path.join(root, 'Re-Nerfing', f'seed{s}') for s in args.seeds]
    steps = tables.equal_time_steps(root, config, runs, dirs)
    for seed in args.seeds:
      cfg = dataclasses.replace(config, seed=seed, num_rounds=0, max_steps=steps)
      rows.setdefault('B equal time', {})[seed] = dict(run(
          cfg, scene, os.path.join(root, 'B equal time', f'seed{seed}'))[0], steps=steps)
  return rows


def pairs_of(all_rows, scenes, seeds, label, ref):
  """[(metrics of row `label`, metrics of row `ref`)] of the same (scene, seed)."""
  return [(all_rows[sc][label][s], all_rows[sc][ref][s]) for sc in scenes
          if label in all_rows[sc] and ref in all_rows[sc] for s in seeds
          if s in all_rows[sc][label] and s in all_rows[sc][ref]]


def summarize(all_rows, scenes, seeds):
  """Per scene and over scenes: mean +- std of each row and its paired deltas against
  each reference row of REFERENCES (B, the seed-matched controls, B 2x, R1)."""
  out = {'scenes': {}, 'mean': {}}
  labels = []
  for sc in scenes:
    for label in all_rows[sc]:
      if label not in labels:
        labels.append(label)
  for sc in scenes:
    rows = all_rows[sc]
    res = {}
    for label, by_seed in rows.items():
      entry = {k: tables.mean_std([m[k] for m in by_seed.values()]) for k in METRICS
               if all(k in m for m in by_seed.values())}
      entry['seconds'] = tables.mean_std([m['cumulative_seconds'] for m in by_seed.values()])
      steps = sorted({m['steps'] for m in by_seed.values() if 'steps' in m})
      if steps:  # B at the rounds' total time: this scene's step count
        entry['steps'] = steps
      for key, ref, _ in REFERENCES:
        if label != ref and ref in rows and not (key == 'paired_R1' and label == 'B'):
          entry[key] = pair_stats(pairs_of(all_rows, [sc], seeds, label, ref))
      res[label] = entry
    for key, _, _ in REFERENCES:  # Holm over the rows compared with one reference
      holm(res[label].get(key, {}) for label in res)
    res['paper_R1_delta'] = paper_delta(sc)
    out['scenes'][sc] = res
  for label in labels:
    if label == 'B':
      continue
    # The mean over scenes of each scene's mean delta, and the pooled pairs.
    per_scene = {k: [out['scenes'][sc][label]['paired'][k]['mean'] for sc in scenes
                     if k in out['scenes'][sc].get(label, {}).get('paired', {})]
                 for k in METRICS}
    entry = {'mean_of_scene_means': {k: tables.mean_std(v) for k, v in per_scene.items() if v},
             'scenes': sum(label in all_rows[sc] for sc in scenes)}
    for key, ref, _ in REFERENCES:  # 'pooled', 'pooled_ctrl', ... ({} when no pair)
      entry['pooled' + key[len('paired'):]] = (
          pair_stats(pairs_of(all_rows, scenes, seeds, label, ref)) if label != ref else {})
    out['mean'][label] = entry
  for key, _, _ in REFERENCES:
    pooled = 'pooled' + key[len('paired'):]
    if len(scenes) == 1:  # The pooled table repeats the scene's tests: the same Holm p.
      for label, e in out['mean'].items():
        e[pooled] = copy.deepcopy(out['scenes'][scenes[0]].get(label, {}).get(key, {}))
    else:
      holm(e[pooled] for e in out['mean'].values())
  paper = [paper_delta(sc) for sc in scenes if paper_delta(sc)]
  out['paper_R1_delta_mean'] = {k: round(float(np.mean([p[k] for p in paper])), 3)
                                for k in METRICS} if paper else None
  return out


def holm(cells):
  """Holm-adjusts one family of comparisons in place (paired.adjust_family), per metric:
  cells are pair_stats results {metric: paired_summary} of the rows of one table compared
  with one reference (one column of a scene's table or of the pooled table)."""
  cells = list(cells)
  for k in METRICS:
    paired.adjust_family([c[k] for c in cells if k in c], BETTER[k])


def fmt_pair(p, k, d=2):
  """One cell: mean +- std (wins/n), p-value and 95% interval; bold when a gain is shown."""
  return paired.format_cell(p.get(k, {}), d)


# ../shared/REFERENCE_NUMBERS.md: the paper's 3DGS rows are on mip-NeRF 360 (30 views),
# not LLFF; its mean R1 delta there (PSNR, SSIM, LPIPS).
PAPER_3DGS_360 = (20.49, .600, .259), (21.30, .627, .235)


def markdown(summary, scenes, command, sources=(), backbone='nerf'):
  lines = []
  for sc in scenes:
    res = summary['scenes'][sc]
    pd = res['paper_R1_delta']
    labels = [lb for lb in res if lb != 'paper_R1_delta']
    refs = [(key, name) for key, ref, name in REFERENCES if ref in labels]
    lines += [f'### {sc}', '', '| row | PSNR | SSIM | LPIPS-alex | cum. s | '
              + ' | '.join(f'dPSNR vs {name}' for _, name in refs) + ' |',
              '|---|---|---|---|---|' + '---|' * len(refs)]
    for label in labels:
      e = res[label]
      cell = lambda k, d: f'{e[k][0]:.{d}f} +- {e[k][1]:.{d}f}' if k in e else ''
      shown = f"{label} ({', '.join(map(str, e['steps']))} steps)" if 'steps' in e else label
      lines.append(f"| {shown} | {cell('psnr', 2)} | {cell('ssim', 3)} | "
                   f"{cell('lpips_alex', 3)} | {e['seconds'][0]:.0f} | "
                   + ' | '.join(fmt_pair(e.get(key, {}), 'psnr') for key, _ in refs) + ' |')
    if pd:
      lines.append(f"| paper R1 - RegNeRF | | | | | {pd['psnr']:+.2f} |" + ' |' * (len(refs) - 1))
    lines += ['', f'dSSIM and dLPIPS-alex of {sc}:', '',
              '| row | ' + ' | '.join(f'dSSIM vs {n} | dLPIPS vs {n}' for _, n in refs[:2])
              + ' |', '|---|' + '---|---|' * len(refs[:2])]
    for label in labels:
      e = res[label]
      lines.append(f'| {label} | ' + ' | '.join(
          f"{fmt_pair(e.get(key, {}), 'ssim', 3)} | {fmt_pair(e.get(key, {}), 'lpips_alex', 3)}"
          for key, _ in refs[:2]) + ' |')
    lines.append('')
  pooled_refs = [(key, ref, name) for key, ref, name in REFERENCES
                 if any(ref in summary['scenes'][sc] for sc in scenes)]
  lines += ['### Over scenes (pooled pairs)', '',
            '| row | scenes | mean of scene means dPSNR vs B | '
            + ' | '.join(f'dPSNR vs {name}' for _, _, name in pooled_refs)
            + ' | dSSIM vs B | dLPIPS vs B |',
            '|---|---|---|' + '---|' * len(pooled_refs) + '---|---|']
  for label, e in summary['mean'].items():
    m = e['mean_of_scene_means']
    mp = f"{m['psnr'][0]:+.2f} +- {m['psnr'][1]:.2f}" if 'psnr' in m else ''
    lines.append(f"| {label} | {e['scenes']} | {mp} | " + ' | '.join(
        fmt_pair(e.get('pooled' + key[len('paired'):], {}), 'psnr')
        for key, _, _ in pooled_refs)
        + f" | {fmt_pair(e['pooled'], 'ssim', 3)} | {fmt_pair(e['pooled'], 'lpips_alex', 3)} |")
  pad = ' |' * len(pooled_refs)
  if summary['paper_R1_delta_mean']:
    pm = summary['paper_R1_delta_mean']
    lines.append(f"| paper R1 - RegNeRF (these scenes) | | {pm['psnr']:+.2f} |{pad} "
                 f"{pm['ssim']:+.3f} | {pm['lpips_alex']:+.3f} |")
  if backbone == 'gaussians':
    b, r1 = PAPER_3DGS_360
    lines.append(f'| paper R1 - 3DGS (mip-NeRF 360, 30 views: no LLFF 3DGS rows) | | '
                 f'{r1[0] - b[0]:+.2f} |{pad} {r1[1] - b[1]:+.3f} | {r1[2] - b[2]:+.3f} |')
    lines += ['', 'Backbone: 3D Gaussian Splatting.' + (
        ' The "paper R1 - RegNeRF" rows are the paper\'s LLFF deltas on its NeRF backbone, '
        'for scale only.' if summary['paper_R1_delta_mean'] else '')]
  lines += ['', 'Each delta: the row minus the reference row of the same (scene, seed), '
            'mean +- std over pairs (wins/n: pairs where the row is better: higher PSNR / '
            'SSIM, lower LPIPS), the two-sided paired t-test p-value, its Holm '
            'adjustment ("Holm") over the rows compared with the same reference in the '
            'same table (one column; the pooled table is a table of its own) and the '
            'paired bootstrap 95% interval of the mean delta (unadjusted). **Bold**: a '
            'gain is shown (the interval excludes 0 and the Holm p < 0.05); anything else '
            'is not a gain. References: '
            "B; D's seed K 0 = B's training at D's seed (Config.d_seed), i.e. D without "
            "pseudo-views, the control that differs from R1 in the pseudo-views alone; "
            "D's seed 2x = the same at 2x B's steps; B 2x = B trained 2x longer (the "
            'control for more compute); R1 (e.g. masks on against off).', '',
            'Command:', '', f'    {command}', '']
  if sources:
    lines += ['Merged from the tables of:', ''] + [f'    {c}' for c in sources] + ['']
  return '\n'.join(lines)


def refresh(path):
  """Rewrites the table `path` (its .json summary and its .md) from its rows with the
  current statistics; its command, sources and everything else are kept."""
  table = report.read_json(path)
  if 'rows' not in table or 'summary' not in table or 'command' not in table:
    raise SystemExit(f'--refresh: {path} is not a renerf_scenes table')
  rows = {sc: {label: {int(seed): m for seed, m in by_seed.items()}
               for label, by_seed in labels.items()} for sc, labels in table['rows'].items()}
  scenes = list(rows)
  seeds = sorted({s for labels in rows.values() for by_seed in labels.values()
                  for s in by_seed})
  table['summary'] = summarize(rows, scenes, seeds)
  report.write_json(path, table)
  base = os.path.splitext(path)[0]
  report.write_markdown(base + '.md', markdown(
      table['summary'], scenes, table['command'], table.get('sources', ()),
      table.get('backbone', 'nerf')))


def plot(summary, scenes, path):
  labels = [lb for lb in summary['mean']]
  fig, axes = figures.subplots(1, len(METRICS), figsize=(5 * len(METRICS), 3.6))
  axes = axes[0]
  width = 0.8 / max(len(labels), 1)
  for ax, k in zip(axes, METRICS):
    for i, label in enumerate(labels):
      xs, ys, es = [], [], []
      for j, sc in enumerate(scenes):
        p = summary['scenes'][sc].get(label, {}).get('paired', {})
        if k in p:
          xs.append(j + (i - len(labels) / 2 + 0.5) * width)
          ys.append(p[k]['mean'])
          es.append(p[k]['std'])
      ax.bar(xs, ys, width, yerr=es, capsize=2, label=label)
    pd = [summary['scenes'][sc]['paper_R1_delta'] for sc in scenes]
    ax.scatter([j for j, p in enumerate(pd) if p], [p[k] for p in pd if p], marker='*',
               color='k', zorder=5, label='paper R1')
    ax.axhline(0, color='grey', lw=0.8)
    ax.set_xticks(range(len(scenes)))
    ax.set_xticklabels(scenes)
    ax.set_title(f'{k}: D - B (paired by seed)')
  axes[0].legend(fontsize=7)
  fig.tight_layout()
  figures.save_figure(fig, path, dpi=100)


def main(argv=None):
  p = parser()
  args = p.parse_args(argv)
  command = tables.command_line('experiments.renerf_scenes', argv)
  table = args.table or args.name
  if args.refresh:
    for path in args.refresh:
      refresh(path)
    return
  if args.merge:
    all_rows, seeds, sources, (config, _, _), backbone = merged_rows(args.merge)
    scenes = list(all_rows)
    summary = summarize(all_rows, scenes, seeds)
    write_table(args.out, table, {'name': args.name, 'config': config, 'seeds': seeds,
                                  'backbone': backbone, 'rows': all_rows, 'summary': summary,
                                  'command': command, 'sources': sources},
                scenes, command, sources, backbone)
    return
  if not args.config:
    p.error('--config is required unless --merge is given')
  if args.no_r1 and args.rounds_scenes:
    p.error('--no_r1 leaves no rounds for --rounds_scenes')
  for flag, names in (('--rounds_scenes', args.rounds_scenes),
                      ('--scenes_2x', args.scenes_2x or [])):
    extra = [n for n in names if n not in args.scenes]
    if extra:
      p.error(f'{flag} names {", ".join(extra)}, not in --scenes ({" ".join(args.scenes)})')
  jit_cache.enable_compilation_cache()
  bindings = args.gin_bindings + [f'Config.data_dir = {args.data_dir!r}']
  all_rows = {sc: scene_runs(args, sc, bindings) for sc in args.scenes}
  summary = summarize(all_rows, args.scenes, args.seeds)
  backbone = load_config(args.config, bindings).backbone
  write_table(args.out, table, {'name': args.name, 'config': args.config, 'seeds': args.seeds,
                                'backbone': backbone, 'rows': all_rows, 'summary': summary,
                                'command': command},
              args.scenes, command, backbone=backbone)


def write_table(out, table, result, scenes, command, sources=(), backbone='nerf'):
  """Writes <out>/<table>.json, .md and .png and prints the markdown."""
  report.write_json(os.path.join(out, table + '.json'), result)
  text = markdown(result['summary'], scenes, command, sources, backbone)
  report.write_markdown(os.path.join(out, table + '.md'), text)
  plot(result['summary'], scenes, os.path.join(out, table + '.png'))
  print(text)


if __name__ == '__main__':
  main()
