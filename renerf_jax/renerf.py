"""Re-Nerfing rounds on immutable state: RoundState -> RoundState (the paper's Figure 2).

  round 0: train B on the real views                         (the baseline)
  round r: render pseudo-views with B at interpolated poses
           [Laplace uncertainty of B -> masks]               (only with Config.use_masks)
           train D from scratch on real + masked pseudo-views (pseudo rays until step K)
           D becomes the next round's B

`round_step` is a pure function of (config, scene, state): it reads and writes no file
and keeps no process-wide cache. It works on any model family through
`backbones.Backbone` (`Config.backbone`): train on real + pseudo-views, render,
evaluate. Persistence and resume (round_<r>/ directories, DONE markers, checkpoints;
their paths in `rundir.py`) live at the edge, in `round_driver.py`, which hands the step
its synthesis, training and evaluation functions bound to a round directory.
"""
import dataclasses
from typing import Any, Callable, Optional, Tuple

import flax
import numpy as np

from renerf_jax import auto_rounds, backbones, fit, metrics, report
from renerf_jax.errors import ConfigError, DataError
from renerf_jax.pseudo_views import PseudoViews, pseudo_view_poses


@flax.struct.dataclass
class RoundState:
  """Everything one round hands to the next (a pytree; only `params`, `pseudo` are leaves)."""
  params: Any  # Field parameters of the current model (B for the next round); None at first.
  pseudo: Optional[PseudoViews]  # Pseudo-views the current model was trained with.
  round_index: int = flax.struct.field(pytree_node=False, default=-1)  # -1: none yet.
  metrics: Tuple[dict, ...] = flax.struct.field(pytree_node=False, default=())
  curves: Tuple[list, ...] = flax.struct.field(pytree_node=False, default=())
  seconds: float = flax.struct.field(pytree_node=False, default=0.)  # Cumulative wall
  # seconds of every round so far (training + synthesis + masks).


def initial_state() -> RoundState:
  """The state before the baseline: no model, no pseudo-views, no metrics."""
  return RoundState(params=None, pseudo=None)


def round_config(config, r):
  """The Config of round r's training (D starts from scratch; Config.d_seed).

  'offset': seed + 1000 r (and init_seed + 1000 r when set) for round r >= 1;
  'same_init': those draws with B's initialisation (init_seed = B's); 'same': B's Config.
  """
  if r == 0 or config.d_seed == 'same':
    return config
  b_init = config.init_seed if config.init_seed >= 0 else config.seed
  init = b_init if config.d_seed == 'same_init' else (
      config.init_seed + 1000 * r if config.init_seed >= 0 else -1)
  return dataclasses.replace(config, seed=config.seed + 1000 * r, init_seed=init)


def control_config(config, steps=None):
  """The seed-matched control of round 1 (issue 49): B's training (no rounds, no
  pseudo-views) with D's Config (round_config(config, 1): D's seed and initialisation)
  for `steps` steps (None: B's). It differs from R1 in the pseudo-views alone."""
  return dataclasses.replace(round_config(config, 1), num_rounds=0, seed_control=False,
                             max_steps=config.max_steps if steps is None else steps)


def validation_scene(scene):
  """The scene with its validation views in the place of the test views (evaluation
  renders and scores Scene.test_idx)."""
  return dataclasses.replace(scene, test_idx=np.asarray(scene.val_idx),
                             val_idx=np.zeros(0, np.int64))


def validation_metrics(config, scene, params, r) -> dict:
  """Round r's model (params) at the scene's validation views: val_<metric> means and
  val_psnr_views (one PSNR per view, for Config.num_rounds = 'auto')."""
  val = backbones.get_backbone(config).evaluate(round_config(config, r),
                                                validation_scene(scene), params,
                                                show_progress=False)
  return dict({f'val_{k}': v for k, v in val.mean.items()},
              val_psnr_views=[float(v['psnr']) for v in val.per_image])


