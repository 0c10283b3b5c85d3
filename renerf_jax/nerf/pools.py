"""The NeRF's training pools: the real and pseudo-view rays, random poses for depth TV,
the training cameras' centres for the near-camera penalty."""
from typing import Optional

import jax.numpy as jnp
import numpy as np

from renerf_jax import random_poses
from renerf_jax.datasets import ray_pool
from renerf_jax.nerf import training
from renerf_jax.pseudo_views import PseudoViews


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
