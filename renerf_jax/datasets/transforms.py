"""Scenes in the Instant-NGP / nerfstudio `transforms.json` format.

The format COLMAP conversions (`colmap2nerf.py`, `ns-process-data`) and phone capture
apps write: one `transform_matrix` (camera-to-world, OpenGL axes as in NeRF) and
`file_path` per frame; intrinsics `fl_x fl_y cx cy w h` at the top level or per frame,
`camera_angle_x` (and `camera_angle_y`) where focal lengths are missing; OpenCV
distortion `k1 k2 p1 p2`, undone on the ray directions (cameras.pixel_directions); and
`aabb_scale`, the scene box of Instant-NGP: in NeRF's world units it is centred at the
origin with half-size 1.5 x aabb_scale (Instant-NGP scales positions by 0.33 into a
box of side aabb_scale), which is Scene.bbox and Scene.world_bounds here.

Two layouts load:
  <scene>/transforms.json                          a capture: frames sorted by file name,
      every Config.llffhold-th a test view, Config.n_input_views training views chosen
      from the rest by Config.train_view_selection, Config.val_views validation views
      (datasets/split.py; the other frames stay in the Scene for the oracle of issue 34);
      a nerfstudio `ply_file_path` (SfM points in the json's frame) is read into
      Scene.points, and its box (1st-99th percentiles) is the scene box where the file
      has no aabb_scale;
  <scene>/transforms_train.json, transforms_test.json   NeRF-synthetic (Blender): the
      n_input_views training views by Config.blender_split, every test_stride-th test
      view, in the files' order (the order the published few-shot splits index), and
      Config.val_views frames of transforms_val.json evenly spaced.
RGBA images are composited on white when Config.white_bkgd, else on black (as the
Blender loader does). Config.normalize_poses moves and scales the cameras as mip-NeRF
360 places unbounded scenes (the focus point of the optical axes at the origin, the
farthest camera at distance 1); nerfstudio's own files carry no aabb_scale and are not
normalised otherwise, so the default box (half-size 1.5) may not hold such a scene
without it. Config.undistort resamples distorted photos to a centred pinhole camera
(undistort.py). Every problem is one DataError line naming the file.
"""
import json
import os

import numpy as np

from renerf_jax.datasets import images as image_io
from renerf_jax.datasets import undistort
from renerf_jax.datasets.blender import blender_split
from renerf_jax.datasets.points import points_box, read_points_ply
from renerf_jax.datasets.scene import Scene
from renerf_jax.datasets.split import split_of, validation_frames
from renerf_jax.errors import DataError

DISTORTION_KEYS = ('k1', 'k2', 'p1', 'p2')
# Camera models whose rays this loader makes (pinhole with OpenCV's k1 k2 p1 p2);
# fisheye and the 8-coefficient model are refused, not silently misread.
CAMERA_MODELS = ('OPENCV', 'PINHOLE', 'SIMPLE_PINHOLE', 'SIMPLE_RADIAL', 'RADIAL')
UNSUPPORTED_KEYS = ('k3', 'k4', 'k5', 'k6')


def _read_json(path):
  try:
    with open(path) as f:
      meta = json.load(f)
  except (OSError, json.JSONDecodeError, UnicodeDecodeError) as e:
    raise DataError(f'cannot read {path}: {type(e).__name__}: {e}') from None
  if not isinstance(meta, dict) or not isinstance(meta.get('frames'), list):
    raise DataError(f'{path}: no "frames" list')
  if not meta['frames']:
    raise DataError(f'{path}: "frames" is empty')
  return meta


def _number(meta, key, path, where):
  try:
    v = float(meta[key])
  except (TypeError, ValueError):
    raise DataError(f'{path}: {where} "{key}" is not a number: {meta[key]!r}') from None
  if not np.isfinite(v):
    raise DataError(f'{path}: {where} "{key}" is not finite: {v}')
  return v


