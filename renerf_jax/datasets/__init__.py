"""Datasets: LLFF, transforms.json (Instant-NGP / nerfstudio), COLMAP, Blender and the two embedded
scenes (forward-facing 'procedural', 360-degree 'orbit'), behind one `load_scene`."""
import dataclasses

from renerf_jax.datasets import split
from renerf_jax.datasets.scene import (Scene, camera_rays, downsample_scene, fewshot_split,
                                       ray_pool)

__all__ = ["Scene", "camera_rays", "downsample_scene", "fewshot_split", "load_scene",
           "ray_pool"]


def load_scene(config) -> Scene:
  """Loads the scene selected by config.dataset_loader (then config.image_downsample)."""
  if config.dataset_loader == 'llff':
    from renerf_jax.datasets.llff import load_llff  # pylint: disable=g-import-not-at-top
    scene = load_llff(config)
  elif config.dataset_loader == 'transforms':
    from renerf_jax.datasets.transforms import load_transforms  # pylint: disable=g-import-not-at-top
    scene = load_transforms(config)
  elif config.dataset_loader == 'colmap':
    from renerf_jax.datasets.colmap import load_colmap  # pylint: disable=g-import-not-at-top
    scene = load_colmap(config)
  elif config.dataset_loader == 'blender':
    from renerf_jax.datasets.blender import load_blender  # pylint: disable=g-import-not-at-top
    scene = load_blender(config)
  elif config.dataset_loader == 'orbit':
    from renerf_jax.datasets.orbit import load_orbit  # pylint: disable=g-import-not-at-top
    scene = load_orbit(config)
  else:
    from renerf_jax.datasets.procedural import load_procedural  # pylint: disable=g-import-not-at-top
    scene = load_procedural(config)
  scene = downsample_scene(scene, config.image_downsample)
  if config.leave_out_view >= 0:  # Issue 64's probe: a training view held out.
    train, val = split.leave_out_view(scene.train_idx, scene.val_idx, config.leave_out_view)
    scene = dataclasses.replace(scene, train_idx=train, val_idx=val)
  return scene
