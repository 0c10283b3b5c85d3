"""One fit loop for every backbone: resume, per-step keys, pseudo-view window, log.

`fit` runs config.max_steps optimisation steps of any train state with a `step` field
(NeRF: training.TrainState; Gaussians: gaussians.training.GaussianTrainState). The
backbone gives how to make a fresh state, its jitted step, what to log and an optional
hook between steps (the Gaussians' densification strategy); the loop owns everything
both share:

  * the keys: (k_init, base_key) = init_and_step_keys(config); the fresh state is made
    from k_init (and is the template of the checkpoint), step s draws from
    fold_in(base_key, s) whether or not the run was resumed;
  * resuming from out_dir's last checkpoint (rundir.resume_training), so a resumed run
    repeats the uninterrupted one's computation bit for bit;
  * the pseudo-view window: the step is told pseudo_on for window[0] <= s < window[1];
  * the progress bar and rundir.TrainingLog's log / evaluation / checkpoint cadence
    (training time counts the steps only).
"""
import dataclasses
from typing import Any, Callable, Optional

import jax

from renerf_jax import rundir
from renerf_jax.config_checks import pseudo_steps
from renerf_jax.progress import progress_bar


@dataclasses.dataclass
class TrainResult:
  state: Any  # The backbone's train state after config.max_steps steps.
  train_seconds: float  # Wall time spent in optimisation (evaluation excluded).
  curve: list  # [{'step', 'train_seconds', 'eval_psnr'}] cheap test evaluations.


def init_and_step_keys(config):
  """(key of the parameters' initialisation, base key of the per-step draws).

  Both are split from PRNGKey(Config.seed); with Config.init_seed >= 0 the initialisation
  key is split from PRNGKey(init_seed) instead (init_seed == seed gives the same keys).
  """
  k_init, base_key = jax.random.split(jax.random.PRNGKey(config.seed))
  if config.init_seed >= 0:
    k_init = jax.random.split(jax.random.PRNGKey(config.init_seed))[0]
  return k_init, base_key


def pseudo_window(config):
  """[start, end) steps in which pseudo-views are drawn (Config.pseudo_schedule)."""
  k = min(pseudo_steps(config), config.max_steps)
  return {'early': (0, k), 'all': (0, config.max_steps),
          'late': (config.max_steps - k, config.max_steps)}[config.pseudo_schedule]


def fit(config, out_dir, init_state: Callable, step_fn: Callable, log_fields: Callable,
        window=(0, 0), place: Optional[Callable] = None,
        after_step: Optional[Callable] = None, eval_fn=None, time_offset: float = 0.,
        desc: str = 'train', show_progress: bool = True) -> TrainResult:
  """Trains a fresh state (or resumes the one in out_dir) for config.max_steps steps.

  Args:
    config: Config (seed, max_steps, print_every, eval_every, checkpoint_every).
    out_dir: directory of checkpoints and log.jsonl (resumed when checkpoints exist);
      None trains in memory (no checkpoints, no log).
    init_state: k_init -> a fresh train state (also the checkpoint's template).
    step_fn: (state, pseudo_on, key) -> (state, stats): one optimisation step; key is
      fold_in(base_key, step), pseudo_on a Python bool.
    log_fields: (state, stats fetched to the host) -> (fields of the log record,
      progress-bar postfix dict or None), at the steps TrainingLog logs.
    window: (start, end): pseudo_on for start <= step < end only ((0, 0): never).
    place: optional state -> state, applied once to the fresh or restored state (device
      placement, own copies the steps may donate).
    after_step: optional (state, done, key) -> state, run after step `done` (1-based)
      and before it is logged, with that step's key (the Gaussians' densification).
    eval_fn: optional params -> test PSNR (cheap), called every config.eval_every steps.
    time_offset: seconds added to logged times (cumulative time over rounds).
    desc: progress-bar label. show_progress: draw the bar.

  Returns:
    TrainResult.
  """
  k_init, base_key = init_and_step_keys(config)
  state, train_seconds, curve = rundir.resume_training(out_dir, init_state(k_init))
  if place is not None:
    state = place(state)
  start = int(state.step)
  bar = progress_bar(total=config.max_steps, initial=start, desc=desc,
                     disable=not show_progress)
  log = rundir.TrainingLog(config, out_dir, eval_fn, train_seconds, curve, time_offset, bar)

  for step in range(start, config.max_steps):
    pseudo_on = window[0] <= step < window[1]
    key = jax.random.fold_in(base_key, step)
    state, stats = step_fn(state, pseudo_on, key)
    done = step + 1
    if after_step is not None:
      state = after_step(state, done, key)
    bar.update(1)
    if log.due(done):
      stats = jax.device_get(stats)
      log.stop_clock()
      fields, postfix = log_fields(state, stats)
      log.record(done, state, fields, postfix=postfix)
  bar.close()
  return TrainResult(state=state, train_seconds=log.train_seconds, curve=curve)