def frame_camera(meta, frame, path):
  """(w, h, (fx, fy, cx, cy, k1, k2, p1, p2), camera_angle_x) of one frame: its own keys
  over the file's. w, h, fx, fy, cx, cy and camera_angle_x may be None (then the image
  decides: cx, cy at its centre, fx from camera_angle_x and its width)."""
  where = f'frame {frame.get("file_path", "?")!r}'
  get = lambda key: (_number(frame, key, path, where) if key in frame else
                     _number(meta, key, path, 'top-level') if key in meta else None)
  model = frame.get('camera_model', meta.get('camera_model', 'OPENCV'))
  if model not in CAMERA_MODELS or frame.get('is_fisheye', meta.get('is_fisheye', False)):
    raise DataError(f'{path}: {where}: camera model {model!r}'
                    f'{" (fisheye)" if model in CAMERA_MODELS else ""} is not supported '
                    f'(pinhole with k1 k2 p1 p2: {", ".join(CAMERA_MODELS)})')
  for key in UNSUPPORTED_KEYS:
    if get(key):
      raise DataError(f'{path}: {where}: distortion coefficient "{key}" is not supported '
                      '(only k1 k2 p1 p2)')
  w, h = get('w'), get('h')
  fx, fy = get('fl_x'), get('fl_y')
  angle_x, angle_y = get('camera_angle_x'), get('camera_angle_y')
  if fx is None and angle_x is not None and w is not None:
    fx = 0.5 * w / np.tan(0.5 * angle_x)
  if fy is None and angle_y is not None and h is not None:
    fy = 0.5 * h / np.tan(0.5 * angle_y)
  fx = fx if fx is not None else fy
  fy = fy if fy is not None else fx
  if fx is None and angle_x is None:
    raise DataError(f'{path}: {where} has no focal length (fl_x, fl_y or camera_angle_x)')
  dist = tuple(get(k) or 0. for k in DISTORTION_KEYS)
  return w, h, (fx, fy, get('cx'), get('cy')) + dist, angle_x


def read_frames(path, sort=True):
  """Frames of one transforms file, sorted by file name (or in the file's order).

  Returns:
    (image paths, c2w [N, 3, 4] float64, [(w, h, intrinsics, camera_angle_x)] per frame).
  """
  meta = _read_json(path)
  scene_dir = os.path.dirname(path)
  rows = []
  for i, frame in enumerate(meta['frames']):
    if not isinstance(frame, dict) or not isinstance(frame.get('file_path'), str):
      raise DataError(f'{path}: frame {i} has no "file_path" string')
    if 'transform_matrix' not in frame:
      raise DataError(f'{path}: frame {frame["file_path"]!r} has no "transform_matrix"')
    img = os.path.normpath(os.path.join(scene_dir, frame['file_path']))
    if not os.path.splitext(img)[1]:
      img += '.png'  # NeRF-synthetic names frames without their extension.
    if any(r[1] == img for r in rows):
      raise DataError(f'{path}: frame {i} repeats file_path {frame["file_path"]!r}')
    if not os.path.isfile(img):
      raise DataError(f'{path}: image of frame {frame["file_path"]!r} not found: {img}')
    try:
      c2w = np.asarray(frame['transform_matrix'], np.float64)
    except (TypeError, ValueError):
      c2w = np.zeros(0)
    if c2w.shape not in ((4, 4), (3, 4)) or not np.all(np.isfinite(c2w)):
      raise DataError(f'{path}: frame {frame["file_path"]!r}: transform_matrix is not a '
                      'finite 4x4 (or 3x4) matrix')
    rows.append((frame['file_path'], img, c2w[:3, :4], frame_camera(meta, frame, path)))
  if sort:
    rows.sort(key=lambda r: r[0])
  return [r[1] for r in rows], np.stack([r[2] for r in rows]), [r[3] for r in rows]


