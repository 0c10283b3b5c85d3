"""Random unobserved camera poses (RegNeRF's depth-TV poses, random pseudo-views).

Plain numpy (float64), independent of JAX. Camera-to-world matrices follow the
conventions of `poses`: [..., 3, 4], columns x = right, y = up, z = back (the
camera looks along -z), last column the position.
"""

from typing import Any, Optional

import numpy as np

from renerf_jax.poses import _as_c2w_stack
from renerf_jax.quaternions import _EPS, _normalize

# A bounding-box axis whose extent is below this fraction of the largest
# extent is considered degenerate (e.g. all cameras coplanar).
_DEGENERATE_EXTENT_RTOL = 1e-6

# Width given to a degenerate bounding-box axis, as a fraction of the largest
# extent of the box.
_DEGENERATE_AXIS_FRACTION = 0.1


def look_at(position: Any, target: Any, up: Any) -> np.ndarray:
  """Camera-to-world matrices of cameras looking at a target.

  The camera's -z axis points from `position` to `target`; its y axis is
  `up` made orthogonal to the viewing direction. Where `up` is (nearly)
  parallel to the viewing direction, the world axis least aligned with the
  viewing direction is used as the up hint instead.

  Args:
    position: [..., 3] camera positions.
    target: [..., 3] points to look at, broadcastable.
    up: [..., 3] approximate up vectors, broadcastable.

  Returns:
    [..., 3, 4] float64 camera-to-world matrices (proper rotations).

  Raises:
    ValueError: if a position coincides with its target.
  """
  position = np.asarray(position, dtype=np.float64)
  target = np.asarray(target, dtype=np.float64)
  up = np.asarray(up, dtype=np.float64)
  position, target, up = np.broadcast_arrays(position, target, up)
  back = position - target
  back_norm = np.linalg.norm(back, axis=-1, keepdims=True)
  if np.any(back_norm < _EPS):
    raise ValueError('look_at: camera position coincides with its target')
  back = back / back_norm
  up = _normalize(up)
  right = np.cross(up, back)
  # Degenerate up hint: fall back to the world axis least aligned with back.
  degenerate = np.linalg.norm(right, axis=-1, keepdims=True) < 1e-6
  if np.any(degenerate):
    fallback = np.eye(3)[np.argmin(np.abs(back), axis=-1)]
    right = np.where(degenerate, np.cross(fallback, back), right)
  right = _normalize(right)
  cam_up = np.cross(back, right)
  return np.stack([right, cam_up, back, position], axis=-1)


def random_poses_forward_facing(
    c2w: Any,
    n: int,
    rng: np.random.Generator,
    focus_depth: Optional[float] = None,
    spread: float = 1.2,
) -> np.ndarray:
  """Random unobserved poses for forward-facing (LLFF-like) scenes.

  Positions are uniform in the axis-aligned bounding box of the training
  camera positions, scaled about their mean by `spread` (so slightly beyond
  the cameras for spread > 1). A degenerate box axis (extent below
  1e-6 of the largest extent, e.g. coplanar cameras) gets a total width of
  0.1 times the largest extent, centred on the mean; if every axis is
  degenerate (all cameras at one point) that width is 0.1 * focus_depth.
  Every camera looks at the focus point ``mean_position + focus_depth *
  mean_view_direction`` (mean of the cameras' -z axes), with up hint = mean
  of the cameras' y axes.

  Args:
    c2w: [m, 3, 4] (or [m, 4, 4]) training camera-to-world matrices.
    n: number of poses to return.
    rng: numpy random Generator.
    focus_depth: distance of the focus point along the mean viewing
      direction, in scene units. Defaults to 1.0, which suits LLFF scenes
      rescaled so the near bound is about 1; pass a scene-specific value
      (e.g. the mean depth) otherwise.
    spread: scale of the sampling box about the mean camera position.

  Returns:
    [n, 3, 4] float64 camera-to-world matrices.

  Raises:
    ValueError: if the mean viewing direction or the mean up vector vanishes.
  """
  c2w = _as_c2w_stack(c2w)
  if focus_depth is None:
    focus_depth = 1.0
  pos = c2w[:, :, 3]
  mean = pos.mean(axis=0)
  lo = mean + spread * (pos.min(axis=0) - mean)
  hi = mean + spread * (pos.max(axis=0) - mean)
  extent = hi - lo
  largest = float(extent.max())
  degenerate = extent <= _DEGENERATE_EXTENT_RTOL * largest
  if largest <= _EPS:
    half_width = 0.5 * _DEGENERATE_AXIS_FRACTION * abs(focus_depth)
    degenerate[:] = True
  else:
    half_width = 0.5 * _DEGENERATE_AXIS_FRACTION * largest
  lo = np.where(degenerate, mean - half_width, lo)
  hi = np.where(degenerate, mean + half_width, hi)

  view_dir = -c2w[:, :, 2].mean(axis=0)
  up = c2w[:, :, 1].mean(axis=0)
  if np.linalg.norm(view_dir) < 1e-6 or np.linalg.norm(up) < 1e-6:
    raise ValueError('training cameras have no consistent mean viewing '
                     'direction / up vector; not a forward-facing scene')
  view_dir = _normalize(view_dir)
  focus = mean + focus_depth * view_dir

  positions = rng.uniform(lo, hi, size=(n, 3))
  return look_at(positions, focus, up)


