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
import time
from typing import Any, Callable, Optional, Tuple

import flax
import jax.numpy as jnp
import numpy as np

from renerf_jax import contraction, fit, pseudo_views, random_poses, report, training
from renerf_jax.datasets import camera_rays, ray_pool
from renerf_jax.errors import ConfigError
from renerf_jax.pseudo_views import PseudoViews, pseudo_view_poses, render_pseudo_views


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


def regularizer_poses(config, scene):
  """Random unobserved poses for depth TV ([n_random_poses, 3, 4]), or None when off."""
  if config.depth_tv_loss_mult <= 0:
    return None
  rng = np.random.default_rng(config.seed)
  train = np.asarray(scene.poses[scene.train_idx], np.float64)
  poses = random_poses.random_unobserved_poses(train, config.n_random_poses, rng,
                                               scene.forward_facing, scene.focus_depth,
                                               config.random_pose_spread)
  return jnp.asarray(poses, jnp.float32)


def make_pools(config, scene, pseudo: Optional[PseudoViews]):
  """The NeRF backbone's training pools: real views, pseudo-views (if any: 'mixed' with
  the real rays for Config.pseudo_mix='pixels', 'pseudo' alone for 'fraction'), random
  poses (depth TV), the training cameras' centres (the near-camera penalty)."""
  pools = {'real': ray_pool(scene, scene.train_idx)}
  if pseudo is not None:
    pool = ray_pool(scene, None, images=pseudo.images, masks=pseudo.masks,
                    poses=pseudo.poses)
    if config.pseudo_mix == 'pixels':
      pools['mixed'] = training.mixed_pool(pools['real'], pool)
    else:
      pools['pseudo'] = pool
  poses = regularizer_poses(config, scene)
  if poses is not None:
    pools['random_poses'] = poses
  if config.near_camera_loss_mult > 0:
    pools['camera_centres'] = jnp.asarray(scene.poses[scene.train_idx][:, :3, 3],
                                          jnp.float32)
  return pools


def synthesize(config, scene, params, show_progress=False, sigma_fn=None, render_fn=None):
  """Pseudo-views of model `params`, with uncertainty masks if config.use_masks.

  With masks, the Hessian pass runs first and the colours and the uncertainty of the
  pseudo-views come out of one render pass.

  Args:
    config, scene: Config and Scene. params: model B.
    show_progress: draw progress bars.
    sigma_fn: the Hessian pass (uncertainty.masks.compute_masks' sigma_fn; None:
      uncertainty.laplace.vertex_sigma_pass).
    render_fn: renders one unmasked view (pseudo_views.render_pseudo_views' render_fn;
      None: pseudo_views.render_view).

  Returns:
    (PseudoViews, timing: {'seconds': total; 'render_seconds'; with masks
    'hessian_seconds', 'mu', 'kept_fraction'}, meta: a description of each view). The
    Hessian pass and each view's render count with the seconds sigma_fn / render_fn
    report for them: a function that reuses earlier work reports what that work cost, so
    sharing work never makes a round look cheaper.
  """
  if config.pseudo_source == 'photo':
    return pseudo_views.photo_pseudo_views(config, scene)
  t0 = time.perf_counter()
  poses, meta = pseudo_view_poses(config, scene)
  pose_seconds = time.perf_counter() - t0
  if config.use_masks:
    pv, timing = masked_pseudo_views(config, scene, params, poses, show_progress, sigma_fn)
  else:
    pv, timing = render_pseudo_views(config, scene, params, poses, show_progress, render_fn)
  timing['seconds'] = (pose_seconds + timing['render_seconds'] +
                       timing.get('hessian_seconds', 0.))
  return pv, timing, meta