def shared_intrinsics(cams, shapes, paths, path):
  """The one (fx, fy, cx, cy, k1, k2, p1, p2) of all frames, checked against the image
  sizes; DataError naming the first frame that differs."""
  out = None
  for (w, h, intr, angle_x), (ih, iw), img in zip(cams, shapes, paths):
    if (w is not None and int(round(w)) != iw) or (h is not None and int(round(h)) != ih):
      raise DataError(f'{path}: {img} is {iw}x{ih} pixels but the file gives w x h = '
                      f'{w if w is None else int(round(w))}x'
                      f'{h if h is None else int(round(h))}')
    fx, fy, cx, cy = intr[:4]
    if fx is None:  # camera_angle_x only, without w: the image's width decides.
      fx = fy = 0.5 * iw / np.tan(0.5 * angle_x)
    full = (fx, fy, 0.5 * iw if cx is None else cx, 0.5 * ih if cy is None else cy) + intr[4:]
    if out is not None and not np.allclose(full, out, rtol=1e-6, atol=1e-9):
      raise DataError(f'{path}: the intrinsics of {img} differ from the first frame\'s '
                      '(one camera per scene is supported)')
    out = out or full
  return tuple(float(v) for v in out)


def focus_point(poses):
  """The point nearest (least squares) every camera's optical axis (-z in OpenGL)."""
  origins, axes = poses[:, :3, 3], -poses[:, :3, 2]
  axes = axes / np.linalg.norm(axes, axis=-1, keepdims=True)
  proj = np.eye(3)[None] - axes[:, :, None] * axes[:, None, :]  # onto each axis' normal
  return np.linalg.solve(proj.sum(0), np.einsum('nij,nj->i', proj, origins))


def normalize_poses(poses):
  """Camera centres moved so the focus point is the origin and scaled so the farthest
  camera is at distance 1 (rotations unchanged).

  Returns:
    (poses [N, 3, 4], the focus point [3] in the input's units, the scale).
  """
  centre = focus_point(poses)
  offsets = poses[:, :3, 3] - centre
  scale = 1. / max(float(np.max(np.linalg.norm(offsets, axis=-1))), 1e-12)
  out = np.array(poses, np.float64)
  out[:, :3, 3] = offsets * scale
  return out, centre, scale


def load_transforms(config) -> Scene:
  """Loads <Config.data_dir>/<Config.scene> in either layout of the module docstring."""
  scene_dir = os.path.join(config.data_dir, config.scene)
  single = os.path.join(scene_dir, 'transforms.json')
  train_file = os.path.join(scene_dir, 'transforms_train.json')
  if os.path.isfile(single):
    paths, poses, cams = read_frames(single)
    train_idx, val_idx, test_idx = split_of(config, poses, single)
    meta_path = single
  elif os.path.isfile(train_file):
    if config.train_view_selection != 'linspace':
      raise DataError(f'{train_file}: Config.train_view_selection applies to captures; a '
                      'Blender layout chooses its training frames by Config.blender_split')
    tr_paths, tr_poses, tr_cams = read_frames(train_file, sort=False)
    te_paths, te_poses, te_cams = read_frames(
        os.path.join(scene_dir, 'transforms_test.json'), sort=False)
    pick, keep = blender_split(len(tr_paths), len(te_paths), config, train_file)
    paths = [tr_paths[i] for i in pick] + [te_paths[i] for i in keep]
    poses = np.concatenate([tr_poses[pick], te_poses[keep]], 0)
    cams = [tr_cams[i] for i in pick] + [te_cams[i] for i in keep]
    train_idx = np.arange(len(pick))
    test_idx = np.arange(len(pick), len(paths))
    val_idx = np.arange(len(paths), len(paths) + config.val_views)
    if config.val_views:  # Evenly spaced frames of transforms_val.json.
      val_file = os.path.join(scene_dir, 'transforms_val.json')
      if not os.path.isfile(val_file):
        raise DataError(f'Config.val_views={config.val_views} but {val_file} is missing')
      va_paths, va_poses, va_cams = read_frames(val_file, sort=False)
      vpick = validation_frames(len(va_paths), config.val_views, val_file)
      paths += [va_paths[i] for i in vpick]
      poses = np.concatenate([poses, va_poses[vpick]], 0)
      cams += [va_cams[i] for i in vpick]
    meta_path = train_file
  else:
    raise DataError(f'no transforms.json (or transforms_train.json) in {scene_dir}')
  rgba = image_io.read_images(paths, keep_alpha=True)
  rgb, alpha = rgba[..., :3], rgba[..., 3:]
  images = rgb * alpha + (1. - alpha) if config.white_bkgd else rgb * alpha
  intr = shared_intrinsics(cams, [images.shape[1:3]] * len(paths), paths, meta_path)
  h, w = images.shape[1:3]
  fx, fy, cx, cy = intr[:4]
  pinhole = (abs(fx - fy) <= 1e-9 * fx and abs(cx - 0.5 * w) <= 1e-9 * w
             and abs(cy - 0.5 * h) <= 1e-9 * h and not any(intr[4:]))
  if config.undistort and not pinhole:  # Resampled to a centred pinhole camera.
    try:
      images, fx = undistort.undistort_images(images, intr)
    except ValueError as e:
      raise DataError(f'{meta_path}: Config.undistort: {e}') from None
    pinhole = True
  meta = _read_json(meta_path)
  half = 1.5 * (_number(meta, 'aabb_scale', meta_path, 'top-level')
                if 'aabb_scale' in meta else 1.)
  box, xyz, rgb = ((-half,) * 3, (half,) * 3), None, None
  if isinstance(meta.get('ply_file_path'), str):  # nerfstudio: SfM points, json's frame.
    xyz, rgb = read_points_ply(os.path.join(scene_dir, meta['ply_file_path']))
    if 'aabb_scale' not in meta:  # No box of its own: the points' box.
      box = points_box(xyz)
  return object_scene(config, config.scene, images, poses, fx, box, train_idx, test_idx,
                      intrinsics=None if pinhole else intr, val_idx=val_idx, points=xyz,
                      point_colors=rgb)


