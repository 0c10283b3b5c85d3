"""Tests for renerf_jax.poses."""

import numpy as np
import pytest

from renerf_jax import poses

ATOL = 1e-9


# ----------------------------------------------------------------- helpers


def rodrigues(axis, angle):
  """Rotation matrix about unit `axis` by `angle` (closed form)."""
  axis = np.asarray(axis, np.float64)
  axis = axis / np.linalg.norm(axis)
  k = np.array([[0.0, -axis[2], axis[1]],
                [axis[2], 0.0, -axis[0]],
                [-axis[1], axis[0], 0.0]])
  return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def axis_angle_quat(axis, angle):
  """Quaternion (w, x, y, z) of a rotation about `axis` by `angle`."""
  axis = np.asarray(axis, np.float64)
  axis = axis / np.linalg.norm(axis)
  return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])


def random_rotations(rng, n):
  q = rng.normal(size=(n, 4))
  return poses.quaternion_to_rotation(q)


def random_unit_vectors(rng, n):
  v = rng.normal(size=(n, 3))
  return v / np.linalg.norm(v, axis=-1, keepdims=True)


def assert_proper_rotation(rot, atol=1e-9):
  rot = np.asarray(rot)
  eye = np.broadcast_to(np.eye(3), rot.shape)
  np.testing.assert_allclose(np.swapaxes(rot, -1, -2) @ rot, eye, atol=atol)
  np.testing.assert_allclose(np.linalg.det(rot), 1.0, atol=atol)


def assert_same_quat(q, q_ref, atol=1e-12):
  """q equals q_ref up to the sign ambiguity q ~ -q."""
  q = np.asarray(q)
  q_ref = np.asarray(q_ref)
  err = np.minimum(np.abs(q - q_ref).max(-1), np.abs(q + q_ref).max(-1))
  assert np.all(err < atol), err.max()


def yaw_pose(yaw, position):
  rot = rodrigues([0.0, 1.0, 0.0], yaw)
  return np.concatenate([rot, np.asarray(position, float)[:, None]], axis=1)


def forward_facing_rig(rng, n=9):
  """Cameras roughly in the z=0 plane looking along -z, slightly jittered."""
  pos = np.concatenate([rng.uniform(-0.5, 0.5, (n, 2)),
                        rng.uniform(-0.05, 0.05, (n, 1))], axis=1)
  rots = [rodrigues(a, 0.1 * rng.uniform())
          for a in random_unit_vectors(rng, n)]
  return np.concatenate([np.stack(rots), pos[:, :, None]], axis=2)


ADVERSARIAL = [
    (np.array([1.0, 0.0, 0.0]), 0.0),
    (np.array([1.0, 0.0, 0.0]), np.pi),
    (np.array([0.0, 1.0, 0.0]), np.pi),
    (np.array([0.0, 0.0, 1.0]), np.pi),
    (np.array([1.0, 1.0, 0.0]), np.pi),
    (np.array([0.3, -0.4, 0.8]), np.pi),
    (np.array([-0.2, 0.9, 0.1]), np.pi),
    (np.array([0.6, 0.2, -0.7]), 1e-8),
    (np.array([0.0, 0.0, 1.0]), 1e-8),
    (np.array([0.6, 0.2, -0.7]), np.pi - 1e-7),
    (np.array([1.0, 0.0, 0.0]), np.pi - 1e-7),
    (np.array([0.0, 1.0, 0.0]), np.pi / 2),
]


# ----------------------------------------------------- quaternion <-> matrix


def test_quaternion_to_rotation_matches_rodrigues():
  rng = np.random.default_rng(0)
  axes = random_unit_vectors(rng, 50)
  angles = rng.uniform(-np.pi, np.pi, 50)
  quats = np.stack([axis_angle_quat(a, t) for a, t in zip(axes, angles)])
  expected = np.stack([rodrigues(a, t) for a, t in zip(axes, angles)])
  np.testing.assert_allclose(poses.quaternion_to_rotation(quats), expected,
                             atol=1e-12)
  # Non-unit input is normalised first.
  np.testing.assert_allclose(poses.quaternion_to_rotation(3.0 * quats),
                             expected, atol=1e-12)


