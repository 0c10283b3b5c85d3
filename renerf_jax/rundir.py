"""The run directory: every path of a run, DONE markers, checkpoints and training logs.

Every file name of a run is spelled here and nowhere else; the package, experiments,
benchmarks and scripts derive paths with these functions:

  <run_dir>/   config.json, config.gin (config_json_path, config_gin_path), rounds.json/.md
               (rounds_table_paths), eval_rounds.json/.md (eval_rounds_paths),
               error_vs_time.png, shared_baseline.json (experiments), comparison.png
    control/     control_dir: round 1's seed-matched control, a run directory of its own
    round_<r>/   round_dir: params.msgpack, result.json (params_path, result_path),
                 point_cloud.ply (Gaussians), copied_from.json (experiments), DONE
      train/          train_dir: checkpoints/ (checkpoints_dir, checkpoint_path; a damaged
                      one is renamed *.damaged: checkpoint_io), log.jsonl
      eval/           eval_dir (eval_extra/: eval.py): metrics.json/.md, renders
      pseudo_views/   pseudo_views_dir (r >= 1): views.npz, views.json, timing.json, PNGs

Every write is atomic (report.atomic_open: temp file + fsync + rename); the temp files
a killed write leaves are removed by remove_stale_temp_files. In a multi-process run
(renerf_jax.distributed) only process 0 writes; every process reads the same files (a
file system all hosts share).
"""
import glob
import json
import os
import re
import time

import numpy as np
from flax import serialization

from renerf_jax import checkpoint_io, distributed, report

# ------------------------------------------------------------------- the run's layout


def config_json_path(run_dir):
  """The run's Config as JSON (written last when a run directory is made: it marks it)."""
  return os.path.join(run_dir, 'config.json')


def config_gin_path(run_dir):
  """The run's operative gin config (what view.py and the experiments load)."""
  return os.path.join(run_dir, 'config.gin')


def rounds_table_paths(run_dir):
  """(rounds.json, rounds.md): train.py's table of the rounds' metrics."""
  return os.path.join(run_dir, 'rounds.json'), os.path.join(run_dir, 'rounds.md')


def eval_rounds_paths(run_dir):
  """(eval_rounds.json, eval_rounds.md): eval.py's tables."""
  return os.path.join(run_dir, 'eval_rounds.json'), os.path.join(run_dir, 'eval_rounds.md')


def error_vs_time_path(run_dir):
  """eval.py's plot of the test PSNR against run time."""
  return os.path.join(run_dir, 'error_vs_time.png')


def shared_baseline_path(run_dir):
  """The experiments' note of the run whose round_0 was copied into run_dir."""
  return os.path.join(run_dir, 'shared_baseline.json')


def control_dir(run_dir):
  """The run directory of round 1's seed-matched control (Config.seed_control)."""
  return os.path.join(run_dir, 'control')


def comparison_path(run_dir):
  """train.py's picture of a test view: photo | B | control | R1."""
  return os.path.join(run_dir, 'comparison.png')


def round_dir(run_dir, r):
  """Round r's directory (r = 0: the baseline B)."""
  return os.path.join(run_dir, f'round_{r}')


def train_dir(rdir):
  """The training run's directory of the round in rdir (checkpoints, log)."""
  return os.path.join(rdir, 'train')


def eval_dir(rdir):
  """The test evaluation a round wrote when it finished."""
  return os.path.join(rdir, 'eval')


def eval_extra_dir(rdir):
  """eval.py's evaluation of a finished round with more metrics than it wrote."""
  return os.path.join(rdir, 'eval_extra')


def pseudo_views_dir(rdir):
  """The pseudo-views the round in rdir trained on (rounds >= 1)."""
  return os.path.join(rdir, 'pseudo_views')


def params_path(rdir):
  """A finished round's parameters (flax msgpack)."""
  return os.path.join(rdir, 'params.msgpack')


def result_path(rdir):
  """A finished round's metrics and training curve (result.json)."""
  return os.path.join(rdir, 'result.json')


def point_cloud_path(rdir):
  """The Gaussians' export of a finished round (the reference 3DGS .ply)."""
  return os.path.join(rdir, 'point_cloud.ply')


def copied_from_path(directory):
  """The note of where a copied round (or pseudo-view folder) came from."""
  return os.path.join(directory, 'copied_from.json')


def done_path(directory):
  """The DONE marker of a finished round (written last, atomically)."""
  return os.path.join(directory, 'DONE')


def checkpoints_dir(out_dir):
  """The checkpoint folder of a training run's directory (a round's train_dir)."""
  return os.path.join(out_dir, 'checkpoints')


def log_path(out_dir):
  """The JSONL log of a training run's directory (one record per logged step)."""
  return os.path.join(out_dir, 'log.jsonl')


