"""Shared pieces of the command-line entry points (train.py, eval.py): flags, the run
directory, one-line errors."""
import argparse
import dataclasses
import os
import sys
from typing import Optional, Sequence

from renerf_jax import jit_cache, report
from renerf_jax.configs import config_differences, config_to_gin, fields_where, load_config
from renerf_jax.errors import USER_ERRORS, RunDirError


def parse_args(argv: Optional[Sequence[str]] = None, description: str = ''):
  """Parses --gin_configs / --gin_bindings (both repeatable) and other flags.

  Args:
    argv: command-line arguments without the program name (default sys.argv[1:]).
    description: help text.

  Returns:
    argparse.Namespace with gin_configs, gin_bindings, run_dir.
  """
  parser = argparse.ArgumentParser(description=description)
  parser.add_argument('--gin_configs', action='append', default=[],
                      help='gin config file (repeatable)')
  parser.add_argument('--gin_bindings', action='append', default=[],
                      help="gin binding, e.g. \"Config.max_steps=100\" (repeatable)")
  parser.add_argument('--run_dir', default=None,
                      help='run directory (default runs/<config name>)')
  return parser.parse_args(argv)


def default_run_dir(gin_configs: Sequence[str]) -> str:
  """runs/<stems of the gin files joined by '+'>, e.g. runs/llff3_cpu+renerf."""
  stems = [os.path.splitext(os.path.basename(p))[0] for p in gin_configs]
  return os.path.join('runs', '+'.join(stems) if stems else 'default')


def exit_on_error(fn):
  """Decorator for CLI mains: known user errors become one line on stderr and exit 2."""
  def wrapped(*args, **kwargs):
    try:
      return fn(*args, **kwargs)
    except USER_ERRORS as e:
      print(f'error: {e}', file=sys.stderr)
      sys.exit(2)
  return wrapped


def setup(argv, description):
  """Parses flags and gin, turns on the compilation cache; returns (config, run_dir)."""
  args = parse_args(argv, description)
  jit_cache.enable_compilation_cache()
  config = load_config(args.gin_configs, args.gin_bindings)
  return config, args.run_dir or default_run_dir(args.gin_configs)


def check_run_dir(config, run_dir, create):
  """Guards a run directory against being reused with a different configuration.

  The first call writes run_dir/config.json (and the operative gin config); a later call
  with a configuration differing in a field that is not 'resumable' (its category in
  configs.AFFECTS) raises RunDirError, so earlier results are never mixed with or
  overwritten by a different experiment.
  """
  path = os.path.join(run_dir, 'config.json')
  current = report.to_jsonable(dataclasses.asdict(config))
  if os.path.isfile(path):
    # A field added to Config after the run was made counts as its default value.
    saved = dict(report.to_jsonable(dataclasses.asdict(type(config)())),
                 **report.read_json(path))
    diff = config_differences(config, saved, fields_where('resumable'))
    if diff:
      k = diff[0]
      raise RunDirError(
          f'{run_dir} holds a run made with a different configuration ({k}: '
          f'{saved.get(k)!r} there, {current.get(k)!r} now{", ..." if len(diff) > 1 else ""})'
          f'; pass --run_dir to start a new run')
    if create and saved != current:
      report.write_json(path, current)
  elif create:
    os.makedirs(run_dir, exist_ok=True)
    # config.json last: it marks the directory as made (a run killed in between would
    # otherwise never get its config.gin).
    report.write_markdown(os.path.join(run_dir, 'config.gin'), config_to_gin(config))
    report.write_json(path, current)
  else:
    raise RunDirError(f'no finished run in {run_dir} (config.json missing); train first '
                      f'or pass --run_dir')