def test_rotation_quaternion_round_trip_random():
  rng = np.random.default_rng(1)
  rots = random_rotations(rng, 500).reshape(20, 25, 3, 3)
  quats = poses.rotation_to_quaternion(rots)
  assert quats.shape == (20, 25, 4)
  np.testing.assert_allclose(np.linalg.norm(quats, axis=-1), 1.0, atol=1e-12)
  assert np.all(quats[..., 0] >= 0.0)
  np.testing.assert_allclose(poses.quaternion_to_rotation(quats), rots,
                             atol=1e-12)


@pytest.mark.parametrize('axis,angle', ADVERSARIAL)
def test_rotation_to_quaternion_adversarial(axis, angle):
  rot = rodrigues(axis, angle)
  quat = poses.rotation_to_quaternion(rot)
  assert quat.shape == (4,)
  assert quat[0] >= 0.0
  np.testing.assert_allclose(np.linalg.norm(quat), 1.0, atol=1e-14)
  assert_same_quat(quat, axis_angle_quat(axis, angle), atol=1e-12)
  np.testing.assert_allclose(poses.quaternion_to_rotation(quat), rot,
                             atol=1e-12)


def test_rotation_to_quaternion_w_nonnegative_near_half_turn():
  # Slightly past 180 degrees: the closed form has w < 0, output must flip.
  rot = rodrigues([0.2, 0.5, -0.3], np.pi + 1e-3)
  quat = poses.rotation_to_quaternion(rot)
  assert quat[0] >= 0.0
  np.testing.assert_allclose(poses.quaternion_to_rotation(quat), rot,
                             atol=1e-12)


def test_quaternion_angle_matches_rotation_angle():
  rng = np.random.default_rng(2)
  for _ in range(20):
    axis = random_unit_vectors(rng, 1)[0]
    angle = rng.uniform(0.0, np.pi)
    q0 = poses.rotation_to_quaternion(random_rotations(rng, 1)[0])
    q1 = poses.rotation_to_quaternion(
        poses.quaternion_to_rotation(q0) @ rodrigues(axis, angle))
    np.testing.assert_allclose(poses.quaternion_angle(q0, q1), angle,
                               atol=1e-9)
    np.testing.assert_allclose(poses.quaternion_angle(q0, -q1), angle,
                               atol=1e-9)
  tiny = axis_angle_quat([1.0, 0.0, 0.0], 1e-9)
  np.testing.assert_allclose(
      poses.quaternion_angle(np.array([1.0, 0, 0, 0]), tiny), 1e-9, rtol=1e-6)


# -------------------------------------------------------------------- slerp


def test_slerp_identical_inputs():
  q = axis_angle_quat([0.1, 0.7, -0.2], 1.1)
  for t in [0.0, 0.3, 0.5, 1.0]:
    out = poses.slerp(q, q, t)
    assert np.all(np.isfinite(out))
    np.testing.assert_allclose(out, q, atol=1e-15)


def test_slerp_nearly_identical_inputs():
  axis = np.array([0.3, -0.5, 0.8])
  q0 = axis_angle_quat(axis, 0.4)
  q1 = axis_angle_quat(axis, 0.4 + 1e-9)
  t = np.linspace(0.0, 1.0, 11)
  out = poses.slerp(q0, q1, t)
  assert out.shape == (11, 4)
  assert np.all(np.isfinite(out))
  np.testing.assert_allclose(np.linalg.norm(out, axis=-1), 1.0, atol=1e-15)
  expected = np.stack([axis_angle_quat(axis, 0.4 + ti * 1e-9) for ti in t])
  np.testing.assert_allclose(out, expected, atol=1e-15)


def test_slerp_antipodal_is_same_rotation():
  q = axis_angle_quat([0.2, 0.3, 0.9], 2.0)
  rot = poses.quaternion_to_rotation(q)
  t = np.linspace(0.0, 1.0, 7)
  out = poses.slerp(q, -q, t)
  assert np.all(np.isfinite(out))
  np.testing.assert_allclose(
      poses.quaternion_to_rotation(out), np.broadcast_to(rot, (7, 3, 3)),
      atol=1e-12)


