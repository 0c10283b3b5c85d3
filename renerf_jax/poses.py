"""Camera pose math for Re-Nerfing pseudo-view synthesis.

Everything here is plain numpy (float64) and independent of the rest of the
package, so it can be used from data loaders without touching JAX.

Conventions
-----------
* A camera-to-world matrix ``c2w`` has shape [..., 3, 4] (a [..., 4, 4]
  homogeneous matrix is accepted wherever a whole pose is expected and its
  last row is ignored). The rotation columns are the camera axes in world
  coordinates: x = right, y = up, z = back, i.e. the camera looks along its
  -z axis (OpenGL / NeRF convention). The last column is the camera position.
* Quaternions are (w, x, y, z) with unit norm. ``q`` and ``-q`` describe the
  same rotation; functions returning quaternions canonicalise to ``w >= 0``.
* Angles are in radians.
"""

from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

# Below this quaternion arc angle (radians) slerp falls back to a normalised
# linear interpolation; the two agree to O(angle**3) there.
_SLERP_MIN_ARC = 1e-6

# A bounding-box axis whose extent is below this fraction of the largest
# extent is considered degenerate (e.g. all cameras coplanar).
_DEGENERATE_EXTENT_RTOL = 1e-6

# Width given to a degenerate bounding-box axis, as a fraction of the largest
# extent of the box.
_DEGENERATE_AXIS_FRACTION = 0.1

_EPS = 1e-12

_SEQUENCING_METHODS = ('ordered', 'position', 'rotation')

AUGMENTATION_PRESETS: Dict[str, Tuple[float, ...]] = {
    '2x': (0.5,),
    '3x': (0.33, 0.66),
    '3x_b': (0.2, 0.8),
    '3x_c': (0.1, 0.9),
    '4x': (0.25, 0.5, 0.75),
    '5x': (0.2, 0.4, 0.6, 0.8),
    '7x': (0.1, 0.2, 0.4, 0.6, 0.8, 0.9),
    '11x': (0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95),
}
"""Interpolation-factor sets of the paper, keyed by augmentation name.

Each factor ``beta`` in (0, 1) yields one pseudo-view per neighbouring pair
of training cameras, at ``(1 - beta) * camera_i + beta * camera_j``.
"""


def _normalize(v: np.ndarray, axis: int = -1) -> np.ndarray:
  """Scales vectors to unit length.

  Args:
    v: [..., d] array.
    axis: axis holding the vector components.

  Returns:
    Array of the same shape with unit-norm vectors along `axis`.
  """
  return v / np.linalg.norm(v, axis=axis, keepdims=True)


def _as_c2w(c2w: Any) -> np.ndarray:
  """Converts poses to a float64 [..., 3, 4] array.

  Args:
    c2w: [..., 3, 4] or [..., 4, 4] camera-to-world matrices.

  Returns:
    [..., 3, 4] float64 array.

  Raises:
    ValueError: if the trailing shape is neither (3, 4) nor (4, 4).
  """
  c2w = np.asarray(c2w, dtype=np.float64)
  if c2w.ndim < 2 or c2w.shape[-1] != 4 or c2w.shape[-2] not in (3, 4):
    raise ValueError(
        f'expected camera-to-world matrices of shape [..., 3, 4] or '
        f'[..., 4, 4], got {c2w.shape}')
  return c2w[..., :3, :]


def _as_c2w_stack(c2w: Any) -> np.ndarray:
  """Converts a set of poses to a float64 [n, 3, 4] array.

  Args:
    c2w: [n, 3, 4] or [n, 4, 4] camera-to-world matrices.

  Returns:
    [n, 3, 4] float64 array.

  Raises:
    ValueError: if the input is not a stack of poses.
  """
  c2w = _as_c2w(c2w)
  if c2w.ndim != 3:
    raise ValueError(f'expected a stack of poses [n, 3, 4], got {c2w.shape}')
  return c2w


