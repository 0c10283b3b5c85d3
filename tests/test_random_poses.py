"""Tests for renerf_jax.random_poses."""

import numpy as np
import pytest

from pose_helpers import assert_proper_rotation, random_unit_vectors, rodrigues
from renerf_jax import random_poses


# ----------------------------------------------------------------- helpers


def forward_facing_rig(rng, n=9):
  """Cameras roughly in the z=0 plane looking along -z, slightly jittered."""
  pos = np.concatenate([rng.uniform(-0.5, 0.5, (n, 2)),
                        rng.uniform(-0.05, 0.05, (n, 1))], axis=1)
  rots = [rodrigues(a, 0.1 * rng.uniform())
          for a in random_unit_vectors(rng, n)]
  return np.concatenate([np.stack(rots), pos[:, :, None]], axis=2)


# ----------------------------------------------------------------- look_at


def test_look_at_convention():
  c2w = random_poses.look_at(np.array([0.0, 0.0, 5.0]), np.zeros(3),
                             np.array([0.0, 1.0, 0.0]))
  np.testing.assert_allclose(c2w, np.concatenate(
      [np.eye(3), [[0.0], [0.0], [5.0]]], axis=1), atol=1e-15)


def test_look_at_degenerate_up():
  positions = np.array([[0.0, 0.0, 3.0], [0.0, 0.0, -3.0], [1.0, 1.0, 1.0]])
  c2w = random_poses.look_at(positions, np.zeros(3), np.array([0.0, 0.0, 1.0]))
  assert np.all(np.isfinite(c2w))
  assert_proper_rotation(c2w[:, :, :3])
  view = -c2w[:, :, 2]
  np.testing.assert_allclose(
      view, -positions / np.linalg.norm(positions, axis=-1, keepdims=True),
      atol=1e-14)
  with pytest.raises(ValueError):
    random_poses.look_at(np.zeros(3), np.zeros(3), np.array([0.0, 1.0, 0.0]))


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
  out = random_poses.random_poses_forward_facing(c2w, n, np.random.default_rng(10))
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
  a = random_poses.random_poses_forward_facing(c2w, 8, np.random.default_rng(1),
                                               focus_depth=4.0)
  b = random_poses.random_poses_forward_facing(c2w, 8, np.random.default_rng(1),
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
  out = random_poses.random_poses_forward_facing(c2w, 32, np.random.default_rng(13))
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
  c2w = random_poses.look_at(cam_pos, center, np.array([0.0, 0.0, 1.0]))
  n = 100
  out = random_poses.random_poses_sphere(c2w, n, np.random.default_rng(15),
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
  c2w = random_poses.look_at(np.array([[0.0, 0.0, 2.0], [0.0, 0.0, -2.0]]),
                             np.zeros(3), np.array([0.0, 0.0, 1.0]))
  out = random_poses.random_poses_sphere(c2w, 16, np.random.default_rng(16))
  _assert_valid_distinct(out, 16)
  rel = out[:, :, 3]
  np.testing.assert_allclose(np.linalg.norm(rel, axis=-1), 2.0, rtol=1e-12)
  np.testing.assert_allclose(-out[:, :, 2], -rel / 2.0, atol=1e-12)
  # Full elevation range [-90, 90] degrees is used.
  assert rel[:, 2].min() < 0.0 < rel[:, 2].max()


def test_random_unobserved_poses_picks_the_generator_of_the_scene_kind():
  """Forward-facing scenes draw the box poses, 360 scenes the sphere's, bit for bit."""
  rng = np.random.default_rng(0)
  c2w = random_poses.random_poses_sphere(np.eye(4)[None, :3] + np.array(
      [[[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 2.]]]), 4, rng)
  for forward_facing, direct in (
      (True, lambda r: random_poses.random_poses_forward_facing(c2w, 5, r, focus_depth=3.,
                                                                spread=1.5)),
      (False, lambda r: random_poses.random_poses_sphere(c2w, 5, r))):
    got = random_poses.random_unobserved_poses(c2w, 5, np.random.default_rng(7),
                                               forward_facing, 3., 1.5)
    np.testing.assert_array_equal(got, direct(np.random.default_rng(7)))
  draw = lambda ff: random_poses.random_unobserved_poses(c2w, 5, np.random.default_rng(7),
                                                         ff, 3., 1.5)
  assert not np.allclose(draw(True), draw(False))