def object_scene(config, name, images, poses, focal, box, train_idx, test_idx,
                 intrinsics=None, depths=None, val_idx=(), points=None,
                 point_colors=None, point_views=None) -> Scene:
  """The Scene of a capture around an object (not forward-facing, no NDC).

  Args:
    config: Config (normalize_poses, near, far, white_bkgd).
    name: the scene's name. images: [N, H, W, 3] in [0, 1]. poses: [N, 3, 4] c2w.
    focal: pixels. box: ((lo x, y, z), (hi x, y, z)) holding the scene, world units.
    train_idx, test_idx: the split. intrinsics: (fx, fy, cx, cy, k1, k2, p1, p2) when
      not the centred pinhole of `focal`. depths: [N, H, W] true z-depths, or None.
    val_idx: the validation views. points, point_colors, point_views: the SfM points
      [P, 3] (world units), their colours [P, 3] in [0, 1] and [P, N] visibility, or None.

  Returns:
    The Scene; with Config.normalize_poses the cameras, the box, the points and the
    depths are moved and scaled together (normalize_poses).
  """
  box = np.array(box, np.float64)
  if config.normalize_poses:
    poses, centre, scale = normalize_poses(poses)
    box = (box - centre) * scale
    depths = None if depths is None else depths * scale
    points = None if points is None else (np.asarray(points) - centre) * scale
  box = tuple(tuple(float(v) for v in b) for b in box)
  return Scene(name=name, images=images.astype(np.float32),
               poses=poses.astype(np.float32), focal=float(focal), near=config.near,
               far=config.far, use_ndc=False, white_bkgd=config.white_bkgd,
               train_idx=np.asarray(train_idx), test_idx=np.asarray(test_idx),
               depths=None if depths is None else depths.astype(np.float32),
               forward_facing=False, bbox=box, world_bounds=box, intrinsics=intrinsics,
               val_idx=np.asarray(val_idx, np.int64),
               points=None if points is None else np.asarray(points, np.float32),
               point_colors=None if point_colors is None else np.asarray(point_colors,
                                                                         np.float32),
               point_views=point_views)
