"""Tests for renerf_jax.quaternions."""

import numpy as np
import pytest

from pose_helpers import (ADVERSARIAL, assert_proper_rotation, random_rotations,
                          random_unit_vectors, rodrigues)
from renerf_jax import quaternions


# ----------------------------------------------------------------- helpers


def axis_angle_quat(axis, angle):
  """Quaternion (w, x, y, z) of a rotation about `axis` by `angle`."""
  axis = np.asarray(axis, np.float64)
  axis = axis / np.linalg.norm(axis)
  return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])


def assert_same_quat(q, q_ref, atol=1e-12):
  """q equals q_ref up to the sign ambiguity q ~ -q."""
  q = np.asarray(q)
  q_ref = np.asarray(q_ref)
  err = np.minimum(np.abs(q - q_ref).max(-1), np.abs(q + q_ref).max(-1))
  assert np.all(err < atol), err.max()


# ----------------------------------------------------- quaternion <-> matrix


def test_quaternion_to_rotation_matches_rodrigues():
  rng = np.random.default_rng(0)
  axes = random_unit_vectors(rng, 50)
  angles = rng.uniform(-np.pi, np.pi, 50)
  quats = np.stack([axis_angle_quat(a, t) for a, t in zip(axes, angles)])
  expected = np.stack([rodrigues(a, t) for a, t in zip(axes, angles)])
  np.testing.assert_allclose(quaternions.quaternion_to_rotation(quats), expected,
                             atol=1e-12)
  # Non-unit input is normalised first.
  np.testing.assert_allclose(quaternions.quaternion_to_rotation(3.0 * quats),
                             expected, atol=1e-12)


def test_rotation_quaternion_round_trip_random():
  rng = np.random.default_rng(1)
  rots = random_rotations(rng, 500).reshape(20, 25, 3, 3)
  quats = quaternions.rotation_to_quaternion(rots)
  assert quats.shape == (20, 25, 4)
  np.testing.assert_allclose(np.linalg.norm(quats, axis=-1), 1.0, atol=1e-12)
  assert np.all(quats[..., 0] >= 0.0)
  np.testing.assert_allclose(quaternions.quaternion_to_rotation(quats), rots,
                             atol=1e-12)


@pytest.mark.parametrize('axis,angle', ADVERSARIAL)
def test_rotation_to_quaternion_adversarial(axis, angle):
  rot = rodrigues(axis, angle)
  quat = quaternions.rotation_to_quaternion(rot)
  assert quat.shape == (4,)
  assert quat[0] >= 0.0
  np.testing.assert_allclose(np.linalg.norm(quat), 1.0, atol=1e-14)
  assert_same_quat(quat, axis_angle_quat(axis, angle), atol=1e-12)
  np.testing.assert_allclose(quaternions.quaternion_to_rotation(quat), rot,
                             atol=1e-12)


def test_rotation_to_quaternion_w_nonnegative_near_half_turn():
  # Slightly past 180 degrees: the closed form has w < 0, output must flip.
  rot = rodrigues([0.2, 0.5, -0.3], np.pi + 1e-3)
  quat = quaternions.rotation_to_quaternion(rot)
  assert quat[0] >= 0.0
  np.testing.assert_allclose(quaternions.quaternion_to_rotation(quat), rot,
                             atol=1e-12)


def test_quaternion_angle_matches_rotation_angle():
  rng = np.random.default_rng(2)
  for _ in range(20):
    axis = random_unit_vectors(rng, 1)[0]
    angle = rng.uniform(0.0, np.pi)
    q0 = quaternions.rotation_to_quaternion(random_rotations(rng, 1)[0])
    q1 = quaternions.rotation_to_quaternion(
        quaternions.quaternion_to_rotation(q0) @ rodrigues(axis, angle))
    np.testing.assert_allclose(quaternions.quaternion_angle(q0, q1), angle,
                               atol=1e-9)
    np.testing.assert_allclose(quaternions.quaternion_angle(q0, -q1), angle,
                               atol=1e-9)
  tiny = axis_angle_quat([1.0, 0.0, 0.0], 1e-9)
  np.testing.assert_allclose(
      quaternions.quaternion_angle(np.array([1.0, 0, 0, 0]), tiny), 1e-9, rtol=1e-6)


# -------------------------------------------------------------------- slerp


def test_slerp_identical_inputs():
  q = axis_angle_quat([0.1, 0.7, -0.2], 1.1)
  for t in [0.0, 0.3, 0.5, 1.0]:
    out = quaternions.slerp(q, q, t)
    assert np.all(np.isfinite(out))
    np.testing.assert_allclose(out, q, atol=1e-15)