def test_slerp_half_turn_apart():
  # Rotations 180 degrees apart: <q0, q1> = 0.
  q0 = axis_angle_quat([0.0, 0.0, 1.0], 0.3)
  q1 = poses.rotation_to_quaternion(
      poses.quaternion_to_rotation(q0) @ rodrigues([1.0, 2.0, 0.5], np.pi))
  np.testing.assert_allclose(np.dot(q0, q1), 0.0, atol=1e-12)
  t = np.linspace(0.0, 1.0, 9)
  out = poses.slerp(q0, q1, t)
  assert np.all(np.isfinite(out))
  rots = poses.quaternion_to_rotation(out)
  assert_proper_rotation(rots)
  np.testing.assert_allclose(poses.quaternion_angle(q0, out), t * np.pi,
                             atol=1e-9)


def test_slerp_exact_endpoints():
  rng = np.random.default_rng(3)
  q0 = poses.rotation_to_quaternion(random_rotations(rng, 30))
  q1 = poses.rotation_to_quaternion(random_rotations(rng, 30))
  q0 = q0 / np.linalg.norm(q0, axis=-1, keepdims=True)
  start = poses.slerp(q0, q1, 0.0)
  end = poses.slerp(q0, q1, 1.0)
  np.testing.assert_array_equal(start, q0)
  np.testing.assert_allclose(poses.quaternion_to_rotation(end),
                             poses.quaternion_to_rotation(q1), atol=1e-14)
  # Per-element t broadcasting against the batch.
  t = np.where(np.arange(30) % 2 == 0, 0.0, 1.0)
  mixed = poses.slerp(q0, q1, t)
  np.testing.assert_array_equal(mixed[::2], q0[::2])
  np.testing.assert_array_equal(mixed[1::2], end[1::2])


def test_slerp_constant_angular_speed_and_unit_norm():
  rng = np.random.default_rng(4)
  t = np.linspace(0.0, 1.0, 21)
  for _ in range(20):
    q0, q1 = poses.rotation_to_quaternion(random_rotations(rng, 2))
    if rng.uniform() < 0.5:
      q1 = -q1  # must still take the shorter arc
    total = poses.quaternion_angle(q0, q1)
    out = poses.slerp(q0, q1, t)
    np.testing.assert_allclose(np.linalg.norm(out, axis=-1), 1.0, atol=1e-14)
    np.testing.assert_allclose(poses.quaternion_angle(q0, out), t * total,
                               atol=1e-9)
    np.testing.assert_allclose(poses.quaternion_angle(out, q1),
                               (1.0 - t) * total, atol=1e-9)


def test_slerp_batched_t_shape():
  q0 = axis_angle_quat([1.0, 0.0, 0.0], 0.0)
  q1 = axis_angle_quat([1.0, 0.0, 0.0], 1.0)
  out = poses.slerp(q0, q1, np.full((2, 3), 0.5))
  assert out.shape == (2, 3, 4)
  np.testing.assert_allclose(out, np.broadcast_to(
      axis_angle_quat([1.0, 0.0, 0.0], 0.5), (2, 3, 4)), atol=1e-14)


# --------------------------------------------------------- interpolate_pose


def test_interpolate_pose_random_valid_and_linear_positions():
  rng = np.random.default_rng(5)
  rots = random_rotations(rng, 40)
  pos = rng.normal(size=(40, 3))
  c2w = np.concatenate([rots, pos[:, :, None]], axis=2)
  a, b = c2w[:20], c2w[20:]
  for beta in [0.0, 0.1, 0.33, 0.5, 0.9, 1.0]:
    out = poses.interpolate_pose(a, b, beta)
    assert out.shape == (20, 3, 4)
    assert_proper_rotation(out[..., :3])
    np.testing.assert_allclose(out[..., 3],
                               (1 - beta) * pos[:20] + beta * pos[20:],
                               atol=1e-14)
  np.testing.assert_array_equal(poses.interpolate_pose(a, b, 0.0)[..., 3],
                                a[..., 3])
  np.testing.assert_array_equal(poses.interpolate_pose(a, b, 1.0)[..., 3],
                                b[..., 3])
  np.testing.assert_allclose(poses.interpolate_pose(a, b, 0.0), a, atol=1e-12)
  np.testing.assert_allclose(poses.interpolate_pose(a, b, 1.0), b, atol=1e-12)


