"""Shared pieces of the command-line entry points (train.py, eval.py)."""
import dataclasses
import os

from renerf_jax import jit_cache, report
from renerf_jax.configs import (config_differences, config_to_gin, default_run_dir,
                                fields_where, load_config, parse_args)
from renerf_jax.errors import RunDirError


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