def test_slerp_nearly_identical_inputs():
  axis = np.array([0.3, -0.5, 0.8])
  q0 = axis_angle_quat(axis, 0.4)
  q1 = axis_angle_quat(axis, 0.4 + 1e-9)
  t = np.linspace(0.0, 1.0, 11)
  out = quaternions.slerp(q0, q1, t)
  assert out.shape == (11, 4)
  assert np.all(np.isfinite(out))
  np.testing.assert_allclose(np.linalg.norm(out, axis=-1), 1.0, atol=1e-15)
  expected = np.stack([axis_angle_quat(axis, 0.4 + ti * 1e-9) for ti in t])
  np.testing.assert_allclose(out, expected, atol=1e-15)


def test_slerp_antipodal_is_same_rotation():
  q = axis_angle_quat([0.2, 0.3, 0.9], 2.0)
  rot = quaternions.quaternion_to_rotation(q)
  t = np.linspace(0.0, 1.0, 7)
  out = quaternions.slerp(q, -q, t)
  assert np.all(np.isfinite(out))
  np.testing.assert_allclose(
      quaternions.quaternion_to_rotation(out), np.broadcast_to(rot, (7, 3, 3)),
      atol=1e-12)


def test_slerp_half_turn_apart():
  # Rotations 180 degrees apart: <q0, q1> = 0.
  q0 = axis_angle_quat([0.0, 0.0, 1.0], 0.3)
  q1 = quaternions.rotation_to_quaternion(
      quaternions.quaternion_to_rotation(q0) @ rodrigues([1.0, 2.0, 0.5], np.pi))
  np.testing.assert_allclose(np.dot(q0, q1), 0.0, atol=1e-12)
  t = np.linspace(0.0, 1.0, 9)
  out = quaternions.slerp(q0, q1, t)
  assert np.all(np.isfinite(out))
  rots = quaternions.quaternion_to_rotation(out)
  assert_proper_rotation(rots)
  np.testing.assert_allclose(quaternions.quaternion_angle(q0, out), t * np.pi,
                             atol=1e-9)


def test_slerp_exact_endpoints():
  rng = np.random.default_rng(3)
  q0 = quaternions.rotation_to_quaternion(random_rotations(rng, 30))
  q1 = quaternions.rotation_to_quaternion(random_rotations(rng, 30))
  q0 = q0 / np.linalg.norm(q0, axis=-1, keepdims=True)
  start = quaternions.slerp(q0, q1, 0.0)
  end = quaternions.slerp(q0, q1, 1.0)
  np.testing.assert_array_equal(start, q0)
  np.testing.assert_allclose(quaternions.quaternion_to_rotation(end),
                             quaternions.quaternion_to_rotation(q1), atol=1e-14)
  # Per-element t broadcasting against the batch.
  t = np.where(np.arange(30) % 2 == 0, 0.0, 1.0)
  mixed = quaternions.slerp(q0, q1, t)
  np.testing.assert_array_equal(mixed[::2], q0[::2])
  np.testing.assert_array_equal(mixed[1::2], end[1::2])


def test_slerp_constant_angular_speed_and_unit_norm():
  rng = np.random.default_rng(4)
  t = np.linspace(0.0, 1.0, 21)
  for _ in range(20):
    q0, q1 = quaternions.rotation_to_quaternion(random_rotations(rng, 2))
    if rng.uniform() < 0.5:
      q1 = -q1  # must still take the shorter arc
    total = quaternions.quaternion_angle(q0, q1)
    out = quaternions.slerp(q0, q1, t)
    np.testing.assert_allclose(np.linalg.norm(out, axis=-1), 1.0, atol=1e-14)
    np.testing.assert_allclose(quaternions.quaternion_angle(q0, out), t * total,
                               atol=1e-9)
    np.testing.assert_allclose(quaternions.quaternion_angle(out, q1),
                               (1.0 - t) * total, atol=1e-9)


def test_slerp_batched_t_shape():
  q0 = axis_angle_quat([1.0, 0.0, 0.0], 0.0)
  q1 = axis_angle_quat([1.0, 0.0, 0.0], 1.0)
  out = quaternions.slerp(q0, q1, np.full((2, 3), 0.5))
  assert out.shape == (2, 3, 4)
  np.testing.assert_allclose(out, np.broadcast_to(
      axis_angle_quat([1.0, 0.0, 0.0], 0.5), (2, 3, 4)), atol=1e-14)
