"""Stored parameters read back with damage in mind: training checkpoints and a finished
round's params.msgpack (flax msgpack files).

Writes are atomic (report.atomic_open), so a damaged file (truncated, emptied, cut short
by a copy or a full disk) comes from outside the run. A checkpoint is a cache of state
that training recomputes bit for bit (a resumed run equals an uninterrupted one), so a
damaged one is set aside and training resumes from the checkpoint before it; a finished
round's parameters are a result, so a damaged one is one line (RunDirError), never
silently trained again. Imports no module that imports rundir.
"""
import os
import sys

from flax import serialization

from renerf_jax import distributed
from renerf_jax.errors import RunDirError

DAMAGED_SUFFIX = '.damaged'  # A damaged checkpoint's new name: <checkpoint>.damaged.


def _first_line(e: Exception) -> str:
  text = str(e).strip()
  return f'{type(e).__name__}: {text.splitlines()[0]}' if text else type(e).__name__


def _fit(path, template, state_dict):
  """state_dict restored into template's structure; RunDirError when it does not fit."""
  try:
    return serialization.from_state_dict(template, state_dict)
  except (ValueError, KeyError, TypeError, AttributeError) as e:
    raise RunDirError(f"{path} does not fit this run's model ({_first_line(e)}); pass "
                      '--run_dir to start a new run') from None


def restore_newest(checkpoints, template):
  """The newest checkpoint that decodes, restored into template's structure, or None.

  Args:
    checkpoints: [(step, path)] sorted by step (rundir.list_checkpoints).
    template: the pytree the checkpoints hold (its structure and dtypes).

  Returns:
    The restored pytree, or None when no checkpoint decodes (training starts over).
    A checkpoint that does not decode is renamed <path>.damaged by process 0 (so it is
    never read again, and kept to look at), with one warning line on stderr naming it.

  Raises:
    RunDirError: a checkpoint that decodes but does not fit template (another model).
  """
  for i in range(len(checkpoints) - 1, -1, -1):
    path = checkpoints[i][1]
    try:
      with open(path, 'rb') as f:
        state_dict = serialization.msgpack_restore(f.read())
    except Exception as e:  # pylint: disable=broad-except  (msgpack's errors, OSError)
      then = (f'resuming from step {checkpoints[i - 1][0]}' if i else
              'no checkpoint left: training starts over')
      if distributed.is_writer():
        print(f'warning: {path} is damaged ({_first_line(e)}); moved to '
              f'{os.path.basename(path)}{DAMAGED_SUFFIX}, {then}', file=sys.stderr)
        if os.path.exists(path):
          os.replace(path, path + DAMAGED_SUFFIX)
      continue
    return _fit(path, template, state_dict)
  return None


def read_params(path, template, what):
  """A finished round's parameters (params.msgpack) restored into template.

  Args:
    path: the file. template: the parameter pytree. what: the round, for the message
      (e.g. 'round 1 of runs/demo').

  Raises:
    RunDirError: one line when the file is missing, does not decode, or does not fit.
  """
  try:
    with open(path, 'rb') as f:
      state_dict = serialization.msgpack_restore(f.read())
  except Exception as e:  # pylint: disable=broad-except
    raise RunDirError(f'{path} is damaged ({_first_line(e)}): {what} is marked finished '
                      'with it; move that round directory aside to train the round '
                      'again') from None
  return _fit(path, template, state_dict)
