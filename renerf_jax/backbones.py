"""What the round driver needs of a model family (`Config.backbone`).

Re-Nerfing is an add-on to any novel-view-synthesis backbone. A round needs five things
of one, each a function of the Config and the Scene; only `train` (its checkpoints and
log, through rundir, when given a directory) and `export` write files, the rest return
arrays that round_driver.py writes:

  init_params(config)                        -> a parameter template (loading a round)
  train(config, scene, out_dir, pseudo, ...) -> fit.TrainResult, trained from scratch
      on the real training views plus the pseudo-views (drawn inside the step window)
  synthesize(config, scene, params, ...)     -> (PseudoViews, timing, meta)
  cheap_eval_fn(config, scene)               -> params -> test PSNR (training curves)
  evaluate(config, scene, params)            -> evaluation.Evaluation (metrics, renders)

and, for anything that looks at a model, `render_views(config, scene, params, poses)`:
RGB, depth and accumulated opacity at cameras; optionally `export(params, round_dir)`,
extra files of a finished round (the Gaussians' .ply). `Config.backbone` picks one:
'nerf' (the RegNeRF-style mip-NeRF, with the MLP or grid field of `Config.field`) or
'gaussians' (3D Gaussian Splatting, renerf_jax/gaussians: whole images a step, no
uncertainty masks unless Config.mask_signal = 'one_minus_acc').
"""
import dataclasses
import time
from typing import Callable, Optional

import jax
import numpy as np

from renerf_jax import metrics, pseudo_views, renerf, rundir, training
from renerf_jax.datasets import camera_rays
from renerf_jax.errors import ConfigError
from renerf_jax.evaluation import cheap_eval_fn, evaluate_test_views, evaluate_views
from renerf_jax.pseudo_views import PseudoViews, pseudo_view_poses
from renerf_jax.rendering import render_image


@dataclasses.dataclass(frozen=True)
class Backbone:
  """A model family as the round driver sees it (see the module docstring)."""
  name: str
  init_params: Callable
  train: Callable
  synthesize: Callable
  cheap_eval_fn: Callable
  evaluate: Callable
  render_views: Callable
  # (params, round directory) -> None: extra files of a finished round (None: none).
  export: Optional[Callable] = None


# ------------------------------------------------------------------------- the NeRFs


def nerf_init_params(config):
  """The NeRF's parameter template (the init of seed key 0)."""
  return training.init_state(config, jax.random.PRNGKey(0)).params


def nerf_train(config, scene, out_dir, pseudo, **kwargs):
  """Trains a NeRF on the real views plus `pseudo` (training.train_model's kwargs), from
  the ray pools of renerf.make_pools."""
  return training.train_model(config, scene, out_dir,
                              renerf.make_pools(config, scene, pseudo), **kwargs)


def nerf_synthesize(config, scene, params, show_progress=False):
  """renerf.synthesize: pseudo-views, with Laplace or Hessian-free masks."""
  return renerf.synthesize(config, scene, params, show_progress)


def nerf_render_views(config, scene, params, poses, show_progress=False):
  """RGB [N, H, W, 3], depth [N, H, W] (the ray-distance expectation) and accumulated
  opacity [N, H, W] of the NeRF at camera-to-world `poses` [N, 3, 4]."""
  rays = camera_rays(scene, None, np.asarray(poses, np.float32))
  outs = [render_image(config, params, jax.tree_util.tree_map(lambda x, i=i: x[i], rays),
                       show_progress=show_progress, desc=f'view {i}')
          for i in range(len(poses))]
  return {'rgb': np.stack([o['rgb'] for o in outs]),
          'depth': np.stack([o['distance'] for o in outs]),
          'acc': np.stack([o['acc'] for o in outs])}


NERF = Backbone(name='nerf', init_params=nerf_init_params, train=nerf_train,
                synthesize=nerf_synthesize, cheap_eval_fn=cheap_eval_fn,
                evaluate=evaluate_test_views, render_views=nerf_render_views)


# ------------------------------------------------------------------ 3D Gaussian Splatting


def _gs():
  from renerf_jax.gaussians import training as gs_training  # pylint: disable=g-import-not-at-top
  return gs_training


def gaussians_init_params(config):
  """The Gaussians' parameter template: Config.gs_capacity empty slots."""
  return _gs().init_params(config)


def gaussians_train(config, scene, out_dir, pseudo, **kwargs):
  """3DGS from scratch on the real views plus `pseudo` (whole images, drawn uniformly
  while the pseudo-views are on)."""
  return _gs().train_gaussians(config, scene, out_dir, pseudo, **kwargs)


