"""Re-Nerfing rounds in a run directory: the edge of the pure `renerf.round_step`, and the
files a round writes of its results (test evaluations, pseudo-views, parameters).

  runs/<name>/round_<r>/                                 (every path: renerf_jax.rundir)
    pseudo_views/   views.npz (+ PNGs), views.json, timing.json   (r >= 1)
    train/          checkpoints/, log.jsonl                        (resume mid-round)
    eval/           test renders, metrics.json, metrics.md
    params.msgpack, result.json, DONE
  runs/<name>/control/round_0/   the seed-matched control (Config.seed_control), alike

A round marked DONE is loaded, never rewritten; an interrupted round resumes from what it
left: its pseudo-views (if saved) and its last atomic checkpoint. Every write is atomic
(temp file + rename), and temp files of a killed write are removed when the round resumes.
In a multi-process run (renerf_jax.distributed) every process computes each round and
reads what is on disk; process 0 alone writes. Evaluation, pseudo-view synthesis and
uncertainty return arrays and dicts; they are written here (and by eval.py) only.
"""
import os
import sys
from typing import Callable, Optional, Sequence

import numpy as np
from flax import serialization

from renerf_jax import (auto_rounds, backbones, checkpoint_io, distributed, figures,
                        pseudo_views, renerf, report, rundir)
from renerf_jax.errors import RunDirError
from renerf_jax.evaluation import Evaluation
from renerf_jax.pseudo_views import PseudoViews

# ------------------------------------------------------------ the files of a round


def save_evaluation(out_dir, ev: Evaluation, save_png=True):
  """Writes metrics.json, metrics.md and, per test view, test_XXX.png and depth_XXX.png.

  Args:
    out_dir: the folder (created). ev: evaluation.Evaluation.
    save_png: also write the renders.
  """
  os.makedirs(out_dir, exist_ok=True)
  if save_png:
    for m, image, distance in zip(ev.per_image, ev.images, ev.distances):
      figures.save_image_png(rundir.render_path(out_dir, m['name']), image)
      figures.save_image_png(rundir.depth_render_path(out_dir, m['name']),
                            figures.colorize(distance))
  report.write_json(rundir.metrics_path(out_dir), ev.summary())
  report.write_markdown(rundir.metrics_md_path(out_dir), report.markdown_table(
      report.per_image_table(ev.per_image), list(ev.columns)) + '\n')


def save_pseudo_views(directory, pv: PseudoViews, meta, save_png=True):
  """Writes views.npz (atomically), views.json and, per view, rgb / mask / uncertainty PNGs.

  Args:
    directory: the folder (created). pv: the PseudoViews. meta: their metadata (JSON).
    save_png: also write the PNGs.
  """
  os.makedirs(directory, exist_ok=True)
  arrays = {k: np.asarray(getattr(pv, k)) for k in ('images', 'poses', 'masks',
                                                     'uncertainty')}
  with report.atomic_open(rundir.views_npz_path(directory), 'wb') as f:
    np.savez_compressed(f, **arrays)
  report.write_json(rundir.views_json_path(directory), meta)
  if save_png:
    png = lambda kind, i: rundir.pseudo_view_png_path(directory, kind, i)
    for i in range(arrays['images'].shape[0]):
      figures.save_image_png(png('view', i), arrays['images'][i])
      figures.save_image_png(png('mask', i), arrays['masks'][i])
      if np.any(arrays['uncertainty'][i]):
        heat = pseudo_views.uncertainty_heatmap(arrays['uncertainty'][i],
                                                arrays['uncertainty'])
        figures.save_image_png(png('uncertainty', i), heat)
        figures.save_image_png(png('panel', i),
                              pseudo_views.side_by_side(arrays['images'][i], heat,
                                                        arrays['masks'][i]))


def load_pseudo_views(directory) -> Optional[PseudoViews]:
  """The PseudoViews in directory/views.npz (None: not written yet)."""
  path = rundir.views_npz_path(directory)
  if not os.path.isfile(path):
    return None
  with np.load(path) as z:
    return PseudoViews(**{k: z[k] for k in ('images', 'poses', 'masks', 'uncertainty')})


def params_template(config, r):
  """The parameter pytree of round r's backbone (its structure for deserialising)."""
  return backbones.get_backbone(config).init_params(renerf.round_config(config, r))


def load_round_params(config, rdir, r):
  """The parameters of the finished round r in rdir (its params.msgpack).

  Args:
    config: the run's Config. rdir: the round's directory. r: its index.

  Returns:
    The parameter pytree of round r's backbone.
  """
  return checkpoint_io.read_params(rundir.params_path(rdir), params_template(config, r),
                                  f'round {r} in {rdir}')


# ------------------------------------------------------------------ the round driver


def stored_synthesis(out_dir, synthesize_fn: Optional[Callable] = None) -> Callable:
  """synthesize_fn (default: the Config's Backbone.synthesize) with its result kept in
  out_dir: a resumed round reuses it.

  Returns:
    A function like Backbone.synthesize.
  """
  def fn(config, scene, params, show_progress=False):
    pv = load_pseudo_views(out_dir)
    info_path = rundir.timing_path(out_dir)
    if pv is not None and os.path.isfile(info_path):
      return pv, report.read_json(info_path), report.read_json(
          rundir.views_json_path(out_dir))
    fn_ = synthesize_fn or backbones.get_backbone(config).synthesize
    pv, timing, meta = fn_(config, scene, params, show_progress)
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
  with report.atomic_open(rundir.params_path(rdir), 'wb') as f:
    f.write(serialization.to_bytes(state.params))
  if export is not None:
    export(state.params, rdir)
  report.write_json(rundir.result_path(rdir), {'metrics': state.metrics[-1],
                                               'curve': state.curves[-1]})
  rundir.mark_done(rdir, {'round': state.round_index})