def training_paths(out_dir):
  """(checkpoint folder, log.jsonl path) of a training run's directory."""
  return checkpoints_dir(out_dir), log_path(out_dir)


def round_log_path(run_dir, r):
  """Round r's training log."""
  return log_path(train_dir(round_dir(run_dir, r)))


def round_checkpoints_dir(run_dir, r):
  """Round r's training checkpoints."""
  return checkpoints_dir(train_dir(round_dir(run_dir, r)))


def metrics_path(ev_dir):
  """metrics.json of an evaluation folder (evaluation.Evaluation.summary())."""
  return os.path.join(ev_dir, 'metrics.json')


def metrics_md_path(ev_dir):
  """metrics.md of an evaluation folder (the per-image table)."""
  return os.path.join(ev_dir, 'metrics.md')


def render_path(ev_dir, name):
  """The render of the test view called `name` in metrics.json ('test_003')."""
  return os.path.join(ev_dir, f'{name}.png')


def depth_render_path(ev_dir, name):
  """The depth map of the test view called `name` in metrics.json ('test_003')."""
  return os.path.join(ev_dir, name.replace('test_', 'depth_', 1) + '.png')


def views_npz_path(pv_dir):
  """The pseudo-views' arrays (images, poses, masks, uncertainty)."""
  return os.path.join(pv_dir, 'views.npz')


def views_json_path(pv_dir):
  """The pseudo-views' metadata (the synthesis's `meta`)."""
  return os.path.join(pv_dir, 'views.json')


def timing_path(pv_dir):
  """The synthesis's timing, written last: it marks the pseudo-views as complete."""
  return os.path.join(pv_dir, 'timing.json')


def pseudo_view_png_path(pv_dir, kind, i):
  """PNG of pseudo-view i: kind 'view', 'mask', 'uncertainty' or 'panel'."""
  return os.path.join(pv_dir, f'{kind}_{i:03d}.png')


# --------------------------------------------------------- markers and atomic writes


def is_done(directory):
  """Whether the round in `directory` is finished (its DONE marker exists)."""
  return os.path.isfile(done_path(directory))


def mark_done(directory, info=None):
  """Writes the DONE marker (atomically) with `info` as its JSON."""
  report.write_json(done_path(directory), info or {})


def remove_stale_temp_files(directory):
  """Deletes the temp files that killed atomic writes left under `directory` (recursive).

  report.atomic_open writes '.<name>.<random>.tmp' next to its target and renames it over
  the target; a SIGKILL (or power loss) before the rename leaves the temp file (never
  read, as large as a checkpoint). Call this only on a directory no other process writes
  to (the unfinished round of this run). Returns the removed paths.
  """
  removed = []
  for root, _, files in os.walk(directory):
    for path in [os.path.join(root, n) for n in files if n[0] == '.' and n.endswith('.tmp')]:
      try:
        os.remove(path)
        removed.append(path)
      except FileNotFoundError:
        pass
  return removed


# ------------------------------------------------- checkpoints and training logs


def checkpoint_path(directory, step):
  """The checkpoint of `step` in a checkpoint folder."""
  return os.path.join(directory, f'checkpoint_{step:08d}.msgpack')


_CKPT = re.compile(r'checkpoint_(\d+)\.msgpack$')
_CKPT_GLOB = 'checkpoint_*.msgpack'


def save_checkpoint(directory, target, step, keep=2):
  """Writes a pytree atomically (temp file + fsync + rename) and keeps the last `keep`.

  A crash at any moment leaves either the previous checkpoints or the new one complete,
  never a truncated file under a checkpoint name.
  """
  os.makedirs(directory, exist_ok=True)
  data = serialization.to_bytes(target)
  with report.atomic_open(checkpoint_path(directory, step), 'wb') as f:
    f.write(data)
  for old in list_checkpoints(directory)[:-keep]:
    os.remove(old[1])


def list_checkpoints(directory):
  """[(step, path)] of complete checkpoints, sorted by step."""
  out = []
  for path in glob.glob(os.path.join(directory, _CKPT_GLOB)):
    m = _CKPT.search(path)
    if m:
      out.append((int(m.group(1)), path))
  return sorted(out)


def restore_checkpoint(directory, template):
  """The newest checkpoint that decodes, restored into `template`'s structure, or None
  (checkpoint_io.restore_newest: a damaged one is renamed *.damaged with a warning)."""
  return checkpoint_io.restore_newest(list_checkpoints(directory), template)


