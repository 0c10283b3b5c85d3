"""Re-Nerfing rounds in a run directory: the edge of the pure `renerf.round_step`.

  runs/<name>/round_<r>/
    pseudo_views/   views.npz (+ PNGs), views.json, timing.json   (r >= 1)
    train/          checkpoints/, log.jsonl                        (resume mid-round)
    eval/           test renders, metrics.json, metrics.md
    params.msgpack, result.json, DONE

A round marked DONE is loaded, never rewritten; an interrupted round resumes from what it
left: its pseudo-views (if saved) and its last atomic checkpoint. Every write is atomic
(temp file + rename), and temp files of a killed write are removed when the round resumes.
In a multi-process run (renerf_jax.distributed) every process computes each round and
reads what is on disk; process 0 alone writes.
"""
import os
from typing import Callable, Optional

from flax import serialization

from renerf_jax import backbones, distributed, renerf, report, rundir
from renerf_jax.outputs import load_pseudo_views, save_evaluation, save_pseudo_views


def round_dir(run_dir, r):
  return os.path.join(run_dir, f'round_{r}')


def stored_synthesis(out_dir, synthesize_fn: Callable = renerf.synthesize) -> Callable:
  """synthesize_fn with its result kept in out_dir: a resumed round reuses it.

  Returns:
    A function like renerf.synthesize.
  """
  def fn(config, scene, params, show_progress=False):
    pv = load_pseudo_views(out_dir)
    info_path = os.path.join(out_dir, 'timing.json')
    if pv is not None and os.path.isfile(info_path):
      return pv, report.read_json(info_path), report.read_json(
          os.path.join(out_dir, 'views.json'))
    pv, timing, meta = synthesize_fn(config, scene, params, show_progress)
    if distributed.is_writer():
      save_pseudo_views(out_dir, pv, meta)
      report.write_json(info_path, timing)  # Last: it marks the pseudo-views as complete.
    return pv, timing, meta
  return fn


def stored_evaluation(out_dir, evaluate_fn: Callable) -> Callable:
  """evaluate_fn with its Evaluation written to out_dir (metrics.json/.md, renders).

  Returns:
    A function like renerf.round_step's evaluate_fn.
  """
  def fn(config, scene, params):
    ev = evaluate_fn(config, scene, params)
    if distributed.is_writer():
      save_evaluation(out_dir, ev)
    return ev
  return fn


def save_round(rdir, state: renerf.RoundState, export=None):
  """Writes the round's params, the backbone's exports (export(params, rdir), e.g. the
  Gaussians' .ply) and result.json, then marks it DONE (process 0 only)."""
  if not distributed.is_writer():
    return
  with report.atomic_open(os.path.join(rdir, 'params.msgpack'), 'wb') as f:
    f.write(serialization.to_bytes(state.params))
  if export is not None:
    export(state.params, rdir)
  report.write_json(os.path.join(rdir, 'result.json'), {'metrics': state.metrics[-1],
                                                        'curve': state.curves[-1]})
  rundir.mark_done(rdir, {'round': state.round_index})


def params_template(config, r):
  """The parameter pytree of round r's backbone (its structure for deserialising)."""
  return backbones.get_backbone(config).init_params(renerf.round_config(config, r))


def load_round(config, rdir, state: renerf.RoundState) -> renerf.RoundState:
  """The RoundState after the finished round in rdir (read-only)."""
  r = state.round_index + 1
  template = params_template(config, r)
  with open(os.path.join(rdir, 'params.msgpack'), 'rb') as f:
    params = serialization.from_bytes(template, f.read())
  result = report.read_json(os.path.join(rdir, 'result.json'))
  return renerf.RoundState(
      params=params, pseudo=load_pseudo_views(os.path.join(rdir, 'pseudo_views')),
      round_index=r, metrics=state.metrics + (result['metrics'],),
      curves=state.curves + (result['curve'],),
      seconds=float(result['metrics']['cumulative_seconds']))


def run_rounds(config, scene, run_dir, show_progress=True,
               synthesize_fn: Optional[Callable] = None) -> renerf.RoundState:
  """Baseline plus config.num_rounds rounds in run_dir, resuming what is there.

  Args:
    config, scene: Config and Scene. run_dir: the run directory.
    show_progress: draw progress bars.
    synthesize_fn: the pseudo-view synthesis (None: the backbone's; experiments share
      work between table variants through it).

  Returns:
    RoundState after the last round.
  """
  renerf.check_rounds_config(config, scene)
  backbone = backbones.get_backbone(config)
  state = renerf.initial_state()
  distributed.sync('run_rounds')  # Every process sees the same directory from here on.
  for r in range(config.num_rounds + 1):
    rdir = round_dir(run_dir, r)
    if rundir.is_done(rdir):
      state = load_round(config, rdir, state)
      continue
    if distributed.is_writer():
      rundir.remove_stale_temp_files(rdir)  # Left by a run killed mid-write.
    train_dir, eval_dir = os.path.join(rdir, 'train'), os.path.join(rdir, 'eval')
    state = renerf.round_step(
        config, scene, state, show_progress,
        synthesize_fn=stored_synthesis(os.path.join(rdir, 'pseudo_views'),
                                       synthesize_fn or backbone.synthesize),
        train_fn=lambda cfg, sc, pseudo, **kw: backbone.train(cfg, sc, train_dir, pseudo,
                                                              **kw),
        evaluate_fn=stored_evaluation(
            eval_dir, lambda cfg, sc, params: backbone.evaluate(cfg, sc, params,
                                                                show_progress=False)))
    save_round(rdir, state, backbone.export)
  return state
