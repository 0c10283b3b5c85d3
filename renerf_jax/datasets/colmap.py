"""Captures in COLMAP's own layout: <scene>/sparse/0/{cameras,images,points3D}.{bin,txt}
beside the photos in <scene>/images/ (or images_<Config.factor>/ where that folder
exists), as COLMAP writes them and the mip-NeRF 360 and Tanks and Temples scenes ship.

Photos are sorted by name (the standard test views: every Config.llffhold-th) and split
by datasets/split.py. COLMAP's world-to-camera pose (quaternion w x y z, translation;
OpenCV axes: x right, y down, z forward) becomes the project's camera-to-world with
OpenGL axes (x right, y up, looking along -z) once, here: c2w = [R^T | -R^T t] with its
y and z columns negated. Intrinsics come from the camera models SIMPLE_PINHOLE,
PINHOLE, SIMPLE_RADIAL, RADIAL and OPENCV (colmap_io.opencv_intrinsics), scaled to the
photos' actual size. One camera shared by every photo loads as transforms.json's does
(its distortion undone on the rays, or resampled with Config.undistort); a camera per
photo (phone captures) needs Config.undistort: every photo is resampled to one shared
centred pinhole camera (undistort.undistort_each), which both backbones render, rather
than per-image intrinsics through both. The SfM points, with the images each is seen in
(its track), go into Scene.points for the Gaussians' SfM start; the points' box (1st to
99th percentile of each axis) is Scene.bbox and world_bounds. Config.normalize_poses
moves cameras, points and box together. Every problem is one DataError line naming the
file.
"""
import logging
import os

import numpy as np

from renerf_jax.datasets import colmap_io
from renerf_jax.datasets import images as image_io
from renerf_jax.datasets import undistort
from renerf_jax.datasets.points import points_box
from renerf_jax.datasets.split import split_of
from renerf_jax.datasets.transforms import object_scene
from renerf_jax.errors import DataError


def qvec_to_rotmat(q):
  """The rotation matrix of a quaternion (w, x, y, z), normalised first."""
  w, x, y, z = np.asarray(q, np.float64) / np.linalg.norm(q)
  return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                   [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                   [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def colmap_to_c2w(qvec, tvec):
  """COLMAP's world-to-camera (OpenCV axes) -> camera-to-world [3, 4], OpenGL axes."""
  rot = qvec_to_rotmat(qvec)
  c2w = np.concatenate([rot.T, -rot.T @ np.asarray(tvec, np.float64)[:, None]], 1)
  return c2w * np.array([1., -1., -1., 1.])


def model_dir_of(scene_dir):
  """sparse/0 where it exists (COLMAP's mapper output), else sparse/."""
  sub = os.path.join(scene_dir, 'sparse', '0')
  return sub if os.path.isdir(sub) else os.path.join(scene_dir, 'sparse')


def image_dir_of(scene_dir, factor):
  """images_<factor>/ where factor > 1 and it exists, else images/ (a warning line says
  so where factor > 1: Config.image_downsample then sets the resolution)."""
  sub = os.path.join(scene_dir, f'images_{factor}')
  if factor > 1 and not os.path.isdir(sub):
    logging.warning('%s not found: reading the full-size photos of images/ '
                    '(Config.factor = 1 says so; Config.image_downsample downsamples)', sub)
  return sub if factor > 1 and os.path.isdir(sub) else os.path.join(scene_dir, 'images')


def read_capture(scene_dir, factor=1):
  """A COLMAP capture's photos and cameras, sorted by name.

  Returns:
    dict: 'paths' (image files), 'poses' [N, 3, 4] OpenGL c2w, 'cameras' (N models'
    (name, width, height, params)), 'image_ids' [N], 'points' (colmap_io's points),
    'model' (the model folder).
  """
  model_dir = model_dir_of(scene_dir)
  if not os.path.isdir(model_dir):
    raise DataError(f'no COLMAP model folder (sparse/0 or sparse) in {scene_dir}')
  cams, imgs, points = colmap_io.read_model(model_dir)
  images_file = colmap_io.model_files(model_dir)[1]
  if not imgs:
    raise DataError(f'{images_file}: the model holds no images')
  img_dir = image_dir_of(scene_dir, factor)
  imgs = sorted(imgs, key=lambda r: r[4])
  paths, poses, models = [], [], []
  for image_id, q, t, cam_id, name, _ in imgs:
    path = os.path.join(img_dir, name)
    if not os.path.isfile(path):
      raise DataError(f'{images_file}: image {name!r} not found: {path}')
    if cam_id not in cams:
      raise DataError(f'{images_file}: image {name!r} has camera {cam_id}, which the '
                      'cameras file does not hold')
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(t)) and np.linalg.norm(q) > 0):
      raise DataError(f'{images_file}: image {name!r} has a non-finite or zero pose')
    paths.append(path)
    poses.append(colmap_to_c2w(q, t))
    models.append(cams[cam_id])
  return {'paths': paths, 'poses': np.stack(poses), 'cameras': models,
          'image_ids': np.asarray([r[0] for r in imgs]), 'points': points,
          'model': model_dir, 'images_file': images_file}


