"""Tests for renerf_jax.poses."""

import numpy as np
import pytest

from pose_helpers import ADVERSARIAL, assert_proper_rotation, random_rotations, rodrigues
from renerf_jax import poses, quaternions


# ----------------------------------------------------------------- helpers


def yaw_pose(yaw, position):
  rot = rodrigues([0.0, 1.0, 0.0], yaw)
  return np.concatenate([rot, np.asarray(position, float)[:, None]], axis=1)


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
    q = quaternions.rotation_to_quaternion(out[:, :3])
    np.testing.assert_allclose(
        quaternions.quaternion_angle(np.array([1.0, 0, 0, 0]), q), beta * angle,
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
  # A comma-separated string (Config.interp_factors) is parsed here, once.
  assert poses.resolve_factors('0.25,0.5') == (0.25, 0.5)
  assert poses.resolve_factors(' 0.5 ') == (0.5,)
  with pytest.raises(ValueError, match='outside the open interval'):
    poses.resolve_factors('0.5,2')


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


# --------------------------------------------------------------- camera_path


def test_camera_path_is_smooth_valid_and_goes_there_and_back():
  rng = np.random.default_rng(3)
  rots = quaternions.quaternion_to_rotation(rng.normal(size=(4, 4)))
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