@pytest.mark.parametrize('axis,angle', ADVERSARIAL)
def test_interpolate_pose_adversarial(axis, angle):
  c2w0 = np.concatenate([np.eye(3), np.zeros((3, 1))], axis=1)
  c2w1 = np.concatenate([rodrigues(axis, angle), np.ones((3, 1))], axis=1)
  for beta in [0.0, 0.25, 0.5, 0.75, 1.0]:
    out = poses.interpolate_pose(c2w0, c2w1, beta)
    assert out.shape == (3, 4)
    assert np.all(np.isfinite(out))
    assert_proper_rotation(out[:, :3])
    np.testing.assert_allclose(out[:, 3], beta * np.ones(3), atol=1e-15)
    q = poses.rotation_to_quaternion(out[:, :3])
    np.testing.assert_allclose(
        poses.quaternion_angle(np.array([1.0, 0, 0, 0]), q), beta * angle,
        atol=1e-7)
  np.testing.assert_allclose(poses.interpolate_pose(c2w0, c2w1, 1.0), c2w1,
                             atol=1e-12)


def test_interpolate_pose_accepts_homogeneous():
  c2w0 = np.eye(4)
  c2w1 = np.eye(4)
  c2w1[:3, :3] = rodrigues([0, 1, 0], 0.8)
  c2w1[:3, 3] = [1.0, 2.0, 3.0]
  out = poses.interpolate_pose(c2w0, c2w1, 0.5)
  assert out.shape == (3, 4)
  np.testing.assert_allclose(out[:, :3], rodrigues([0, 1, 0], 0.4), atol=1e-12)
  np.testing.assert_allclose(out[:, 3], [0.5, 1.0, 1.5])


# --------------------------------------------------------------- sequencing


def test_sequence_cameras_ordered():
  c2w = np.stack([yaw_pose(0.1 * i, [i, 0, 0]) for i in range(5)])
  np.testing.assert_array_equal(poses.sequence_cameras(c2w, 'ordered'),
                                np.arange(5))


def _assert_recovers_line(order, perm):
  recovered = perm[order]  # original (sorted) index of each visited camera
  n = len(perm)
  assert sorted(order.tolist()) == list(range(n))
  assert (recovered.tolist() == list(range(n))
          or recovered.tolist() == list(range(n))[::-1]), recovered


def test_sequence_cameras_position_recovers_shuffled_line():
  rng = np.random.default_rng(6)
  n = 12
  direction = np.array([1.0, 2.0, -0.5])
  # Non-uniform but monotone spacing along the line.
  s = np.cumsum(rng.uniform(0.5, 1.5, n))
  perm = rng.permutation(n)
  positions = (s[perm])[:, None] * direction
  rots = random_rotations(rng, n)  # must be ignored by 'position'
  c2w = np.concatenate([rots, positions[:, :, None]], axis=2)
  order = poses.sequence_cameras(c2w, 'position')
  assert order.dtype.kind == 'i'
  _assert_recovers_line(order, perm)


def test_sequence_cameras_rotation_recovers_shuffled_yaws():
  rng = np.random.default_rng(7)
  n = 10
  yaws = np.deg2rad(np.cumsum(rng.uniform(5.0, 15.0, n)) - 60.0)
  perm = rng.permutation(n)
  c2w = np.stack([yaw_pose(yaws[p], rng.normal(size=3)) for p in perm])
  order = poses.sequence_cameras(c2w, 'rotation')
  _assert_recovers_line(order, perm)


def test_sequence_cameras_unknown_method():
  c2w = np.stack([yaw_pose(0.0, [i, 0, 0]) for i in range(3)])
  with pytest.raises(ValueError, match='sequencing method'):
    poses.sequence_cameras(c2w, 'random')


def test_neighbour_pairs():
  assert poses.neighbour_pairs(np.array([2, 0, 1])) == [(2, 0), (0, 1)]
  pairs = poses.neighbour_pairs([0, 1])
  assert pairs == [(0, 1)]
  assert all(type(i) is int for pair in pairs for i in pair)
  with pytest.raises(ValueError, match='need at least 2 training views'):
    poses.neighbour_pairs([0])
  with pytest.raises(ValueError, match='got 0'):
    poses.neighbour_pairs([])


# ------------------------------------------------------------------ presets


@pytest.mark.parametrize('name,length', [('2x', 1), ('3x', 2), ('3x_b', 2),
                                         ('3x_c', 2), ('4x', 3), ('5x', 4),
                                         ('7x', 6), ('11x', 11)])
