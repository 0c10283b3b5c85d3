"""What a run directory holds, read for looking at it (view.py): the config, the scene,
each round's parameters (finished, or the latest checkpoint of the round in training),
its pseudo-views and its training log. Reads only; never writes into the run.
"""
import dataclasses
from typing import Optional

from flax import serialization

from renerf_jax import auto_rounds, report, rundir
from renerf_jax.datasets import load_scene
from renerf_jax.round_driver import load_pseudo_views, load_round_params, params_template
from renerf_jax.run_config import load_run_config


def run_config(run_dir):
  """The Config a run was made with (run_dir/config.gin, as train.py wrote it, checked
  against config.json: run_config.load_run_config; a damaged one is one RunDirError)."""
  return load_run_config(run_dir)


@dataclasses.dataclass(frozen=True)
class RoundInfo:
  """One round of a run as the viewer lists it."""
  index: int  # 0: the baseline B.
  done: bool  # Finished (params.msgpack + DONE), else training (checkpoint or nothing).
  step: Optional[int]  # Training step of the parameters there (None: none yet).
  # Config.num_rounds = 'auto': the finished round's decision line (auto_rounds.decide).
  decision: Optional[str] = None
  # False for a round whose 'auto' decision discarded it (the run keeps the one before).
  kept: bool = True

  @property
  def label(self) -> str:
    """The round's name in the viewer's menus ('B (round 0)', 'R1', ...): the same while
    it trains and once finished (the training step is shown in the status line), marked
    'R2 (discarded)' once an 'auto' decision discards it."""
    name = 'B (round 0)' if self.index == 0 else f'R{self.index}'
    return name if self.kept else f'{name} (discarded)'


def list_rounds(config, run_dir):
  """[RoundInfo] of rounds 0..config.num_rounds that have parameters to show: finished
  rounds and the first unfinished one if it has a checkpoint (with num_rounds 'auto':
  none after a discarded round)."""
  out, decided = [], []
  for r in range(auto_rounds.max_rounds(config) + 1):
    if r > 0 and auto_rounds.stops_after(config, decided):
      break  # 'auto': the previous round was discarded; no later round trains.
    rdir = rundir.round_dir(run_dir, r)
    if rundir.is_done(rdir):
      m = {'round': r}
      if auto_rounds.is_auto(config) and r > 0:
        try:
          m = report.read_json(rundir.result_path(rdir))['metrics']
        except (OSError, ValueError, KeyError):
          pass  # Shown without its decision.
      decided.append(m)
      d = m.get('auto') or {}
      out.append(RoundInfo(r, True, None, d.get('line'), d.get('take', True)))
      continue
    ckpts = rundir.list_checkpoints(rundir.round_checkpoints_dir(run_dir, r))
    if ckpts:
      out.append(RoundInfo(r, False, ckpts[-1][0]))
    break
  return out


def shown_round(rounds) -> int:
  """The position in `rounds` (list_rounds) of the model a viewer opens on: the newest
  round, or with num_rounds 'auto' the round the run keeps when the newest was discarded
  (list_rounds lists none after it)."""
  if not rounds:
    raise ValueError('no rounds to show')
  return len(rounds) - 2 if len(rounds) > 1 and not rounds[-1].kept else len(rounds) - 1


def load_params(config, run_dir, r):
  """(params, step) of round r: the finished round's params.msgpack (step None), else the
  latest training checkpoint's params (None, None when there is none yet).

  A checkpoint is a complete file or absent (rundir.save_checkpoint renames atomically),
  so reading while training writes is safe; one removed between listing and reading
  (training keeps the last two) is retried once, and a damaged one is passed over.
  """
  rdir = rundir.round_dir(run_dir, r)
  if rundir.is_done(rdir):
    return load_round_params(config, rdir, r), None
  template = params_template(config, r)
  ckpt_dir = rundir.round_checkpoints_dir(run_dir, r)
  for _ in range(2):
    for step, path in reversed(rundir.list_checkpoints(ckpt_dir)):
      try:
        with open(path, 'rb') as f:
          raw = serialization.msgpack_restore(f.read())
      except FileNotFoundError:
        break  # Removed by training meanwhile: list again.
      except Exception:  # pylint: disable=broad-except
        continue  # Damaged: the one before it (training sets it aside on resuming).
      return serialization.from_state_dict(template, raw['state']['params']), step
    else:
      return None, None
  return None, None


def latest_checkpoint_step(run_dir, r) -> Optional[int]:
  """Step of round r's newest training checkpoint (None: none)."""
  ckpts = rundir.list_checkpoints(rundir.round_checkpoints_dir(run_dir, r))
  return ckpts[-1][0] if ckpts else None


def round_pseudo_views(run_dir, r):
  """The PseudoViews round r trained on (None for B or before they are written)."""
  return load_pseudo_views(rundir.pseudo_views_dir(rundir.round_dir(run_dir, r)))


def last_log_record(run_dir, r) -> Optional[dict]:
  """The last record of round r's training log (step, loss, PSNR, ...), None if empty."""
  recs = rundir.read_jsonl(rundir.round_log_path(run_dir, r))
  return recs[-1] if recs else None


def open_run(run_dir):
  """(config, scene) of a run directory."""
  config = run_config(run_dir)
  return config, load_scene(config)