def round_step(config, scene, state: RoundState, show_progress: bool = False,
               synthesize_fn: Optional[Callable] = None,
               train_fn: Optional[Callable] = None,
               evaluate_fn: Optional[Callable] = None) -> RoundState:
  """The next round: B's params -> pseudo-views [-> masks] -> D's params and metrics.

  The model family is `backbones.get_backbone(config)`; the three functions below
  default to its in-memory ones (no file written).

  Args:
    config: Config. scene: Scene. state: the state after the previous round.
    show_progress: draw progress bars.
    synthesize_fn: (config, scene, params, show_progress) -> (PseudoViews, timing, meta).
    train_fn: (config, scene, pseudo: PseudoViews or None, **kwargs) ->
      fit.TrainResult (kwargs: window, init_params, eval_fn, time_offset, desc,
      show_progress, as nerf.training.train_model takes them).
    evaluate_fn: (config, scene, params) -> evaluation.Evaluation.
    round_driver.py binds them to a round directory.

  Returns:
    RoundState of round state.round_index + 1.
  """
  backbone = backbones.get_backbone(config)
  synthesize_fn = synthesize_fn or backbone.synthesize
  train_fn = train_fn or (lambda cfg, sc, pseudo, **kw: backbone.train(cfg, sc, None,
                                                                        pseudo, **kw))
  evaluate_fn = evaluate_fn or (lambda cfg, sc, params: backbone.evaluate(
      cfg, sc, params, show_progress=False))
  r = state.round_index + 1
  cfg = round_config(config, r)
  pseudo, synth_seconds = None, 0.
  if r > 0:
    pseudo, timing, _ = synthesize_fn(config, scene, state.params, show_progress)
    synth_seconds = timing['seconds']
  start = state.seconds + synth_seconds
  result = train_fn(
      cfg, scene, pseudo,
      window=fit.pseudo_window(cfg) if pseudo is not None else (0, 0),
      init_params=state.params if r > 0 and config.renerf_init == 'continue' else None,
      eval_fn=backbone.cheap_eval_fn(cfg, scene), time_offset=start,
      desc=f'round {r}' if r else 'baseline', show_progress=show_progress)
  seconds = start + result.train_seconds
  ev = evaluate_fn(cfg, scene, result.state.params)
  metrics = dict(ev.mean, round=r, round_seconds=synth_seconds + result.train_seconds,
                 cumulative_seconds=seconds, nan_skips=int(result.state.nan_skips))
  if len(scene.val_idx):  # The validation views' means and per-view PSNRs (no renders).
    metrics.update(validation_metrics(config, scene, result.state.params, r))
  if r > 0 and auto_rounds.is_auto(config):  # Keep D, or B? (validation views only)
    prev = state.metrics[-1]
    if 'val_psnr_views' not in prev:  # B from before 'auto' (resumed, copied): render it.
      prev = dict(prev, **validation_metrics(config, scene, state.params, r - 1))
    metrics['auto'] = auto_rounds.round_decision(config, prev, metrics)
  return RoundState(params=result.state.params, pseudo=pseudo, round_index=r,
                    metrics=state.metrics + (metrics,),
                    curves=state.curves + (result.curve,), seconds=seconds)


def check_rounds_config(config, scene):
  """Raises ConfigError now for pseudo-view settings that round 1 could not use.

  Without this, a single training view with interpolated pseudo-views (no neighbouring
  pair to interpolate), a bad Config.interp_factors or Config.pseudo_targets, or the
  oracle (Config.pseudo_source='photo') with masks, would only fail after the baseline
  had trained. With num_rounds = 0 only LPIPS-alex against the image size is checked
  (the baseline alone needs no pseudo-views), and that a Gaussian SfM start has points.
  """
  metrics.check_lpips_size(config.lpips_nets, scene.height, scene.width)
  if config.backbone == 'gaussians' and config.gs_init == 'sfm' and scene.points is None:
    raise DataError(f"scene {scene.name!r}: Config.gs_init='sfm' needs SfM points (a "
                    "COLMAP model's points3D or a transforms.json ply_file_path)")
  auto_rounds.check_auto(config, scene)
  if auto_rounds.max_rounds(config) > 0:
    pseudo_view_poses(config, scene)
    if config.seed_control and config.renerf_init != 'reset':
      raise ConfigError(f'Config.seed_control trains D from scratch at D\'s seed; with '
                        f'Config.renerf_init={config.renerf_init!r} D starts from B, so that '
                        'control would differ from R1 in more than the pseudo-views')
    if (config.backbone != 'nerf' and config.use_masks
        and config.mask_signal != 'one_minus_acc'):
      raise ConfigError(f'Config.mask_signal={config.mask_signal!r} needs the NeRF '
                        f'backbone; Config.backbone={config.backbone!r} masks with '
                        "'one_minus_acc' only")


