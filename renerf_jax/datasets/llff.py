"""LLFF scenes: poses_bounds.npy + images_<factor>/, RegNeRF protocol."""
import logging
import os

import numpy as np

from renerf_jax import cameras
from renerf_jax.datasets import images as image_io
from renerf_jax.datasets.split import split_of
from renerf_jax.datasets.scene import (Scene, focus_depth_from_bounds,
                                       frustum_bounds)
from renerf_jax.errors import DataError


def read_poses_bounds(path):
  """Reads and validates poses_bounds.npy.

  Returns:
    (poses [N, 3, 5] in LLFF's [down, right, back, position, hwf] layout, bounds [N, 2]).
  """
  if not os.path.isfile(path):
    raise DataError(f'poses file not found: {path}')
  with open(path, 'rb') as f:
    if f.read(6) != b'\x93NUMPY':
      raise DataError(f'{path} is not a .npy file (no NUMPY header)')
  try:
    arr = np.load(path)
  except Exception as e:  # pylint: disable=broad-except
    first = str(e).strip().splitlines()[0] if str(e).strip() else 'not a .npy array'
    raise DataError(f'cannot read {path}: {type(e).__name__}: {first}') from None
  if not isinstance(arr, np.ndarray) or arr.dtype.kind not in 'fiu':
    raise DataError(f'{path} holds no numeric array, expected [N, 17] numbers')
  if arr.ndim != 2 or arr.shape[1] != 17:
    raise DataError(f'{path} has shape {arr.shape}, expected [N, 17] (3x5 pose + 2 bounds)')
  if not np.all(np.isfinite(arr)):
    bad = int(np.argwhere(~np.isfinite(arr))[0, 0])
    raise DataError(f'{path} has NaN or inf values (first in row {bad})')
  poses = arr[:, :15].reshape(-1, 3, 5).astype(np.float64)
  bounds = arr[:, 15:].astype(np.float64)
  if np.any(bounds <= 0):
    raise DataError(f'{path} has non-positive depth bounds (first in row '
                    f'{int(np.argwhere(bounds <= 0)[0, 0])})')
  return poses, bounds


def raise_near_bounds(bounds, min_near: float):
  """Raises every per-image near bound to at least min_near (far bounds kept above it).

  Args:
    bounds: [N, 2] near/far depth bounds in poses_bounds.npy units.
    min_near: the smallest near bound allowed (> 0).

  Returns:
    [N, 2] bounds with near >= min_near and far >= near.
  """
  near = np.maximum(bounds[:, 0], min_near)
  return np.stack([near, np.maximum(bounds[:, 1], near)], axis=1)


def bounds_warning(bounds, path):
  """A one-line warning when a capture's depth bounds look set by spurious near points,
  else None.

  RegNeRF's LLFF processing scales the scene by 1 / (0.75 min near bound), so one image
  with a near bound far below the others' pushes the whole scene towards NDC's far end.
  LLFF's own captures (fern, orchids, fortress here) have near bounds within 1.3x of each
  other and far / near around 4-6; the re-processed room and trex in ../shared have 4-5x
  and 22 (their near bounds are 3-12x smaller than the depths triangulated from the images,
  experiments/results/near_bounds_room_trex/README.md).

  Args:
    bounds: [N, 2] near/far bounds. path: the file they came from (named in the warning).

  Returns:
    str or None.
  """
  near_spread = float(bounds[:, 0].max() / bounds[:, 0].min())
  far_near = float(np.median(bounds[:, 1] / bounds[:, 0]))
  if near_spread > 2. or far_near > 12.:
    return (f'{path}: near bounds vary {near_spread:.1f}x across images and the median '
            f'far/near is {far_near:.1f} (LLFF captures: under 2 and 12); spurious near '
            'points make the scene tiny in NDC. Check the bounds, or set '
            'Config.llff_min_near for this scene')
  return None


def load_llff(config) -> Scene:
  """Loads an LLFF scene with RegNeRF's processing and few-shot split.

  Reads <data_dir>/<scene>/poses_bounds.npy and images_<factor>/; converts poses to the
  OpenGL convention, scales focal by 1/factor, raises the near bounds to
  Config.llff_min_near where it names this scene (warns when the bounds look spurious:
  bounds_warning), rescales by 1/(0.75 * min bound) and recentres on the average pose.
  Rays use NDC when config.use_ndc. Scene.world_bounds is the box of the camera frusta
  between the rescaled near and (capped) far bounds (scene.frustum_bounds).
  """
  if not os.path.isdir(config.data_dir):
    raise DataError(f'data directory not found: {config.data_dir!r} (Config.data_dir)')
  scene_dir = os.path.join(config.data_dir, config.scene)
  if not os.path.isdir(scene_dir):
    raise DataError(f'scene folder not found: {scene_dir} (Config.scene={config.scene!r})')
  bounds_path = os.path.join(scene_dir, 'poses_bounds.npy')
  poses_raw, bounds = read_poses_bounds(bounds_path)
  for _, min_near in config.llff_min_near:  # Config keeps only Config.scene's pair.
    bounds = raise_near_bounds(bounds, min_near)
  warning = bounds_warning(bounds, bounds_path)
  if warning:
    logging.warning(warning)
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
  train_idx, val_idx, test_idx = split_of(config, poses, bounds_path)
  near, far = (0., 1.) if config.use_ndc else (float(bounds.min() * .9), float(bounds.max()))
  return Scene(name=config.scene, images=images.astype(np.float32),
               poses=poses.astype(np.float32), focal=focal, near=near, far=far,
               use_ndc=config.use_ndc, white_bkgd=config.white_bkgd,
               train_idx=train_idx, test_idx=test_idx, val_idx=val_idx, forward_facing=True, focus_depth=focus_depth_from_bounds(bounds),
               bbox=((-1.,) * 3, (1.,) * 3) if config.use_ndc else ((-far,) * 3, (far,) * 3),
               world_bounds=frustum_bounds(poses[train_idx], bounds[train_idx], focal, h, w))