def resume_training(out_dir, state):
  """Where a training run in out_dir stands: its last checkpoint, or a fresh start.

  Args:
    out_dir: the run's directory (None: training in memory, nothing is read).
    state: the fresh train state (also the template of the checkpoint).

  Returns:
    (state, train_seconds, curve): restored from the last checkpoint with the log
    truncated to its step, or `state`, 0 and an emptied log; curve = the log's records
    with an 'eval_psnr'. (Only process 0 truncates or removes the log; the others read
    the records up to the restored step, the same ones.)
  """
  if out_dir is None:
    return state, 0., []
  ckpt_dir, log_path = training_paths(out_dir)
  restored = restore_checkpoint(ckpt_dir, {'state': state, 'meta': {
      'train_seconds': np.zeros((), np.float64)}})
  train_seconds, writer = 0., distributed.is_writer()
  if restored is None:
    if writer and os.path.exists(log_path):
      os.remove(log_path)
    max_step = 0
  else:
    state, train_seconds = restored['state'], float(restored['meta']['train_seconds'])
    max_step = int(state.step)
    if writer:
      truncate_jsonl(log_path, max_step)
  return state, train_seconds, [r for r in read_jsonl(log_path, max_step)
                                if 'eval_psnr' in r]


def save_training(out_dir, state, train_seconds):
  """An atomic checkpoint of a training run at state.step (None: nothing written)."""
  if out_dir is not None:
    save_checkpoint(training_paths(out_dir)[0], {'state': state, 'meta': {
        'train_seconds': np.asarray(train_seconds, np.float64)}}, int(state.step))


class TrainingLog:
  """The logging, evaluation and checkpoint edge of a training loop (both backbones).

  Training time counts the steps only: evaluation and writing happen between two
  clock reads. Each logged step appends one record to out_dir's log.jsonl (nothing is
  written when out_dir is None); evaluated records also join `curve`. With several
  processes every one evaluates (the renders are shared), process 0 writes, and all
  meet at each checkpoint (so a lost process stops the others there at the latest).
  """

  def __init__(self, config, out_dir, eval_fn, train_seconds, curve, time_offset, bar):
    self.config, self.out_dir, self.eval_fn = config, out_dir, eval_fn
    self.train_seconds, self.curve, self.time_offset, self.bar = (train_seconds, curve,
                                                                  time_offset, bar)
    self.t_last = time.perf_counter()

  def _eval_now(self, done):
    c = self.config
    return self.eval_fn is not None and c.eval_every > 0 and (
        done % c.eval_every == 0 or done == c.max_steps)

  def _ckpt_now(self, done):
    return done % self.config.checkpoint_every == 0 or done == self.config.max_steps

  def due(self, done):
    """Whether step `done` (1-based) is logged, evaluated or checkpointed."""
    return (done % self.config.print_every == 0 or done == self.config.max_steps
            or self._eval_now(done) or self._ckpt_now(done))

  def stop_clock(self):
    """Ends the timed stretch of steps (call it right after fetching the step's stats:
    what is read from the state after it is not training time)."""
    if self.t_last is not None:
      self.train_seconds += time.perf_counter() - self.t_last
      self.t_last = None

  def record(self, done, state, fields, postfix=None):
    """Logs step `done`: fields (after step, train_seconds, time), the test PSNR where
    due, a progress-bar postfix; checkpoints state where due; restarts the clock.
    Returns the record."""
    self.stop_clock()
    rec = {'step': done, 'train_seconds': self.train_seconds,
           'time': self.time_offset + self.train_seconds}
    rec.update(fields)
    eval_now = self._eval_now(done)
    if eval_now:
      rec['eval_psnr'] = float(self.eval_fn(state.params))
      self.curve.append(rec)
    self.bar.set_postfix(loss=f"{rec['loss']:.4f}", psnr=f"{rec['psnr']:.2f}",
                         **(postfix or {}),
                         **({'test': f"{rec['eval_psnr']:.2f}"} if eval_now else {}))
    writer = distributed.is_writer()
    if self.out_dir is not None and writer:
      append_jsonl(training_paths(self.out_dir)[1], rec)
    if self._ckpt_now(done):
      if writer:
        save_training(self.out_dir, state, self.train_seconds)
      distributed.sync(f'checkpoint {done}')
    self.t_last = time.perf_counter()
    return rec


def append_jsonl(path, record):
  """Appends one JSON line (flushed + fsynced)."""
  os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
  with open(path, 'a') as f:
    f.write(json.dumps(report.to_jsonable(record)) + '\n')
    f.flush()
    os.fsync(f.fileno())


def read_jsonl(path, max_step=None):
  """Records of a JSONL log (skipping a torn last line); only step <= max_step if given."""
  if not os.path.isfile(path):
    return []
  out = []
  with open(path) as f:
    for line in f:
      try:
        rec = json.loads(line)
      except json.JSONDecodeError:
        continue
      if max_step is None or rec.get('step', 0) <= max_step:
        out.append(rec)
  return out


def truncate_jsonl(path, max_step):
  """Drops log records after max_step (they belong to steps lost by a crash)."""
  if os.path.isfile(path):
    recs = read_jsonl(path, max_step)
    with report.atomic_open(path, 'w') as f:
      for rec in recs:
        f.write(json.dumps(rec) + '\n')