def masked_pseudo_views(config, scene, params, poses, show_progress=False, sigma_fn=None):
  """Pseudo-views at `poses` with Laplace-uncertainty masks (pixels with U > mu masked).

  Returns:
    (PseudoViews with masks and uncertainty, timing: {'render_seconds': the wall time
    of all but the Hessian pass, 'hessian_seconds': the pass's as sigma_fn reports
    them, 'mu', 'kept_fraction'}).
  """
  from renerf_jax.uncertainty import masks as uncertainty_masks  # pylint: disable=g-import-not-at-top
  t0 = time.perf_counter()
  # The deformation grid spans the space the fields see: the contracted cube with
  # Config.contraction (as Bayes' Rays does on unbounded scenes), else the scene box.
  lo, hi = contraction.CONTRACTED_BOX if config.contraction else scene.bbox
  rays = camera_rays(scene, None, poses)
  train_rays = ray_pool(scene, scene.train_idx)['rays']
  t_masks = time.perf_counter()
  res = uncertainty_masks.compute_masks(config, params, train_rays, rays, np.asarray(lo),
                                        np.asarray(hi), show_progress=show_progress,
                                        sigma_fn=sigma_fn)
  masks_wall = time.perf_counter() - t_masks
  pv = PseudoViews(images=np.clip(res.rgb, 0., 1.), poses=np.asarray(poses),
                   masks=np.asarray(res.mask, np.float32),
                   uncertainty=np.asarray(res.uncertainty, np.float32))
  render_seconds = time.perf_counter() - t0 - masks_wall + res.render_seconds
  return pv, {'render_seconds': render_seconds, 'hessian_seconds': res.hessian_seconds,
              'mu': float(res.mu), 'kept_fraction': float(np.mean(pv.masks))}


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
      show_progress, as training.train_model takes them).
    evaluate_fn: (config, scene, params) -> evaluation.Evaluation.
    round_driver.py binds them to a round directory.

  Returns:
    RoundState of round state.round_index + 1.
  """
  from renerf_jax import backbones  # pylint: disable=g-import-not-at-top  (it imports us)
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
  return RoundState(params=result.state.params, pseudo=pseudo, round_index=r,
                    metrics=state.metrics + (metrics,),
                    curves=state.curves + (result.curve,), seconds=seconds)


def check_rounds_config(config, scene):
  """Raises ConfigError now for pseudo-view settings that round 1 could not use.

  Without this, a single training view with interpolated pseudo-views (no neighbouring
  pair to interpolate), a bad Config.interp_factors or Config.pseudo_targets, or the
  oracle (Config.pseudo_source='photo') with masks, would only fail after the baseline
  had trained. With num_rounds = 0 nothing is checked (the
  baseline alone needs no pseudo-views).
  """
  if config.num_rounds > 0:
    pseudo_view_poses(config, scene)
    if (config.backbone != 'nerf' and config.use_masks
        and config.mask_signal != 'one_minus_acc'):
      raise ConfigError(f'Config.mask_signal={config.mask_signal!r} needs the NeRF '
                        f'backbone; Config.backbone={config.backbone!r} masks with '
                        "'one_minus_acc' only")


def run_rounds(config, scene, show_progress: bool = False) -> RoundState:
  """Baseline plus config.num_rounds rounds in memory (round_driver.run_rounds: on disk)."""
  check_rounds_config(config, scene)
  state = initial_state()
  for _ in range(config.num_rounds + 1):
    state = round_step(config, scene, state, show_progress)
  return state


def rounds_table(metrics):
  """Markdown table of per-round test metrics in the shape of the paper's 3-view table."""
  rows = [dict(m, name='baseline' if m['round'] == 0 else f"Re-Nerfing R{m['round']}")
          for m in metrics]
  cols = [('name', 'round'), ('psnr', 'PSNR'), ('ssim', 'SSIM'),
          ('lpips_alex', 'LPIPS-alex'), ('lpips_vgg', 'LPIPS-vgg'), ('avg_err', 'avg err'),
          ('cumulative_seconds', 'cum. time [s]')]
  return report.markdown_table(rows, [c for c in cols if c[0] == 'name' or
                                      any(c[0] in m for m in metrics)])


def deltas_vs_baseline(metrics):
  """One line per round r >= 1: its metrics minus the baseline's, whatever the sign."""
  base, lines = metrics[0], []
  for m in metrics[1:]:
    parts = [f"{name} {m[k] - base[k]:+.{d}f}" for k, name, d in
             (('psnr', 'PSNR', 2), ('ssim', 'SSIM', 3), ('lpips_alex', 'LPIPS-alex', 3))
             if k in m and k in base]
    lines.append(f"R{m['round']} - baseline: " + ', '.join(parts) + ' (PSNR in dB; '
                 'higher PSNR / SSIM and lower LPIPS are better)')
  return lines
