"""Shared pieces of the command-line entry points (train.py, eval.py)."""
import dataclasses
import os

from renerf_jax import jit_cache, report
from renerf_jax.configs import config_to_gin, default_run_dir, load_config, parse_args
from renerf_jax.errors import RunDirError

# Fields that may change between invocations on one run directory without invalidating
# what it holds (more rounds, logging and rendering knobs, the Hessian pass's chunking).
RESUMABLE_FIELDS = ('num_rounds', 'print_every', 'render_chunk', 'hessian_chunk',
                    'eval_n_views', 'eval_every', 'eval_stride', 'checkpoint_every',
                    'lpips_nets')


def setup(argv, description):
  """Parses flags and gin, turns on the compilation cache; returns (config, run_dir)."""
  args = parse_args(argv, description)
  jit_cache.enable_compilation_cache()
  config = load_config(args.gin_configs, args.gin_bindings)
  return config, args.run_dir or default_run_dir(args.gin_configs)


def check_run_dir(config, run_dir, create):
  """Guards a run directory against being reused with a different configuration.

  The first call writes run_dir/config.json (and the operative gin config); a later call
  with a configuration differing in anything but RESUMABLE_FIELDS raises RunDirError, so
  earlier results are never mixed with or overwritten by a different experiment.
  """
  path = os.path.join(run_dir, 'config.json')
  current = report.to_jsonable(dataclasses.asdict(config))
  if os.path.isfile(path):
    saved = report.read_json(path)
    # A field added to Config after the run was made counts as its default value.
    defaults = report.to_jsonable(dataclasses.asdict(type(config)()))
    saved = dict({k: v for k, v in defaults.items() if k not in saved}, **saved)
    diff = sorted(k for k in set(saved) | set(current)
                  if k not in RESUMABLE_FIELDS and saved.get(k) != current.get(k))
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