def gaussians_render_views(config, scene, params, poses, show_progress=False):
  """RGB, expected depth and accumulated opacity of the Gaussians at `poses`."""
  return _gs().render_views(config, scene, params, poses, show_progress=show_progress)


def synthesize_by_rendering(render_views: Callable, config, scene, params,
                            show_progress=False):
  """Pseudo-views of any backbone: its renders at the pseudo-view poses, unmasked, or
  masked where 1 - accumulated opacity is high (Config.mask_signal 'one_minus_acc', the
  only signal that needs nothing but a render; the paper uses no masks on 3DGS).

  Returns:
    (PseudoViews, timing, meta) as renerf.synthesize.
  """
  from renerf_jax.uncertainty import masks as uncertainty_masks  # pylint: disable=g-import-not-at-top
  if config.pseudo_source == 'photo':
    return pseudo_views.photo_pseudo_views(config, scene)
  if config.use_masks and config.mask_signal != 'one_minus_acc':
    raise ConfigError(f'Config.mask_signal={config.mask_signal!r} needs the NeRF '
                      f'backbone; Config.backbone={config.backbone!r} masks with '
                      "'one_minus_acc' only")
  t0 = time.perf_counter()
  poses, meta = pseudo_view_poses(config, scene)
  out = render_views(config, scene, params, poses, show_progress=show_progress)
  rgb = np.clip(np.asarray(out['rgb'], np.float32), 0., 1.)
  shape = rgb.shape[:3]
  timing = {'render_seconds': time.perf_counter() - t0}
  if config.use_masks:
    u = 1. - np.asarray(out['acc'], np.float32)
    mu = uncertainty_masks.mask_threshold(config, u)
    masks = np.asarray(uncertainty_masks.masks_from_uncertainty(u, mu), np.float32)
    timing.update(mu=mu, kept_fraction=float(np.mean(masks)))
  else:
    u, masks = np.zeros(shape, np.float32), np.ones(shape, np.float32)
  pv = PseudoViews(images=rgb, poses=np.asarray(poses, np.float32), masks=masks,
                   uncertainty=np.asarray(u, np.float32))
  timing['seconds'] = time.perf_counter() - t0
  return pv, timing, meta


def gaussians_synthesize(config, scene, params, show_progress=False):
  return synthesize_by_rendering(gaussians_render_views, config, scene, params,
                                 show_progress)


def cheap_eval_by_rendering(render_views: Callable, config, scene):
  """params -> PSNR on config.eval_n_views test views at pixel stride
  config.eval_stride (as evaluation.cheap_eval_fn), from whole renders."""
  idx = scene.test_idx[:config.eval_n_views]
  s = config.eval_stride
  gt = scene.images[idx][:, ::s, ::s]

  def fn(params):
    rgb = np.clip(render_views(config, scene, params, scene.poses[idx])['rgb'], 0., 1.)
    return float(metrics.mse_to_psnr(np.mean((rgb[:, ::s, ::s] - gt)**2)))
  return fn


def gaussians_cheap_eval_fn(config, scene):
  return cheap_eval_by_rendering(gaussians_render_views, config, scene)


def gaussians_evaluate(config, scene, params, show_progress=False):
  """Test-view metrics and renders of the Gaussians (evaluation.Evaluation); the views
  are rendered in one call (split across processes when there are several)."""
  out = gaussians_render_views(config, scene, params, scene.poses[scene.test_idx],
                               show_progress=show_progress)

  def render_view(j, i):
    del i
    return {'rgb': out['rgb'][j], 'distance': out['depth'][j]}
  return evaluate_views(config, scene, render_view)


def gaussians_export(params, rdir):
  """The round's Gaussians as rdir/point_cloud.ply, the reference 3DGS layout that
  splat viewers open (active Gaussians only)."""
  from renerf_jax.gaussians import ply  # pylint: disable=g-import-not-at-top
  ply.write_ply(rundir.point_cloud_path(rdir), params)


GAUSSIANS = Backbone(name='gaussians', init_params=gaussians_init_params,
                     train=gaussians_train, synthesize=gaussians_synthesize,
                     cheap_eval_fn=gaussians_cheap_eval_fn, evaluate=gaussians_evaluate,
                     render_views=gaussians_render_views, export=gaussians_export)

BACKBONES = {'nerf': NERF, 'gaussians': GAUSSIANS}


def get_backbone(config) -> Backbone:
  """The Backbone of `config.backbone`."""
  if config.backbone not in BACKBONES:
    raise ConfigError(f'Config.backbone={config.backbone!r} ({", ".join(BACKBONES)})')
  return BACKBONES[config.backbone]
