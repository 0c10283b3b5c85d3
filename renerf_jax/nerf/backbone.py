"""The NeRF backbone (Config.backbone = 'nerf'): the RegNeRF-style mip-NeRF with the MLP or
grid field of Config.field, as the round driver sees it (backbones.Backbone)."""
import functools

import jax
import numpy as np

from renerf_jax.backbones import Backbone
from renerf_jax.datasets import camera_rays
from renerf_jax.nerf import pools, synthesis, training
from renerf_jax.nerf.evaluation import cheap_eval_fn, evaluate_test_views
from renerf_jax.nerf.rendering import render_image


@functools.partial(jax.jit, static_argnums=0)
def _init_field_params(config, key):
  return training.init_field_params(config, key)


def nerf_init_params(config):
  """The NeRF's parameter template (the init of seed key 0), as one compiled call, traced
  once per Config in a process (a table loads many rounds of one Config).

  flax's init run op by op compiled about 50 small programs per call (2.8 s for each
  round a table or the viewer loads); the optimiser state is not built.
  """
  return _init_field_params(config, jax.random.PRNGKey(0))


def nerf_train(config, scene, out_dir, pseudo, **kwargs):
  """Trains a NeRF on the real views plus `pseudo` (training.train_model's kwargs), from
  the ray pools of pools.make_pools."""
  return training.train_model(config, scene, out_dir,
                              pools.make_pools(config, scene, pseudo), **kwargs)


def nerf_synthesize(config, scene, params, show_progress=False):
  """synthesis.synthesize: pseudo-views, with Laplace or Hessian-free masks."""
  return synthesis.synthesize(config, scene, params, show_progress)


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


BACKBONE = Backbone(name='nerf', init_params=nerf_init_params, train=nerf_train,
                    synthesize=nerf_synthesize, cheap_eval_fn=cheap_eval_fn,
                    evaluate=evaluate_test_views, render_views=nerf_render_views)