def test_presets_lengths(name, length):
  factors = poses.AUGMENTATION_PRESETS[name]
  assert len(factors) == length
  assert all(0.0 < f < 1.0 for f in factors)
  assert list(factors) == sorted(factors)
  assert poses.resolve_factors(name) == factors


def test_presets_values():
  assert poses.AUGMENTATION_PRESETS['3x'] == (0.33, 0.66)
  assert poses.AUGMENTATION_PRESETS['3x_c'] == (0.1, 0.9)
  assert poses.AUGMENTATION_PRESETS['4x'] == (0.25, 0.5, 0.75)


def test_resolve_factors_sequences():
  assert poses.resolve_factors([0.25, 0.75]) == (0.25, 0.75)
  assert poses.resolve_factors(np.array([0.5])) == (0.5,)
  assert poses.resolve_factors((0.1,)) == (0.1,)


@pytest.mark.parametrize('bad', [0.0, 1.0, 1.5, -0.2])
def test_resolve_factors_rejects_out_of_range(bad):
  with pytest.raises(ValueError, match=repr(float(bad)).replace('.', r'\.')):
    poses.resolve_factors([0.5, bad])


def test_resolve_factors_rejects_unknown_and_empty():
  with pytest.raises(ValueError, match='unknown augmentation preset'):
    poses.resolve_factors('6x')
  with pytest.raises(ValueError):
    poses.resolve_factors([])


# ------------------------------------------------------- interpolated_poses


def test_interpolated_poses_counts_and_meta():
  c2w = np.stack([yaw_pose(0.2 * i, [i, 0.0, 0.0]) for i in range(4)])
  out, meta = poses.interpolated_poses(c2w, '4x', sequencing='ordered')
  assert out.shape == (3 * 3, 3, 4)
  assert len(meta) == 9
  assert [m['pair'] for m in meta[:3]] == [(0, 1)] * 3
  assert [m['beta'] for m in meta[:3]] == [0.25, 0.5, 0.75]
  for pose, m in zip(out, meta):
    i, j = m['pair']
    assert j == i + 1
    np.testing.assert_allclose(pose[:, 3], [i + m['beta'], 0.0, 0.0],
                               atol=1e-14)
    np.testing.assert_allclose(pose[:, :3], rodrigues([0, 1, 0],
                                                      0.2 * (i + m['beta'])),
                               atol=1e-12)


def test_interpolated_poses_position_sequencing_pairs_neighbours():
  # Shuffled cameras on a line: every pair must be adjacent on the line.
  rng = np.random.default_rng(8)
  perm = rng.permutation(6)
  c2w = np.stack([yaw_pose(0.0, [float(p), 0.0, 0.0]) for p in perm])
  _, meta = poses.interpolated_poses(c2w, [0.5])
  assert len(meta) == 5
  for m in meta:
    i, j = m['pair']
    assert abs(perm[i] - perm[j]) == 1


def test_interpolated_poses_identical_cameras():
  c2w = yaw_pose(0.7, [1.0, -2.0, 3.0])
  out, meta = poses.interpolated_poses(np.stack([c2w, c2w]), '5x')
  assert out.shape == (4, 3, 4)
  assert [m['pair'] for m in meta] == [(0, 1)] * 4 or \
      [m['pair'] for m in meta] == [(1, 0)] * 4
  np.testing.assert_allclose(out, np.broadcast_to(c2w, out.shape), atol=1e-12)


def test_interpolated_poses_single_view_raises():
  with pytest.raises(ValueError, match='need at least 2 training views'):
    poses.interpolated_poses(yaw_pose(0.0, [0, 0, 0])[None], '2x')


# ----------------------------------------------------------------- look_at


def test_look_at_convention():
  c2w = poses.look_at(np.array([0.0, 0.0, 5.0]), np.zeros(3),
                      np.array([0.0, 1.0, 0.0]))
  np.testing.assert_allclose(c2w, np.concatenate(
      [np.eye(3), [[0.0], [0.0], [5.0]]], axis=1), atol=1e-15)


