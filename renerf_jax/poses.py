"""Camera pose math for Re-Nerfing pseudo-view synthesis.

Pose interpolation, camera sequencing, the augmentation presets, the pseudo-view
poses between neighbouring cameras and a video camera path. The rotation math is
in `quaternions`, random unobserved poses are in `random_poses`.

Everything here is plain numpy (float64) and independent of the rest of the
package apart from `quaternions`, so it can be used from data loaders without
touching JAX.

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

from typing import Any, Dict, List, Sequence, Tuple, Union

import numpy as np

from renerf_jax.quaternions import (_mean_quaternion, quaternion_angle,
                                    quaternion_to_rotation,
                                    rotation_to_quaternion, slerp)

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
    spec: a key of `AUGMENTATION_PRESETS` (e.g. '3x'), a comma-separated string of
      numbers ('0.25,0.5') or a number / sequence of numbers, each strictly between 0
      and 1.

  Returns:
    Tuple of Python floats.

  Raises:
    ValueError: for an unknown preset name, an empty sequence or a factor
      outside the open interval (0, 1).
  """
  if isinstance(spec, str) and spec not in AUGMENTATION_PRESETS:
    try:  # '0.25,0.5': the factors themselves.
      spec = [float(v) for v in spec.split(',') if v.strip()]
    except ValueError:
      raise ValueError(
          f'unknown augmentation preset {spec!r}; expected one of '
          f'{", ".join(AUGMENTATION_PRESETS)} or a sequence of factors in '
          f'(0, 1)') from None
  if isinstance(spec, str):
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
