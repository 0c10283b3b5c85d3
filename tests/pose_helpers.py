"""Shared helpers of the pose tests (test_quaternions, test_poses, test_random_poses)."""

import numpy as np

from renerf_jax import quaternions


def rodrigues(axis, angle):
  """Rotation matrix about unit `axis` by `angle` (closed form)."""
  axis = np.asarray(axis, np.float64)
  axis = axis / np.linalg.norm(axis)
  k = np.array([[0.0, -axis[2], axis[1]],
                [axis[2], 0.0, -axis[0]],
                [-axis[1], axis[0], 0.0]])
  return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def random_rotations(rng, n):
  q = rng.normal(size=(n, 4))
  return quaternions.quaternion_to_rotation(q)


def random_unit_vectors(rng, n):
  v = rng.normal(size=(n, 3))
  return v / np.linalg.norm(v, axis=-1, keepdims=True)


def assert_proper_rotation(rot, atol=1e-9):
  rot = np.asarray(rot)
  eye = np.broadcast_to(np.eye(3), rot.shape)
  np.testing.assert_allclose(np.swapaxes(rot, -1, -2) @ rot, eye, atol=atol)
  np.testing.assert_allclose(np.linalg.det(rot), 1.0, atol=atol)


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