def test_look_at_degenerate_up():
  positions = np.array([[0.0, 0.0, 3.0], [0.0, 0.0, -3.0], [1.0, 1.0, 1.0]])
  c2w = poses.look_at(positions, np.zeros(3), np.array([0.0, 0.0, 1.0]))
  assert np.all(np.isfinite(c2w))
  assert_proper_rotation(c2w[:, :, :3])
  view = -c2w[:, :, 2]
  np.testing.assert_allclose(
      view, -positions / np.linalg.norm(positions, axis=-1, keepdims=True),
      atol=1e-14)
  with pytest.raises(ValueError):
    poses.look_at(np.zeros(3), np.zeros(3), np.array([0.0, 1.0, 0.0]))


# ------------------------------------------------------------ random poses


def _assert_valid_distinct(c2w, n):
  assert c2w.shape == (n, 3, 4)
  assert np.all(np.isfinite(c2w))
  assert_proper_rotation(c2w[:, :, :3])
  pos = c2w[:, :, 3]
  d = np.linalg.norm(pos[:, None] - pos[None], axis=-1)
  assert np.all(d[~np.eye(n, dtype=bool)] > 1e-9)


def test_random_poses_forward_facing():
  rng = np.random.default_rng(9)
  c2w = forward_facing_rig(rng)
  n = 64
  out = poses.random_poses_forward_facing(c2w, n, np.random.default_rng(10))
  _assert_valid_distinct(out, n)
  pos = c2w[:, :, 3]
  mean = pos.mean(0)
  lo = mean + 1.2 * (pos.min(0) - mean)
  hi = mean + 1.2 * (pos.max(0) - mean)
  assert np.all(out[:, :, 3] >= lo - 1e-12)
  assert np.all(out[:, :, 3] <= hi + 1e-12)
  # Some samples fall outside the cameras' own box (spread > 1).
  assert np.any(out[:, :, 3] < pos.min(0))
  assert np.any(out[:, :, 3] > pos.max(0))
  mean_view = -c2w[:, :, 2].mean(0)
  mean_view /= np.linalg.norm(mean_view)
  assert np.all(-out[:, :, 2] @ mean_view > 0.0)
  # All cameras look at the focus point (default depth 1.0).
  focus = mean + mean_view
  to_focus = focus - out[:, :, 3]
  to_focus /= np.linalg.norm(to_focus, axis=-1, keepdims=True)
  np.testing.assert_allclose(-out[:, :, 2], to_focus, atol=1e-12)
  # Up vectors agree with the rig's mean up direction.
  mean_up = c2w[:, :, 1].mean(0)
  assert np.all(out[:, :, 1] @ mean_up > 0.0)


def test_random_poses_forward_facing_focus_depth_and_reproducible():
  rng = np.random.default_rng(11)
  c2w = forward_facing_rig(rng)
  a = poses.random_poses_forward_facing(c2w, 8, np.random.default_rng(1),
                                        focus_depth=4.0)
  b = poses.random_poses_forward_facing(c2w, 8, np.random.default_rng(1),
                                        focus_depth=4.0)
  np.testing.assert_array_equal(a, b)
  mean_view = -c2w[:, :, 2].mean(0)
  mean_view /= np.linalg.norm(mean_view)
  focus = c2w[:, :, 3].mean(0) + 4.0 * mean_view
  to_focus = focus - a[:, :, 3]
  to_focus /= np.linalg.norm(to_focus, axis=-1, keepdims=True)
  np.testing.assert_allclose(-a[:, :, 2], to_focus, atol=1e-12)


def test_random_poses_forward_facing_coplanar_cameras():
  rng = np.random.default_rng(12)
  n_cam = 6
  pos = np.concatenate([rng.uniform(-1, 1, (n_cam, 2)), np.zeros((n_cam, 1))],
                       axis=1)
  c2w = np.concatenate([np.broadcast_to(np.eye(3), (n_cam, 3, 3)),
                        pos[:, :, None]], axis=2)
  out = poses.random_poses_forward_facing(c2w, 32, np.random.default_rng(13))
  _assert_valid_distinct(out, 32)
  z = out[:, 2, 3]
  largest = 1.2 * (pos.max(0) - pos.min(0)).max()
  assert np.all(np.abs(z) <= 0.05 * largest + 1e-12)
  assert z.min() < 0.0 < z.max()  # degenerate axis sampled around the mean
  assert np.ptp(z) > 0.02 * largest
  assert np.all(out[:, 2, 2] > 0.0)  # looking along -z, towards the scene