def random_poses_sphere(
    c2w: Any,
    n: int,
    rng: np.random.Generator,
    center: Optional[Any] = None,
) -> np.ndarray:
  """Random unobserved poses on a sphere around the scene (360 scenes).

  The sphere is centred on `center` with radius equal to the training
  cameras' mean distance from it. Positions are uniform in area over the
  band of the sphere between the lowest and the highest elevation of the
  training cameras (elevation measured from the xy-plane through `center`,
  with +z as world up as in Blender scenes), at any azimuth. Each camera
  looks at the centre with world up (0, 0, 1) (see `look_at` for the
  straight-up/down case).

  Args:
    c2w: [m, 3, 4] (or [m, 4, 4]) training camera-to-world matrices.
    n: number of poses to return.
    rng: numpy random Generator.
    center: [3] sphere centre; defaults to the origin.

  Returns:
    [n, 3, 4] float64 camera-to-world matrices.

  Raises:
    ValueError: if the cameras are at the centre (zero radius).
  """
  c2w = _as_c2w_stack(c2w)
  center = np.zeros(3) if center is None else np.asarray(center, np.float64)
  rel = c2w[:, :, 3] - center
  dist = np.linalg.norm(rel, axis=-1)
  if np.any(dist < _EPS):
    raise ValueError('a training camera lies at the sphere centre')
  radius = float(dist.mean())
  sin_elev = np.clip(rel[:, 2] / dist, -1.0, 1.0)
  z = rng.uniform(sin_elev.min(), sin_elev.max(), size=n)
  azimuth = rng.uniform(0.0, 2.0 * np.pi, size=n)
  horiz = np.sqrt(np.maximum(1.0 - z * z, 0.0))
  dirs = np.stack([horiz * np.cos(azimuth), horiz * np.sin(azimuth), z], -1)
  positions = center + radius * dirs
  return look_at(positions, center, np.array([0.0, 0.0, 1.0]))


def random_unobserved_poses(
    train_c2w: Any,
    n: int,
    rng: np.random.Generator,
    forward_facing: bool,
    focus_depth: Optional[float] = None,
    spread: float = 1.0,
) -> np.ndarray:
  """n random unobserved poses of a scene, by its kind of capture.

  Forward-facing scenes draw `random_poses_forward_facing` (within and slightly beyond
  the training cameras, looking at the focus point), 360 scenes `random_poses_sphere`
  (the training cameras' sphere). The depth-TV poses and the random pseudo-view targets
  both come from here.

  Args:
    train_c2w: [m, 3, 4] training camera-to-world matrices.
    n: number of poses. rng: numpy random Generator.
    forward_facing: the scene's kind (Scene.forward_facing).
    focus_depth: forward-facing scenes' focus depth (Scene.focus_depth).
    spread: forward-facing box spread (Config.random_pose_spread).

  Returns:
    [n, 3, 4] float64 camera-to-world matrices.
  """
  if forward_facing:
    return random_poses_forward_facing(train_c2w, n, rng, focus_depth=focus_depth,
                                       spread=spread)
  return random_poses_sphere(train_c2w, n, rng)
