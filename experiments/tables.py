"""Shared machinery of the paper-table scripts (renerf_rounds.py, table_*.py).

A table is a list of variants, each the base config plus gin bindings, run for a number of
rounds per seed with a fixed step count per round; every number is a mean +- std over
seeds. Runs live in <out>/<name>/<variant>/seed<k> (train.py-style run directories with
config.json: resumable, finished rounds are never rewritten, a directory made with
another config is refused).

Variants that differ only from round 1 on have the same baseline (sharing.ROUND_FIELDS):
it is trained once per seed and copied (sharing.copy_baseline) into the other variants'
directories, and can be taken from another table's runs with --baseline_from (e.g. the
rounds table's). A copied baseline is the same model bit for bit, so sharing changes no
number; its row is shown once.
Round 1's pseudo-views (and masks) are shared the same way between variants that agree on
every field but sharing.NOT_PSEUDO_VIEW_FIELDS (e.g. the masks table's 'augmented views'
and 'stop aug. views'): rendered once per seed, the copy keeps their render seconds in the cumulative time.

Optionally (--equal_time) the baseline is also trained for the same total wall time as
the rounds of the first variant (training + pseudo-view synthesis + uncertainty): a FIXED
step count, the same for every seed, stored in <out>/<name>/equal_time.json and reused:
the median over seeds of the sum over rounds of max_steps x (round seconds) / (that
round's training seconds), so each round is counted at its own pace and the load on the
machine when it ran cancels. The median makes it robust to one seed whose synthesis shared
the CPU with something its training did not.

Writes <out>/<name>.json, <name>.md (our numbers; the paper's beside them where the
script has them), <name>_time.png (cheap test PSNR during training against cumulative
seconds, every seed) and <name>_metrics_time.png (PSNR, SSIM and LPIPS of the full
evaluation after each round against cumulative seconds, mean +- std over seeds, with
the equal-time baseline as a point of its own).
"""
import argparse
import dataclasses
import os
import re
import shlex
import sys

import numpy as np

from experiments import sharing
from renerf_jax import auto_rounds, cli, figures, jit_cache, report, round_driver, rundir
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene
from renerf_jax.errors import ConfigError

METRICS = ('psnr', 'ssim', 'lpips_alex', 'lpips_vgg')
NAMES = {'psnr': 'PSNR', 'ssim': 'SSIM', 'lpips_alex': 'LPIPS-alex', 'lpips_vgg': 'LPIPS-vgg'}


