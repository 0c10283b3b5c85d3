"""What the round driver needs of a model family (`Config.backbone`).

Re-Nerfing is an add-on to any novel-view-synthesis backbone. A round needs four things
of one, each a function of the Config and the Scene, none of which writes a file unless
given a directory:

  init_params(config)                        -> a parameter template (loading a round)
  train(config, scene, out_dir, pseudo, ...) -> training.TrainResult, trained from scratch
      on the real training views plus the pseudo-views (drawn inside the step window)
  synthesize(config, scene, params, ...)     -> (PseudoViews, timing, meta)
  cheap_eval_fn(config, scene)               -> params -> test PSNR (training curves)
  evaluate(config, scene, params, out_dir)   -> {'per_image': [...], 'mean': {...}}

and, for anything that looks at a model, `render_views(config, scene, params, poses)`:
RGB, depth and accumulated opacity at cameras. `Config.backbone` picks one: 'nerf' (the
RegNeRF-style mip-NeRF, with the MLP or grid field of `Config.field`).
"""
import dataclasses
from typing import Callable

import jax
import numpy as np

from renerf_jax import renerf, training
from renerf_jax.datasets import camera_rays
from renerf_jax.errors import ConfigError
from renerf_jax.evaluation import cheap_eval_fn, evaluate_test_views
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

BACKBONES = {'nerf': NERF}


def get_backbone(config) -> Backbone:
  """The Backbone of `config.backbone`."""
  if config.backbone not in BACKBONES:
    raise ConfigError(f'Config.backbone={config.backbone!r} ({", ".join(BACKBONES)})')
  return BACKBONES[config.backbone]