def run_rounds(config, scene, show_progress: bool = False) -> RoundState:
  """Baseline plus config.num_rounds rounds in memory (round_driver.run_rounds: on disk);
  with num_rounds 'auto', until a round is discarded (auto_rounds.stops_after): the state
  then holds the discarded round's params, auto_rounds.selected_round the kept one's."""
  check_rounds_config(config, scene)
  state = round_step(config, scene, initial_state(), show_progress)
  while not auto_rounds.stops_after(config, state.metrics):
    state = round_step(config, scene, state, show_progress)
  return state


CONTROL_NAME = "control (D's seed, no pseudo-views)"


def rounds_table(metrics, control=None):
  """Markdown table of per-round test metrics in the shape of the paper's 3-view table
  (the seed-matched control's metrics, when given, as a row after the baseline), and the
  validation views' where the scene has them."""
  rows = [dict(m, name='baseline' if m['round'] == 0 else f"Re-Nerfing R{m['round']}")
          for m in metrics]
  if control is not None:
    rows.insert(1, dict(control, name=CONTROL_NAME))
  cols = [('name', 'round'), ('psnr', 'PSNR'), ('ssim', 'SSIM'),
          ('lpips_alex', 'LPIPS-alex'), ('lpips_vgg', 'LPIPS-vgg'), ('avg_err', 'avg err'),
          ('cumulative_seconds', 'cum. time [s]'), ('val_psnr', 'val PSNR'),
          ('val_ssim', 'val SSIM'), ('val_lpips_alex', 'val LPIPS-alex')]
  return report.markdown_table(rows, [c for c in cols if c[0] == 'name' or
                                      any(c[0] in m for m in metrics)])


def _delta(m, ref, label):
  """'label: PSNR +x.xx, SSIM +x.xxx, LPIPS-alex +x.xxx (...)': m minus ref."""
  parts = [f"{name} {m[k] - ref[k]:+.{d}f}" for k, name, d in
           (('psnr', 'PSNR', 2), ('ssim', 'SSIM', 3), ('lpips_alex', 'LPIPS-alex', 3))
           if k in m and k in ref]
  return (f'{label}: ' + ', '.join(parts) + ' (PSNR in dB; higher PSNR / SSIM and lower '
          'LPIPS are better)')


def deltas_vs_baseline(metrics, control=None):
  """One line per round r >= 1: its metrics minus the baseline's, whatever the sign.

  With the seed-matched control's metrics (control_config), first R1 - control (the
  verdict: the two differ in the pseudo-views alone), then the rounds - baseline, then
  control - baseline (what D's seed alone moves), and one line saying what they mean.
  """
  base, lines = metrics[0], []
  if control is not None and len(metrics) > 1:
    lines.append(_delta(metrics[1], control, 'R1 - control'))
  for m in metrics[1:]:
    lines.append(_delta(m, base, f"R{m['round']} - baseline"))
  if control is not None:
    lines += [_delta(control, base, 'control - baseline'),
              "R1 - control is Re-Nerfing's effect (same seed and steps, with against "
              'without pseudo-views); control - baseline is what a change of seed alone '
              'moves. One seed decides nothing: compare the spread over seeds.']
  return lines