def parser(description, default_rounds):
  p = argparse.ArgumentParser(description=description,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--name', required=True, help='results name under --out')
  p.add_argument('--config', required=True, nargs='+',
                 help='gin config file(s), stacked in order (e.g. experiments/configs/'
                      'table_tiny.gin, or gin_configs/llff3_fast.gin gin_configs/'
                      'renerf.gin); a bare name is looked up in gin_configs/')
  p.add_argument('--gin_bindings', action='append', default=[])
  p.add_argument('--data_dir', help='shortcut for Config.data_dir')
  p.add_argument('--scene', help='shortcut for Config.scene')
  p.add_argument('--rounds', type=int, default=default_rounds,
                 help='rounds after the baseline (a variant binding Config.num_rounds '
                      'keeps its own)')
  p.add_argument('--variant', action='append', default=[],
                 help='LABEL=binding;binding (empty: the config as is); replaces the '
                      "script's variants")
  p.add_argument('--seeds', type=int, nargs='+', default=[0, 1, 2])
  p.add_argument('--baseline_from', default=None,
                 help='run directory template with {seed}, e.g. experiments/results/'
                      'fern_rounds_fast/Re-Nerfing/seed{seed}: take round_0 from there '
                      'when its baseline config matches')
  p.add_argument('--out', default='experiments/results')
  return p


def bindings_of(args):
  bindings = list(args.gin_bindings)
  if args.data_dir:
    bindings.append(f"Config.data_dir='{args.data_dir}'")
  if args.scene:
    bindings.append(f"Config.scene='{args.scene}'")
  return bindings


def base_config(args):
  return load_config(args.config, bindings_of(args))


def command_line(module=None, argv=None):
  """The shell line that ran this program, as a table records it: `python -m MODULE ARGS`.

  Args:
    module: the script as a module (e.g. 'experiments.renerf_scenes'); default: the module
      that runs as __main__ (python -m), or the script's path if it was run as a file.
    argv: its arguments; default: this process's (sys.argv[1:]).
  """
  args = list(sys.argv[1:] if argv is None else argv)
  if module is None:
    spec = getattr(sys.modules['__main__'], '__spec__', None)
    if spec is None:  # run as a file: python path/to/script.py
      return 'python ' + shlex.join(sys.argv[:1] + args)
    module = spec.name
  return 'python ' + shlex.join(['-m', module] + args)


def mean_std(vals):
  vals = np.asarray(vals, np.float64)
  return float(vals.mean()), (float(vals.std(ddof=1)) if len(vals) > 1 else 0.)


def variant_spec(spec):
  """A --variant 'LABEL=binding;binding' -> (label, [bindings]).

  The label ends at the first '=' that a 'Config.' binding follows, so a label may hold
  '=' itself ('acc <= 0.5=Config.mask_threshold = 0.5'); with no such binding, at the
  first '=' ('plain='); a spec without '=' is a label with no bindings.
  """
  m = re.search(r'=(?=\s*Config\.)', spec)
  cut = m.start() if m else spec.find('=')
  if cut < 0:
    return spec, []
  if cut == 0:
    raise SystemExit(f"error: --variant {spec!r} is not 'LABEL=binding;binding'")
  return spec[:cut], [b for b in spec[cut + 1:].split(';') if b.strip()]


def label_values(specs, what, labels=None):
  """{LABEL: VALUE} of command-line 'LABEL=VALUE' specs (one clear error line if malformed).

  Args:
    specs: the strings given to an option. what: the option's name, for the error.
    labels: if given, the labels allowed; each may then be given once.

  Returns:
    dict in the order given (a repeated label keeps its last value when labels is None).
  """
  out = {}
  for spec in specs:
    label, sep, value = spec.partition('=')
    if not sep or not label or not value:
      raise SystemExit(f'error: {what} {spec!r} is not LABEL=VALUE')
    if labels is not None:
      if label not in labels:
        raise SystemExit(f'error: {what} {spec!r}: no --method is labelled {label!r}')
      if label in out:
        raise SystemExit(f'error: {what} is given twice for {label!r}')
    out[label] = value
  return out


def round_name(r):
  return 'baseline' if r == 0 else f'R{r}'


def curve_of(run_dir, rounds):
  """(cumulative seconds, cheap test PSNR) over the rounds of one run."""
  pts = []
  for r in range(rounds + 1):
    path = rundir.result_path(rundir.round_dir(run_dir, r))
    pts += [(c['time'], c['eval_psnr']) for c in report.read_json(path)['curve']]
  return pts


def run_seed(config, scene, run_dir, share_from=()):
  """Rounds of one (variant, seed); round_0 copied from a matching finished run if any.

  Round 1's pseudo-views are copied too from a run in share_from with the same baseline
  and pseudo-view settings (sharing.share_pseudo_views): variants that differ only in how
  D is trained render them once per seed.

  Whole finished rounds are copied from a run in share_from made with the same config
  (sharing.copy_finished_rounds), e.g. the masks table's '+ masks' from the rounds table.

  Returns:
    (list of per-round metrics, the run directory round_0 was copied from or None, the
    run directory later rounds were copied from or None).
  """
  if auto_rounds.is_auto(config):
    raise ConfigError("Config.num_rounds='auto' is train.py's: a table's rows train a fixed "
                      'number of rounds (bind an integer)')
  cli.check_run_dir(config, run_dir, create=True)
  copied = None
  if not os.path.exists(rundir.round_dir(run_dir, 0)):
    for src in share_from:
      cfg_path = rundir.config_json_path(src)
      if (os.path.abspath(src) != os.path.abspath(run_dir)
          and rundir.is_done(rundir.round_dir(src, 0)) and os.path.isfile(cfg_path)
          and not sharing.baseline_differences(config, report.read_json(cfg_path))):
        sharing.copy_baseline(config, src, run_dir)
        copied = src
        break
  elif os.path.isfile(rundir.shared_baseline_path(run_dir)):
    copied = report.read_json(rundir.shared_baseline_path(run_dir))['from']
  if copied:
    report.write_json(rundir.shared_baseline_path(run_dir), {'from': copied})
  rounds_from = None
  if config.num_rounds > 0 and rundir.is_done(rundir.round_dir(run_dir, 0)):
    for src in share_from:  # Whole rounds, if another run made them with this config.
      if sharing.copy_finished_rounds(config, src, run_dir):
        break
    for src in share_from:  # Round 1's pseudo-views, if another variant made the same.
      if sharing.share_pseudo_views(config, src, run_dir):
        break
  for r in range(1, config.num_rounds + 1):
    path = rundir.copied_from_path(rundir.round_dir(run_dir, r))
    if os.path.isfile(path):
      rounds_from = os.path.dirname(report.read_json(path)['from'])
  state = round_driver.run_rounds(config, scene, run_dir,
                                  synthesize_fn=sharing.memo_synthesize)
  # The next run's Config (seed, variant) differs, so none of this run's executables is
  # called again; kept, their memory mappings pile up over a table's runs.
  jit_cache.release_compiled()
  return list(state.metrics), copied, rounds_from


def summarize(label, runs, rounds):
  """Rows (one per round) of mean +- std over seeds."""
  rows = []
  for r in range(rounds + 1):
    ms = [run[r] for run in runs]
    row = {'variant': label, 'round': round_name(r), 'seeds': len(ms)}
    for k in METRICS + ('cumulative_seconds',):
      if all(k in m for m in ms):  # lpips_vgg is absent when Config.lpips_nets omits it
        row[k], row[k + '_std'] = mean_std([m[k] for m in ms])
    rows.append(row)
  return rows


def round_step_equivalents(max_steps, round_seconds, train_seconds):
  """Steps of plain training worth one round's time, at that round's own pace.

  A round trains max_steps steps in train_seconds and spends round_seconds in all
  (training plus pseudo-view synthesis and uncertainty). Measuring each round against its
  own training pace cancels the load on the machine, which differs between rounds run at
  different times: rounds on an idle machine and on a busy one count alike. It assumes a
  step of the baseline costs what a step of the round costs (the same config; the rounds'
  pseudo-rays replace real rays in the same batch).

  Args:
    max_steps: training steps of the round.
    round_seconds: the round's seconds in all.
    train_seconds: the seconds of its training loop (> 0).

  Returns:
    max_steps * round_seconds / train_seconds.
  """
  if not train_seconds > 0:
    raise ValueError(f'train_seconds must be > 0 (got {train_seconds!r})')
  return max_steps * round_seconds / train_seconds


EQUAL_TIME_RULE = ('median over seeds of the sum over rounds of max_steps x round seconds / '
                   'that round\'s training seconds')


def synthesis_seconds(run_dir, r):
  """Seconds of round r's pseudo-view synthesis (0 for the baseline), from its timing.json."""
  if r == 0:
    return 0.
  path = rundir.timing_path(rundir.pseudo_views_dir(rundir.round_dir(run_dir, r)))
  if not os.path.isfile(path):
    raise SystemExit(f'error: {path} not found (round {r} has no synthesis timing)')
  return report.read_json(path)['seconds']


def equal_time_steps(root, config, runs, run_dirs):
  """Fixed step count of the equal-total-time baseline (computed once, then reused).

  Per seed, the sum over rounds of round_step_equivalents (each round at its own pace:
  training seconds = round seconds - synthesis seconds); the median over seeds. A stored
  equal_time.json made with another rule is refused (delete it to recompute).
  """
  path = os.path.join(root, 'equal_time.json')
  if os.path.isfile(path):
    saved = report.read_json(path)
    if saved.get('rule') != EQUAL_TIME_RULE:
      raise SystemExit(f'error: {path} was computed with another rule '
                       f'({saved.get("rule")!r}); delete it to recompute the step count')
    return saved['max_steps']
  per_seed = []
  for ms, run_dir in zip(runs, run_dirs):
    per_seed.append(sum(
        round_step_equivalents(config.max_steps, m['round_seconds'],
                               m['round_seconds'] - synthesis_seconds(run_dir, m['round']))
        for m in ms))
  steps = round(float(np.median(per_seed)))
  report.write_json(path, {'max_steps': steps, 'per_seed_steps': per_seed,
                           'from_runs': run_dirs, 'rule': EQUAL_TIME_RULE})
  return steps


def run_table(args, variants, paper=None, equal_time=False, paper_note=''):
  """Runs every variant for every seed and writes the table.

  Args:
    args: parsed arguments of parser().
    variants: list of 'LABEL=binding;binding'.
    paper: optional {(variant label or '*', round name): (PSNR, SSIM, LPIPS)}.
    equal_time: also train the baseline for the total time of the first variant's rounds.
    paper_note: a sentence on where the paper's numbers come from (or why they are absent).

  Returns:
    The results dict written to <out>/<name>.json.
  """
  jit_cache.enable_compilation_cache()
  bindings = bindings_of(args)
  root = os.path.join(args.out, args.name)
  results = {'name': args.name, 'config': ' '.join(args.config), 'bindings': bindings,
             'seeds': args.seeds, 'variants': [], 'command': command_line()}
  rows, curves, shared_rows, summaries, copied_rounds = [], {}, set(), {}, {}
  first_runs = None
  labels = [variant_spec(v)[0] for v in variants]
  for vi, spec in enumerate(variants):
    label, extra = variant_spec(spec)
    config = load_config(args.config, bindings + extra)
    if not any(b.replace(' ', '').startswith('Config.num_rounds=') for b in extra):
      config = dataclasses.replace(config, num_rounds=args.rounds)
    scene = load_scene(config)
    runs, dirs, copied, rounds_copied = [], [], [], []
    for seed in args.seeds:
      run_dir = os.path.join(root, label, f'seed{seed}')
      share = [os.path.join(root, lb, f'seed{seed}') for lb in labels[:vi]]
      if args.baseline_from:
        share.append(args.baseline_from.format(seed=seed))
      metrics, src, rounds_src = run_seed(dataclasses.replace(config, seed=seed), scene,
                                          run_dir, share)
      runs.append(metrics)
      dirs.append(run_dir)
      copied.append(src)
      rounds_copied.append(rounds_src)
      curves[f'{label} seed {seed}'] = curve_of(run_dir, config.num_rounds)
    results['variants'].append({'label': label, 'bindings': extra, 'runs': runs,
                                'run_dirs': dirs, 'baseline_copied_from': copied,
                                'rounds_copied_from': rounds_copied})
    if any(rounds_copied):
      copied_rounds[label] = sorted({os.path.relpath(os.path.dirname(d)) for d in rounds_copied
                                     if d})
    vrows = summarize(label, runs, config.num_rounds)
    summaries[label] = vrows
    # A baseline copied from an earlier variant of this table is that variant's row.
    if vi > 0 and all(c and os.path.abspath(c).startswith(os.path.abspath(root) + os.sep)
                      for c in copied):
      shared_rows.add(label)
      vrows = vrows[1:]
    rows += vrows
    if first_runs is None:
      first_runs, first = runs, (config, scene, dirs)

  if equal_time:
    config, scene, dirs = first
    steps = equal_time_steps(root, config, first_runs, dirs)
    runs = []
    for seed in args.seeds:
      cfg = dataclasses.replace(config, seed=seed, num_rounds=0, max_steps=steps)
      eq_dir = os.path.join(root, 'equal_time_baseline', f'seed{seed}')
      runs.append(run_seed(cfg, scene, eq_dir)[0])
      curves[f'baseline {steps} steps seed {seed}'] = curve_of(eq_dir, 0)
    results['equal_time'] = {'max_steps': steps, 'runs': runs}
    row = summarize('baseline, equal total time', runs, 0)[0]
    row['round'] = f'{steps} steps'
    rows.append(row)
    summaries[f'baseline, {steps} steps'] = [row]

  results['rows'] = rows
  report.write_json(os.path.join(args.out, args.name + '.json'), results)
  if copied_rounds:
    paper_note += ''.join(
        f" The rounds of '{label}' are those of {', '.join(srcs)} (the same config; copied "
        f'from there, with their times).' for label, srcs in copied_rounds.items())
  text = markdown(args, rows, paper or {}, shared_rows, paper_note, results['command'])
  report.write_markdown(os.path.join(args.out, args.name + '.md'), text)
  figures.plot_error_vs_time(curves, os.path.join(args.out, args.name + '_time.png'),
                            metric='psnr',
                            title=f'{args.name}: test PSNR vs cumulative seconds')
  figures.plot_metrics_vs_time(
      metric_curves(summaries), os.path.join(args.out, args.name + '_metrics_time.png'),
      title=f'{args.name}: full test metrics after each round vs cumulative seconds '
            f'(mean +- std over seeds {args.seeds})')
  print(text)
  return results


def metric_curves(summaries):
  """{metric: {variant: [(mean cumulative seconds, mean, std of the metric) per round]}}."""
  out = {}
  for metric in METRICS:
    curves = {label: [(r['cumulative_seconds'], r[metric], r.get(metric + '_std', 0.))
                      for r in vrows]
              for label, vrows in summaries.items() if all(metric in r for r in vrows)}
    if curves:
      out[NAMES[metric]] = curves
  return out


def markdown(args, rows, paper, shared_rows, paper_note, command):
  """The table: mean +- std per row, dPSNR against the first row, the paper beside."""
  metrics = [k for k in METRICS if k in rows[0]]
  base = rows[0]
  table = []
  for row in rows:
    out = {'variant': row['variant'], 'round': row['round']}
    for k in metrics:
      out[k] = f"{row[k]:.3f} +- {row[k + '_std']:.3f}" if k in row else ''
    out['time'] = f"{row['cumulative_seconds']:.0f}"
    if row is not base:
      gain = row['psnr'] - base['psnr']
      out['gain'] = f'{gain:+.2f}' + (' *' if abs(gain) > max(base['psnr_std'],
                                                              row['psnr_std']) else '')
    ref = paper.get((row['variant'], row['round'])) or paper.get(('*', row['round']))
    out['paper'] = ' / '.join(f'{v:g}' for v in ref) if ref else ''
    table.append(out)
  cols = ([('variant', 'variant'), ('round', 'round')] + [(k, NAMES[k]) for k in metrics]
          + [('time', 'cum. s'), ('gain', 'dPSNR')]
          + ([('paper', 'paper PSNR / SSIM / LPIPS')] if paper else []))
  shared = (f" The baseline row stands for the baseline of {', '.join(sorted(shared_rows))} "
            f'too (copied, the same model).' if shared_rows else '')
  return (f'# {args.name}\n\nConfig `{" ".join(args.config)}` {bindings_of(args)}, '
          f'seeds {args.seeds}; '
          f'mean +- std over seeds (fixed step counts per round). cum. s: cumulative wall '
          f'seconds (training + pseudo-views + uncertainty). dPSNR: against the first row; '
          f'* = larger than the seed spread (the larger std of the two rows); a gain '
          f'without * is no gain.{shared} {paper_note}\n\n'
          + report.markdown_table(table, cols) + f'\n\nCommand:\n\n    {command}\n')
