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
'nerf' (the RegNeRF-style mip-NeRF, with the MLP or grid field of `Config.field`:
renerf_jax/nerf/backbone.py) or 'gaussians' (3D Gaussian Splatting: whole images a step,
no uncertainty masks unless Config.mask_signal = 'one_minus_acc':
renerf_jax/gaussians/backbone.py). This module holds the protocol, the registry (each
backbone's package is imported when a Config first asks for it, so the round driver
never imports a backbone's internals) and the helpers any backbone that renders whole
views can use.
"""
import dataclasses
import importlib
import time
from typing import Callable, Optional

import numpy as np

from renerf_jax import metrics, pseudo_views
from renerf_jax.errors import ConfigError
from renerf_jax.pseudo_views import PseudoViews, pseudo_view_poses


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


# Config.backbone -> the module whose BACKBONE implements it.
REGISTRY = {'nerf': 'renerf_jax.nerf.backbone', 'gaussians': 'renerf_jax.gaussians.backbone'}


def get_backbone(config) -> Backbone:
  """The Backbone of `config.backbone` (its package imported on first use)."""
  if config.backbone not in REGISTRY:
    raise ConfigError(f'Config.backbone={config.backbone!r} ({", ".join(REGISTRY)})')
  return importlib.import_module(REGISTRY[config.backbone]).BACKBONE


# ------------------------------------------------------ backbones that render whole views


def synthesize_by_rendering(render_views: Callable, config, scene, params,
                            show_progress=False):
  """Pseudo-views of any backbone: its renders at the pseudo-view poses, unmasked, or
  masked where 1 - accumulated opacity is high (Config.mask_signal 'one_minus_acc', the
  only signal that needs nothing but a render; the paper uses no masks on 3DGS).

  Returns:
    (PseudoViews, timing, meta) as a Backbone's synthesize.
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


def cheap_eval_by_rendering(render_views: Callable, config, scene):
  """params -> PSNR on config.eval_n_views test views at pixel stride
  config.eval_stride (as the NeRF's nerf.evaluation.cheap_eval_fn), from whole renders."""
  idx = scene.test_idx[:config.eval_n_views]
  s = config.eval_stride
  gt = scene.images[idx][:, ::s, ::s]

  def fn(params):
    rgb = np.clip(render_views(config, scene, params, scene.poses[idx])['rgb'], 0., 1.)
    return float(metrics.mse_to_psnr(np.mean((rgb[:, ::s, ::s] - gt)**2)))
  return fn