def load_round(config, rdir, state: renerf.RoundState) -> renerf.RoundState:
  """The RoundState after the finished round in rdir (read-only)."""
  r = state.round_index + 1
  params = load_round_params(config, rdir, r)
  try:
    result = report.read_json(rundir.result_path(rdir))
  except (OSError, ValueError) as e:
    raise RunDirError(f'{rundir.result_path(rdir)} is damaged ({type(e).__name__}): round '
                      f'{r} is marked finished with it; move that round directory aside '
                      'to train the round again') from None
  return renerf.RoundState(
      params=params, pseudo=load_pseudo_views(rundir.pseudo_views_dir(rdir)),
      round_index=r, metrics=state.metrics + (result['metrics'],),
      curves=state.curves + (result['curve'],),
      seconds=float(result['metrics']['cumulative_seconds']))


def run_rounds(config, scene, run_dir, show_progress=True,
               synthesize_fn: Optional[Callable] = None,
               label: Optional[str] = None) -> renerf.RoundState:
  """Baseline plus config.num_rounds rounds in run_dir, resuming what is there (with
  num_rounds 'auto': until a round is discarded, renerf_jax/auto_rounds.py).

  Args:
    config, scene: Config and Scene. run_dir: the run directory.
    show_progress: draw progress bars.
    synthesize_fn: the pseudo-view synthesis (None: the backbone's; experiments share
      work between table variants through it).
    label: the progress bars' label (None: 'baseline', 'round r').

  Returns:
    RoundState after the last round.
  """
  renerf.check_rounds_config(config, scene)
  backbone = backbones.get_backbone(config)
  state = renerf.initial_state()
  distributed.sync('run_rounds')  # Every process sees the same directory from here on.
  for r in range(auto_rounds.max_rounds(config) + 1):
    if r > 0 and auto_rounds.stops_after(config, state.metrics):
      break  # 'auto': the last round was discarded.
    rdir = rundir.round_dir(run_dir, r)
    if rundir.is_done(rdir):
      state = load_round(config, rdir, state)
      continue
    if distributed.is_writer():
      rundir.remove_stale_temp_files(rdir)  # Left by a run killed mid-write.
    train_dir, eval_dir = rundir.train_dir(rdir), rundir.eval_dir(rdir)
    state = renerf.round_step(
        config, scene, state, show_progress,
        synthesize_fn=stored_synthesis(rundir.pseudo_views_dir(rdir), synthesize_fn),
        train_fn=lambda cfg, sc, pseudo, **kw: backbone.train(
            cfg, sc, train_dir, pseudo, **dict(kw, desc=label or kw['desc'])),
        evaluate_fn=stored_evaluation(
            eval_dir, lambda cfg, sc, params: backbone.evaluate(cfg, sc, params,
                                                                show_progress=False)))
    save_round(rdir, state, backbone.export)
    if show_progress and state.metrics[-1].get('auto'):
      print(state.metrics[-1]['auto']['line'], file=sys.stderr)  # As it is decided.
  return state


def control_run_dir(config, run_dir):
  """The run directory whose round_0 is round 1's seed-matched control: with
  Config.d_seed = 'same' the control is B itself (the same Config), so the run's own;
  else rundir.control_dir(run_dir)."""
  return run_dir if config.d_seed == 'same' else rundir.control_dir(run_dir)


def run_control(config, scene, run_dir, state: renerf.RoundState,
                show_progress=True) -> dict:
  """The seed-matched control of round 1 (renerf.control_config) in
  control_run_dir(config, run_dir), resuming what is there.

  Args:
    config, scene: the run's Config and Scene. run_dir: the run directory.
    state: the run's RoundState after its rounds.
    show_progress: draw progress bars.

  Returns:
    The control's test metrics (B's, not trained again, where the control is B).
  """
  control_dir = control_run_dir(config, run_dir)
  if control_dir == run_dir:
    return state.metrics[0]
  return run_rounds(renerf.control_config(config), scene, control_dir, show_progress,
                    label='control').metrics[0]


def hardest_test_view(scene) -> int:
  """The position in scene.test_idx of the test camera farthest from every training
  camera (camera centres)."""
  centres = scene.poses[:, :3, 3]
  gaps = np.linalg.norm(centres[scene.test_idx, None] - centres[None, scene.train_idx],
                        axis=-1).min(1)
  return int(np.argmax(gaps))


def save_comparison(run_dir, scene, rows: Sequence):
  """Writes rundir.comparison_path(run_dir): the photo of the test view farthest from
  the training cameras beside the renders of `rows`, (title, round directory) pairs of
  finished rounds, each titled with its PSNR on that view (read from the rounds' eval/
  files, process 0 only)."""
  if not distributed.is_writer():
    return
  import imageio.v3 as iio  # pylint: disable=g-import-not-at-top
  k = hardest_test_view(scene)
  images = [scene.images[scene.test_idx[k]]]
  titles = [f'photo, test view {k}']
  for title, rdir in rows:
    ev_dir = rundir.eval_dir(rdir)
    m = report.read_json(rundir.metrics_path(ev_dir))['per_image'][k]
    images.append(iio.imread(rundir.render_path(ev_dir, m['name'])))
    titles.append(f"{title}: {m['psnr']:.2f} dB")
  figures.save_panels(rundir.comparison_path(run_dir), images, titles)
