"""LLFF scenes: poses_bounds.npy + images_<factor>/, RegNeRF protocol."""
import os

import numpy as np

from renerf_jax import cameras
from renerf_jax.datasets import images as image_io
from renerf_jax.datasets.scene import Scene, fewshot_split, focus_depth_from_bounds
from renerf_jax.errors import DataError


def read_poses_bounds(path):
  """Reads and validates poses_bounds.npy.

  Returns:
    (poses [N, 3, 5] in LLFF's [down, right, back, position, hwf] layout, bounds [N, 2]).
  """
  if not os.path.isfile(path):
    raise DataError(f'poses file not found: {path}')
  try:
    arr = np.load(path)
  except Exception as e:  # pylint: disable=broad-except
    raise DataError(f'cannot read {path}: {type(e).__name__}') from None
  if arr.ndim != 2 or arr.shape[1] != 17:
    raise DataError(f'{path} has shape {arr.shape}, expected [N, 17] (3x5 pose + 2 bounds)')
  if not np.all(np.isfinite(arr)):
    bad = int(np.argwhere(~np.isfinite(arr))[0, 0])
    raise DataError(f'{path} has NaN or inf values (first in row {bad})')
  poses = arr[:, :15].reshape(-1, 3, 5).astype(np.float64)
  bounds = arr[:, 15:].astype(np.float64)
  if np.any(bounds <= 0):
    raise DataError(f'{path} has non-positive depth bounds')
  return poses, bounds


def load_llff(config) -> Scene:
  """Loads an LLFF scene with RegNeRF's processing and few-shot split.

  Reads <data_dir>/<scene>/poses_bounds.npy and images_<factor>/; converts poses to the
  OpenGL convention, scales focal by 1/factor, rescales by 1/(0.75 * min bound) and
  recentres on the average pose. Rays use NDC when config.use_ndc.
  """
  if not os.path.isdir(config.data_dir):
    raise DataError(f'data directory not found: {config.data_dir!r} (Config.data_dir)')
  scene_dir = os.path.join(config.data_dir, config.scene)
  if not os.path.isdir(scene_dir):
    raise DataError(f'scene folder not found: {scene_dir} (Config.scene={config.scene!r})')
  poses_raw, bounds = read_poses_bounds(os.path.join(scene_dir, 'poses_bounds.npy'))
  suffix = f'_{config.factor}' if config.factor > 1 else ''
  img_dir = os.path.join(scene_dir, 'images' + suffix)
  paths = image_io.list_images(img_dir)
  if len(paths) != poses_raw.shape[0]:
    raise DataError(f'{len(paths)} images in {img_dir} but {poses_raw.shape[0]} poses in '
                    f'{os.path.join(scene_dir, "poses_bounds.npy")}')
  images = image_io.read_images(paths)
  h, w = images.shape[1:3]
  focal = float(poses_raw[0, 2, 4]) / config.factor
  poses = cameras.llff_to_opengl(poses_raw[:, :, :4])
  poses, bounds, _ = cameras.process_llff_poses(poses, bounds)
  train_idx, test_idx = fewshot_split(len(paths), config.n_input_views, config.llffhold)
  near, far = (0., 1.) if config.use_ndc else (float(bounds.min() * .9), float(bounds.max()))
  return Scene(name=config.scene, images=images.astype(np.float32),
               poses=poses.astype(np.float32), focal=focal, near=near, far=far,
               use_ndc=config.use_ndc, white_bkgd=config.white_bkgd,
               train_idx=train_idx, test_idx=test_idx, forward_facing=True, focus_depth=focus_depth_from_bounds(bounds),
               bbox=((-1.,) * 3, (1.,) * 3) if config.use_ndc else ((-far,) * 3, (far,) * 3))
