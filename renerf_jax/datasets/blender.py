"""NeRF-synthetic (Blender) scenes: transforms_{train,test}.json, RGBA on white."""
import json
import os

import numpy as np

from renerf_jax.datasets import images as image_io
from renerf_jax.datasets.scene import Scene
from renerf_jax.datasets.split import validation_frames
from renerf_jax.errors import DataError


def read_split(scene_dir, split):
  """Reads one split's frames. Returns (image paths, c2w [N, 3, 4], camera_angle_x).

  Every problem is one DataError line naming the file: unreadable JSON, no frames, a
  frame without a file_path, a duplicate one, a missing image, a transform_matrix that
  is not a finite 4x4 matrix, a camera_angle_x that is not an angle in (0, pi).
  """
  path = os.path.join(scene_dir, f'transforms_{split}.json')
  if not os.path.isfile(path):
    raise DataError(f'camera file not found: {path}')
  try:
    with open(path) as f:
      meta = json.load(f)
    angle = float(meta['camera_angle_x'])
    frames = meta['frames']
  except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError, ValueError) as e:
    raise DataError(f'malformed {path}: {type(e).__name__}: {e}') from None
  if not 0. < angle < np.pi:
    raise DataError(f'{path}: camera_angle_x={angle} is not an angle in (0, pi)')
  if not isinstance(frames, list) or not frames:
    raise DataError(f'{path}: "frames" is not a non-empty list')
  paths, poses = [], []
  for i, frame in enumerate(frames):
    if not isinstance(frame, dict) or not isinstance(frame.get('file_path'), str):
      raise DataError(f'{path}: frame {i} has no "file_path" string')
    img = os.path.normpath(os.path.join(scene_dir, frame['file_path']))
    if not os.path.splitext(img)[1]:
      img += '.png'
    if img in paths:
      raise DataError(f'{path}: frame {i} repeats file_path {frame["file_path"]!r}')
    if not os.path.isfile(img):
      raise DataError(f'{path}: frame file missing: {img}')
    try:
      c2w = np.asarray(frame.get('transform_matrix'), np.float64)
    except (TypeError, ValueError):
      c2w = np.zeros(0)
    if c2w.shape != (4, 4) or not np.all(np.isfinite(c2w)):
      raise DataError(f'{path}: bad transform_matrix for {frame["file_path"]} (not a '
                      'finite 4x4 matrix)')
    paths.append(img)
    poses.append(c2w[:3, :4])
  return paths, np.stack(poses), angle


# The few-shot Blender training frames of DietNeRF (Jain et al. 2021), used by RegNeRF,
# FreeNeRF, FSGS and DNGaussian: indices into transforms_train.json's frames.
STANDARD_TRAIN_IDS = (26, 86, 2, 55, 75, 93, 16, 73)


def blender_split(n_train, n_test, config, source):
  """The few-shot split of a Blender layout (train and test files).

  Args:
    n_train, n_test: frames in transforms_train.json and transforms_test.json.
    config: Config (n_input_views, blender_split, test_stride).
    source: the file or folder named in the error.

  Returns:
    (the n_input_views training frames: the first n_input_views of STANDARD_TRAIN_IDS
    with Config.blender_split='standard', evenly spaced with 'linspace'; every
    test_stride-th test frame), index arrays. Raises DataError when the frames asked for
    do not exist.
  """
  if config.n_input_views > n_train:
    raise DataError(f'Config.n_input_views={config.n_input_views} but {source} has '
                    f'{n_train} train frames')
  if config.blender_split == 'standard':
    if config.n_input_views > len(STANDARD_TRAIN_IDS):
      raise DataError(f"Config.blender_split='standard' has {len(STANDARD_TRAIN_IDS)} "
                      f'training frames, not Config.n_input_views={config.n_input_views} '
                      "(use 'linspace')")
    pick = np.asarray(STANDARD_TRAIN_IDS[:config.n_input_views])
    if pick.max() >= n_train:
      raise DataError(f"Config.blender_split='standard' needs train frame {pick.max()} but "
                      f"{source} has {n_train} (use 'linspace')")
  else:
    pick = np.round(np.linspace(0, n_train - 1, config.n_input_views)).astype(int)
  return pick, np.arange(0, n_test, config.test_stride)


def load_blender(config) -> Scene:
  """Loads a Blender scene: the n_input_views train views of blender_split and the test
  views, RGBA composited on white when config.white_bkgd."""
  scene_dir = os.path.join(config.data_dir, config.scene)
  if not os.path.isdir(scene_dir):
    raise DataError(f'scene folder not found: {scene_dir}')
  if config.train_view_selection != 'linspace':
    raise DataError(f'{scene_dir}: Config.train_view_selection applies to captures; a '
                    'Blender layout chooses its training frames by Config.blender_split')
  tr_paths, tr_poses, angle = read_split(scene_dir, 'train')
  te_paths, te_poses, _ = read_split(scene_dir, 'test')
  pick, keep = blender_split(len(tr_paths), len(te_paths), config, scene_dir)
  te_paths, te_poses = [te_paths[i] for i in keep], te_poses[keep]
  if config.val_views:  # Evenly spaced frames of transforms_val.json.
    va_paths, va_poses, _ = read_split(scene_dir, 'val')
    vpick = validation_frames(len(va_paths), config.val_views,
                              os.path.join(scene_dir, 'transforms_val.json'))
    te_paths += [va_paths[i] for i in vpick]
    te_poses = np.concatenate([te_poses, va_poses[vpick]], 0)
  paths = [tr_paths[i] for i in pick] + te_paths
  rgba = image_io.read_images(paths, keep_alpha=True)
  rgb, alpha = rgba[..., :3], rgba[..., 3:]
  images = rgb * alpha + (1. - alpha) if config.white_bkgd else rgb * alpha
  w = images.shape[2]
  focal = 0.5 * w / np.tan(0.5 * angle)
  n_tr = len(pick)
  poses = np.concatenate([tr_poses[pick], te_poses], 0)
  return Scene(name=config.scene, images=images.astype(np.float32),
               poses=poses.astype(np.float32), focal=float(focal), near=config.near,
               far=config.far, use_ndc=False, white_bkgd=config.white_bkgd,
               train_idx=np.arange(n_tr),
               test_idx=np.arange(n_tr, len(paths) - config.val_views),
               val_idx=np.arange(len(paths) - config.val_views, len(paths)),
               forward_facing=False,
               bbox=((-1.5, -1.5, -1.5), (1.5, 1.5, 1.5)),
               world_bounds=((-1.5, -1.5, -1.5), (1.5, 1.5, 1.5)))
