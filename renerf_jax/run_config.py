"""A run directory's stored configuration read back with one-line errors: config.json
(what a resumed train.py and eval.py compare the new Config against) and config.gin
(what the viewer and experiments/run_summary.py load), each checked against the other.

Both are written when the run directory is made (config.gin first, config.json last:
it marks the directory as made); config.json is rewritten when a resumable field
changes, config.gin is not. A damaged one (not JSON, not gin, cut short) cannot say
which configuration made the rounds, and guessing could mix experiments, so it is a
RunDirError naming the file: nothing is trained, evaluated or written.
"""
import json
import os
import re
from typing import Sequence

from renerf_jax import report, rundir
from renerf_jax.configs import Config, config_differences, fields_where, load_config
from renerf_jax.errors import ConfigError, RunDirError

_FIELDS = frozenset(Config.__dataclass_fields__)


def read_saved_config(run_dir) -> dict:
  """run_dir/config.json as a dict of Config fields.

  Raises:
    RunDirError: it cannot be read, is not JSON, or is not an object of Config fields.
  """
  path = rundir.config_json_path(run_dir)
  try:
    saved = report.read_json(path)
  except (OSError, ValueError) as e:
    why = f'{type(e).__name__}: {e}' if isinstance(e, json.JSONDecodeError) else (
        type(e).__name__)
    raise RunDirError(f'{path} is damaged ({why}): it records the configuration of the '
                      f'rounds in {run_dir}; restore it, or pass --run_dir to start a '
                      'new run') from None
  if not isinstance(saved, dict) or not saved or not set(saved) & _FIELDS:
    raise RunDirError(f'{path} is damaged (not an object of Config fields): it records '
                      f'the configuration of the rounds in {run_dir}; restore it, or pass '
                      '--run_dir to start a new run')
  return saved


def load_run_config(run_dir, gin_bindings: Sequence[str] = ()) -> Config:
  """The Config run_dir/config.gin holds (fields its backbone ignores at their defaults:
  a config.gin written before such settings were refused still loads), checked against
  config.json in every field that may not change between invocations.

  Args:
    run_dir: the run directory. gin_bindings: bindings applied after config.gin (e.g.
      another Config.data_dir); the fields they bind are not compared.

  Raises:
    RunDirError: either file missing or damaged, or the two disagreeing (config.gin cut
      short at a line: the missing fields take their defaults).
  """
  path = rundir.config_gin_path(run_dir)
  if not os.path.isfile(rundir.config_json_path(run_dir)) or not os.path.isfile(path):
    raise RunDirError(f'{run_dir} is not a run directory (config.json / config.gin '
                      'missing); train first, e.g. python train.py '
                      '--gin_configs=gin_configs/demo.gin')
  try:
    config = load_config([path], gin_bindings, reset_ignored=True)
  except ConfigError as e:
    raise RunDirError(f'{path} is damaged ({e}); restore it, or pass --run_dir to start '
                      'a new run') from None
  bound = {m.group(1) for b in gin_bindings for m in [re.match(r'\s*Config\.(\w+)', b)] if m}
  diff = config_differences(config, read_saved_config(run_dir),
                            tuple(bound) + fields_where('resumable'))
  if diff:
    raise RunDirError(f'{path} is damaged: its Config.{diff[0]} differs from '
                      f'{rundir.config_json_path(run_dir)} (written with it when the run '
                      'was made); restore it, or pass --run_dir to start a new run')
  return config