def photo_intrinsics(camera, shape, source):
  """(fx, fy, cx, cy, k1, k2, p1, p2) of a camera model at the photo's size (h, w)."""
  name, width, height, params = camera
  intr = colmap_io.opencv_intrinsics(name, params, source)
  sx, sy = shape[1] / width, shape[0] / height
  return (intr[0] * sx, intr[1] * sy, intr[2] * sx, intr[3] * sy) + intr[4:]


def point_visibility(points, image_ids):
  """[P, N] bool: which of the images (ids in the Scene's order) see each point."""
  ids, _, _, tracks = points
  column = {int(i): k for k, i in enumerate(image_ids)}
  out = np.zeros((len(ids), len(image_ids)), bool)
  for p, track in enumerate(tracks):
    cols = [column[int(i)] for i in track if int(i) in column]
    out[p, cols] = True
  return out


def load_colmap(config):
  """Loads <Config.data_dir>/<Config.scene> (the module docstring's layout)."""
  scene_dir = os.path.join(config.data_dir, config.scene)
  cap = read_capture(scene_dir, config.factor)
  images = image_io.read_images(cap['paths'])
  shape = images.shape[1:3]
  cameras_file = colmap_io.model_files(cap['model'])[0]
  intr = [photo_intrinsics(c, shape, cameras_file) for c in cap['cameras']]
  shared = all(np.allclose(i, intr[0], rtol=1e-9, atol=1e-12) for i in intr)
  fx, fy, cx, cy = intr[0][:4]
  h, w = shape
  pinhole = shared and (abs(fx - fy) <= 1e-9 * fx and abs(cx - 0.5 * w) <= 1e-9 * w
                        and abs(cy - 0.5 * h) <= 1e-9 * h and not any(intr[0][4:]))
  try:
    if not shared and not config.undistort:
      raise ValueError('the photos have cameras of their own (one camera per scene is '
                       'supported): set Config.undistort = True to resample them to one')
    if not pinhole and config.undistort:
      images, fx = (undistort.undistort_images(images, intr[0]) if shared
                    else undistort.undistort_each(images, intr))
      pinhole = True
  except ValueError as e:
    raise DataError(f'{cap["model"]}: Config.undistort: {e}') from None
  train_idx, val_idx, test_idx = split_of(config, cap['poses'], cap['images_file'])
  _, xyz, rgb, _ = cap['points']
  if not len(xyz):
    raise DataError(f'{cap["model"]}: the model holds no 3D points')
  return object_scene(config, config.scene, images, cap['poses'], fx, points_box(xyz),
                      train_idx, test_idx, intrinsics=None if pinhole else intr[0],
                      val_idx=val_idx, points=xyz, point_colors=rgb / 255.,
                      point_views=point_visibility(cap['points'], cap['image_ids']))
