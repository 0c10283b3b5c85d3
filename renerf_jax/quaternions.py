"""Unit quaternions for camera rotations: conversions, angles, SLERP, the mean.

Plain numpy (float64), independent of JAX. Quaternions are (w, x, y, z) with unit
norm. ``q`` and ``-q`` describe the same rotation; functions returning quaternions
canonicalise to ``w >= 0`` (except `slerp`, whose path stays continuous in t).
Rotation matrices act on column vectors. Angles are in radians.
"""

from typing import Any

import numpy as np

# Below this quaternion arc angle (radians) slerp falls back to a normalised
# linear interpolation; the two agree to O(angle**3) there.
_SLERP_MIN_ARC = 1e-6

_EPS = 1e-12


def _normalize(v: np.ndarray, axis: int = -1) -> np.ndarray:
  """Scales vectors to unit length.

  Args:
    v: [..., d] array.
    axis: axis holding the vector components.

  Returns:
    Array of the same shape with unit-norm vectors along `axis`.
  """
  return v / np.linalg.norm(v, axis=axis, keepdims=True)


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