def rotation_to_quaternion(rot: Any) -> np.ndarray:
  """Converts rotation matrices to unit quaternions (Shepperd's method).

  Of the four equivalent formulas (dividing by 4w, 4x, 4y or 4z) the one
  with the largest divisor is used, which keeps the conversion accurate for
  every rotation, including those close to 180 degrees.

  Args:
    rot: [..., 3, 3] rotation matrices.

  Returns:
    [..., 4] unit quaternions (w, x, y, z), float64, with w >= 0.
  """
  rot = np.asarray(rot, dtype=np.float64)
  if rot.shape[-2:] != (3, 3):
    raise ValueError(f'expected rotations of shape [..., 3, 3], got {rot.shape}')
  r00, r01, r02 = rot[..., 0, 0], rot[..., 0, 1], rot[..., 0, 2]
  r10, r11, r12 = rot[..., 1, 0], rot[..., 1, 1], rot[..., 1, 2]
  r20, r21, r22 = rot[..., 2, 0], rot[..., 2, 1], rot[..., 2, 2]
  # 4 * (w^2, x^2, y^2, z^2) up to the common term 1.
  diag = np.stack([
      1.0 + r00 + r11 + r22,
      1.0 + r00 - r11 - r22,
      1.0 - r00 + r11 - r22,
      1.0 - r00 - r11 + r22,
  ], axis=-1)
  choice = np.argmax(diag, axis=-1)
  # s = 4 * (largest component); always >= 1 for a proper rotation.
  s = 2.0 * np.sqrt(np.maximum(np.max(diag, axis=-1), _EPS))
  candidates = np.stack([
      # Largest is w.
      np.stack([0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s],
               axis=-1),
      # Largest is x.
      np.stack([(r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s],
               axis=-1),
      # Largest is y.
      np.stack([(r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s],
               axis=-1),
      # Largest is z.
      np.stack([(r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s],
               axis=-1),
  ], axis=-2)
  quat = np.take_along_axis(candidates, choice[..., None, None], axis=-2)[..., 0,
                                                                          :]
  quat = np.where(quat[..., :1] < 0.0, -quat, quat)
  return _normalize(quat)


def quaternion_to_rotation(quat: Any) -> np.ndarray:
  """Converts quaternions to rotation matrices.

  Args:
    quat: [..., 4] quaternions (w, x, y, z); normalised before conversion.

  Returns:
    [..., 3, 3] float64 rotation matrices.
  """
  quat = np.asarray(quat, dtype=np.float64)
  if quat.shape[-1] != 4:
    raise ValueError(f'expected quaternions of shape [..., 4], got {quat.shape}')
  w, x, y, z = np.moveaxis(_normalize(quat), -1, 0)
  rows = [
      [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
      [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
      [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
  ]
  return np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)


def quaternion_angle(q0: Any, q1: Any) -> np.ndarray:
  """Angle of the relative rotation between two quaternions.

  Equals ``2 * arccos(|<q0, q1>|)`` but is computed as
  ``4 * atan2(|q0 - q1'|, |q0 + q1'|)`` with ``q1' = sign(<q0, q1>) q1``,
  which stays accurate for tiny and near-180-degree angles.

  Args:
    q0: [..., 4] quaternions (w, x, y, z); normalised internally.
    q1: [..., 4] quaternions, broadcastable against `q0`.

  Returns:
    [...] angles in [0, pi], float64.
  """
  q0 = _normalize(np.asarray(q0, dtype=np.float64))
  q1 = _normalize(np.asarray(q1, dtype=np.float64))
  dot = np.sum(q0 * q1, axis=-1, keepdims=True)
  q1 = np.where(dot < 0.0, -q1, q1)
  diff = np.linalg.norm(q0 - q1, axis=-1)
  summ = np.linalg.norm(q0 + q1, axis=-1)
  return 4.0 * np.arctan2(diff, summ)


def slerp(q0: Any, q1: Any, t: Any) -> np.ndarray:
  """Spherical linear interpolation between unit quaternions.

  Interpolates along the shorter arc (``q1`` is negated when
  ``<q0, q1> < 0``), so antipodal inputs (``q1 = -q0``, the same rotation)
  give that rotation for every ``t``. When the arc is tiny (below
  ``_SLERP_MIN_ARC`` radians) a normalised lerp is used. Endpoints are exact:
  ``t == 0`` returns (normalised) ``q0`` and ``t == 1`` returns (normalised,
  sign-adjusted) ``q1``.

  Args:
    q0: [..., 4] start quaternions (w, x, y, z); normalised internally.
    q1: [..., 4] end quaternions, broadcastable against `q0`.
    t: scalar or [...] interpolation parameter, broadcastable against the
      leading dims of `q0` / `q1`. Usually in [0, 1]; other values
      extrapolate along the same great circle.

  Returns:
    [..., 4] unit quaternions, float64 (not canonicalised to w >= 0, so that
    the path is continuous in t).
  """
  q0 = _normalize(np.asarray(q0, dtype=np.float64))
  q1 = _normalize(np.asarray(q1, dtype=np.float64))
  t = np.asarray(t, dtype=np.float64)[..., None]
  dot = np.sum(q0 * q1, axis=-1, keepdims=True)
  q1 = np.where(dot < 0.0, -q1, q1)
  # Half of the quaternion arc via the stable atan2 form; arc in [0, pi/2].
  arc = 2.0 * np.arctan2(
      np.linalg.norm(q0 - q1, axis=-1, keepdims=True),
      np.linalg.norm(q0 + q1, axis=-1, keepdims=True))
  tiny = arc < _SLERP_MIN_ARC
  safe_arc = np.where(tiny, 1.0, arc)
  sin_arc = np.sin(safe_arc)
  w0 = np.where(tiny, 1.0 - t, np.sin((1.0 - t) * safe_arc) / sin_arc)
  w1 = np.where(tiny, t, np.sin(t * safe_arc) / sin_arc)
  out = _normalize(w0 * q0 + w1 * q1)
  out = np.where(t == 0.0, q0, out)
  out = np.where(t == 1.0, q1, out)
  return out


def interpolate_pose(c2w0: Any, c2w1: Any, beta: Any) -> np.ndarray:
  """Interpolates between two camera poses.

  The position is interpolated linearly, ``(1 - beta) * p0 + beta * p1``
  (exact at beta = 0 and 1); the rotation by slerp of the two rotations'
  quaternions. The rotation goes through a quaternion, so the output
  rotation is always orthonormal with det +1 and equals the input rotation
  at the endpoints to float tolerance.

  Args:
    c2w0: [..., 3, 4] (or [..., 4, 4]) start camera-to-world matrices.
    c2w1: [..., 3, 4] (or [..., 4, 4]) end matrices, broadcastable.
    beta: scalar or [...] interpolation factor, broadcastable against the
      leading dims.

  Returns:
    [..., 3, 4] float64 camera-to-world matrices.
  """
  c2w0 = _as_c2w(c2w0)
  c2w1 = _as_c2w(c2w1)
  beta = np.asarray(beta, dtype=np.float64)
  q = slerp(rotation_to_quaternion(c2w0[..., :3]),
            rotation_to_quaternion(c2w1[..., :3]), beta)
  rot = quaternion_to_rotation(q)
  b = beta[..., None]
  pos = (1.0 - b) * c2w0[..., 3] + b * c2w1[..., 3]
  batch = np.broadcast_shapes(rot.shape[:-2], pos.shape[:-1])
  rot = np.broadcast_to(rot, batch + (3, 3))
  pos = np.broadcast_to(pos, batch + (3,))
  return np.concatenate([rot, pos[..., None]], axis=-1)


def _mean_quaternion(quats: np.ndarray) -> np.ndarray:
  """Sign-invariant mean of quaternions (Markley et al., 2007).

  Args:
    quats: [n, 4] unit quaternions.

  Returns:
    [4] unit quaternion maximising sum_i <q, q_i>^2, with w >= 0.
  """
  _, vecs = np.linalg.eigh(quats.T @ quats)
  mean = vecs[:, -1]
  return mean if mean[0] >= 0 else -mean


def sequence_cameras(c2w: Any, method: str = 'position') -> np.ndarray:
  """Orders training cameras into a chain of neighbours.

  * 'ordered': the given order, ``arange(n)``.
  * 'position': greedy nearest-neighbour chain on camera positions
    (Euclidean distance), starting from the camera farthest from the
    centroid of the positions.
  * 'rotation': greedy nearest-neighbour chain on camera orientations
    (angular distance ``2 * arccos(|<q_i, q_j>|)`` of the quaternions),
    starting from the camera with the largest angular distance to the mean
    rotation (the sign-invariant quaternion mean, i.e. the principal
    eigenvector of sum_i q_i q_i^T).

  Ties (equal distances) are broken towards the lowest camera index, so the
  result is deterministic.

  Args:
    c2w: [n, 3, 4] (or [n, 4, 4]) camera-to-world matrices.
    method: one of 'ordered', 'position', 'rotation'.

  Returns:
    [n] int64 permutation of arange(n).

  Raises:
    ValueError: for an unknown method.
  """
  if method not in _SEQUENCING_METHODS:
    raise ValueError(
        f'unknown camera sequencing method {method!r}; expected one of '
        f'{", ".join(repr(m) for m in _SEQUENCING_METHODS)}')
  c2w = _as_c2w_stack(c2w)
  n = c2w.shape[0]
  if method == 'ordered' or n < 2:
    return np.arange(n, dtype=np.int64)

  if method == 'position':
    pos = c2w[:, :, 3]
    dist = np.linalg.norm(pos[:, None] - pos[None], axis=-1)
    start = int(np.argmax(np.linalg.norm(pos - pos.mean(0), axis=-1)))
  else:
    quats = rotation_to_quaternion(c2w[:, :, :3])
    dist = quaternion_angle(quats[:, None], quats[None])
    start = int(np.argmax(quaternion_angle(quats, _mean_quaternion(quats))))

  order = [start]
  visited = np.zeros(n, dtype=bool)
  visited[start] = True
  for _ in range(n - 1):
    d = np.where(visited, np.inf, dist[order[-1]])
    nxt = int(np.argmin(d))
    order.append(nxt)
    visited[nxt] = True
  return np.asarray(order, dtype=np.int64)


def neighbour_pairs(order: Any) -> List[Tuple[int, int]]:
  """Consecutive camera pairs along a sequence.

  Args:
    order: [n] camera indices in sequence order (e.g. from
      `sequence_cameras`).

  Returns:
    List of n - 1 tuples (order[k], order[k + 1]) of Python ints.

  Raises:
    ValueError: if fewer than two cameras are given.
  """
  order = np.asarray(order).reshape(-1)
  n = order.shape[0]
  if n < 2:
    raise ValueError(
        f'need at least 2 training views to interpolate pseudo-views, got {n}')
  return [(int(order[k]), int(order[k + 1])) for k in range(n - 1)]


def resolve_factors(
    spec: Union[str, float, Sequence[float]]) -> Tuple[float, ...]:
  """Resolves an augmentation spec into interpolation factors.

  Args:
    spec: a key of `AUGMENTATION_PRESETS` (e.g. '3x'), or a number / sequence
      of numbers, each strictly between 0 and 1.

  Returns:
    Tuple of Python floats.

  Raises:
    ValueError: for an unknown preset name, an empty sequence or a factor
      outside the open interval (0, 1).
  """
  if isinstance(spec, str):
    if spec not in AUGMENTATION_PRESETS:
      raise ValueError(
          f'unknown augmentation preset {spec!r}; expected one of '
          f'{", ".join(AUGMENTATION_PRESETS)} or a sequence of factors in '
          f'(0, 1)')
    return AUGMENTATION_PRESETS[spec]
  values = np.atleast_1d(np.asarray(spec, dtype=np.float64))
  if values.ndim != 1 or values.size == 0:
    raise ValueError(
        f'interpolation factors must be a non-empty 1-D sequence, got {spec!r}')
  factors = tuple(float(v) for v in values)
  for f in factors:
    if not 0.0 < f < 1.0:
      raise ValueError(
          f'interpolation factor {f!r} is outside the open interval (0, 1)')
  return factors


def interpolated_poses(
    c2w: Any,
    factors: Union[str, Sequence[float]],
    sequencing: str = 'position',
) -> Tuple[np.ndarray, List[Dict[str, Any]]]:
  """Pseudo-view poses between neighbouring training cameras.

  Cameras are chained with `sequence_cameras`; for every consecutive pair
  (i, j) and every factor beta, the pose ``interpolate_pose(c2w[i], c2w[j],
  beta)`` is produced. Output is grouped by pair, then by factor.

  Args:
    c2w: [n, 3, 4] (or [n, 4, 4]) training camera-to-world matrices, n >= 2.
    factors: preset name or sequence of factors (see `resolve_factors`).
    sequencing: 'ordered', 'position' or 'rotation'.

  Returns:
    poses: [(n - 1) * len(factors), 3, 4] float64 camera-to-world matrices.
    meta: list of dicts {'pair': (i, j), 'beta': beta}, one per pose.

  Raises:
    ValueError: for fewer than two cameras, invalid factors or an unknown
      sequencing method.
  """
  c2w = _as_c2w_stack(c2w)
  betas = resolve_factors(factors)
  pairs = neighbour_pairs(sequence_cameras(c2w, sequencing))
  meta = [{'pair': pair, 'beta': b} for pair in pairs for b in betas]
  idx_i = np.array([m['pair'][0] for m in meta], dtype=np.int64)
  idx_j = np.array([m['pair'][1] for m in meta], dtype=np.int64)
  beta = np.array([m['beta'] for m in meta], dtype=np.float64)
  poses = interpolate_pose(c2w[idx_i], c2w[idx_j], beta)
  return poses, meta


def camera_path(c2w: Any, n_frames: int) -> np.ndarray:
  """A smooth there-and-back camera path through the given cameras (for videos).

  The cameras are chained by `sequence_cameras` (nearest neighbour on position); the
  path runs along the chain and back, its poses spaced evenly in path length (positions
  by lerp, rotations by SLERP, as the pseudo-views). If every camera sits at one
  position, the frames are spaced evenly per segment instead.

  Args:
    c2w: [n, 3, 4] (or [n, 4, 4]) camera-to-world matrices, n >= 1.
    n_frames: number of poses, >= 1.

  Returns:
    [n_frames, 3, 4] float64 camera-to-world matrices; the first is the first camera
    of the chain.
  """
  c2w = _as_c2w_stack(c2w)
  if n_frames < 1:
    raise ValueError(f'n_frames must be >= 1, got {n_frames}')
  chain = c2w[sequence_cameras(c2w, 'position')]
  if len(chain) == 1:
    return np.repeat(chain, n_frames, axis=0)
  seg = np.linalg.norm(np.diff(chain[:, :, 3], axis=0), axis=-1)
  if seg.sum() <= 0:
    seg = np.ones_like(seg)
  knots = np.concatenate([[0.], np.cumsum(seg)])
  # Ping-pong: s in [0, 2 L) maps to the path position L - |L - s|.
  s = np.linspace(0., 2. * knots[-1], n_frames, endpoint=False)
  s = knots[-1] - np.abs(knots[-1] - s)
  i = np.clip(np.searchsorted(knots, s, side='right') - 1, 0, len(seg) - 1)
  beta = np.clip((s - knots[i]) / np.maximum(seg[i], 1e-12), 0., 1.)
  return interpolate_pose(chain[i], chain[i + 1], beta)


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