def test_random_poses_sphere():
  rng = np.random.default_rng(14)
  n_cam, radius = 20, 4.0
  center = np.array([0.5, -0.2, 0.1])
  # Upper hemisphere cameras with elevations in [10, 60] degrees.
  elev = np.deg2rad(rng.uniform(10.0, 60.0, n_cam))
  azim = rng.uniform(0.0, 2 * np.pi, n_cam)
  dirs = np.stack([np.cos(elev) * np.cos(azim), np.cos(elev) * np.sin(azim),
                   np.sin(elev)], -1)
  dist = radius * rng.uniform(0.9, 1.1, n_cam)
  cam_pos = center + dist[:, None] * dirs
  c2w = poses.look_at(cam_pos, center, np.array([0.0, 0.0, 1.0]))
  n = 100
  out = poses.random_poses_sphere(c2w, n, np.random.default_rng(15),
                                  center=center)
  _assert_valid_distinct(out, n)
  rel = out[:, :, 3] - center
  r = np.linalg.norm(rel, axis=-1)
  np.testing.assert_allclose(r, dist.mean(), rtol=1e-12)
  to_center = -rel / r[:, None]
  np.testing.assert_allclose(-out[:, :, 2], to_center, atol=1e-12)
  out_elev = np.arcsin(rel[:, 2] / r)
  assert np.all(out_elev >= elev.min() - 1e-9)
  assert np.all(out_elev <= elev.max() + 1e-9)
  # Camera x axes are horizontal (world up is +z).
  np.testing.assert_allclose(out[:, 2, 0], 0.0, atol=1e-12)
  assert np.all(out[:, 2, 1] > 0.0)


def test_random_poses_sphere_default_center_and_poles():
  # Cameras straight above and below the origin: degenerate look-at.
  c2w = poses.look_at(np.array([[0.0, 0.0, 2.0], [0.0, 0.0, -2.0]]),
                      np.zeros(3), np.array([0.0, 0.0, 1.0]))
  out = poses.random_poses_sphere(c2w, 16, np.random.default_rng(16))
  _assert_valid_distinct(out, 16)
  rel = out[:, :, 3]
  np.testing.assert_allclose(np.linalg.norm(rel, axis=-1), 2.0, rtol=1e-12)
  np.testing.assert_allclose(-out[:, :, 2], -rel / 2.0, atol=1e-12)
  # Full elevation range [-90, 90] degrees is used.
  assert rel[:, 2].min() < 0.0 < rel[:, 2].max()


def test_camera_path_is_smooth_valid_and_goes_there_and_back():
  rng = np.random.default_rng(3)
  rots = poses.quaternion_to_rotation(rng.normal(size=(4, 4)))
  c2w = np.concatenate([rots, rng.normal(size=(4, 3, 1))], -1)
  path = poses.camera_path(c2w, 40)
  assert path.shape == (40, 3, 4) and np.all(np.isfinite(path))
  rot = path[:, :, :3]
  np.testing.assert_allclose(rot @ np.swapaxes(rot, 1, 2),
                             np.broadcast_to(np.eye(3), rot.shape), atol=1e-9)
  np.testing.assert_allclose(np.linalg.det(rot), 1., atol=1e-9)
  chain = c2w[poses.sequence_cameras(c2w, 'position')]
  np.testing.assert_allclose(path[0], chain[0], atol=1e-9)
  np.testing.assert_allclose(path[20], chain[-1], atol=1e-9)  # the far end at half-way
  np.testing.assert_allclose(path[1:20, :, 3], path[39:20:-1, :, 3], atol=1e-9)  # and back
  steps = np.linalg.norm(np.diff(path[:21, :, 3], axis=0), axis=-1)
  # Even spacing in path length: every step is the same except the (shorter) chords
  # across the two interior corners of the 4-camera chain.
  assert np.sum(np.isclose(steps, steps.max(), rtol=1e-6)) >= len(steps) - 2
  # Degenerate inputs: one camera, all cameras at one position.
  assert poses.camera_path(c2w[:1], 5).shape == (5, 3, 4)
  same = c2w.copy()
  same[:, :, 3] = 0.
  assert np.all(np.isfinite(poses.camera_path(same, 9)))
  with pytest.raises(ValueError, match='n_frames'):
    poses.camera_path(c2w, 0)
