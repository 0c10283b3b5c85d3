"""The embedded 360-degree scene (renerf_jax/datasets/orbit.py): its ray caster on extreme
rays, its cameras against the package's own rays, its depths, split and Scene path."""
import dataclasses

import numpy as np

from renerf_jax.configs import Config, load_config
from renerf_jax.datasets import camera_rays, load_scene, orbit
from renerf_jax.datasets.transforms import normalize_poses
from conftest import REPO


def _config(**kw):
  base = load_config([str(REPO / 'gin_configs' / 'demo.gin')],
                     ['Config.procedural_size = (24, 24)'])
  return dataclasses.replace(base, **kw)


def test_cast_is_finite_on_extreme_rays():
  """Rays straight up and down, grazing the floor (dz = 0), from inside the box and from
  the scene's centre all hit something at a finite positive distance of the right kind."""
  origins = np.array([[0., 0., 3.], [0., 0., 3.], [5., 0., 0.5], [-0.4, -0.2, 0.3],
                      [0., 0., 0.35], [6.9, 0., 0.1]])
  dirs = np.array([[0., 0., 1.], [0., 0., -1.], [-1., 0., 0.], [1., 0., 0.],
                   [0., 1., 0.], [1., 0., 0.]])
  t, points, normals, kind = orbit.cast(origins, dirs)
  assert np.all(np.isfinite(t)) and np.all(t > 0) and np.all(np.isfinite(normals))
  np.testing.assert_allclose(np.linalg.norm(normals, axis=-1), 1., atol=1e-9)
  assert kind[0] == orbit.DOME and kind[1] == orbit.FLOOR
  assert kind[2] == orbit.SPHERE  # Along the x axis at z = 0.5: the big sphere first.
  assert kind[3] == orbit.BOX  # From inside the box: its far wall is behind the origin.
  np.testing.assert_allclose(points[1], [0., 0., 0.], atol=1e-9)
  np.testing.assert_allclose(np.linalg.norm(points[5]), 7., rtol=1e-9)


def test_images_and_depths_match_the_packages_own_rays():
  """Ray-casting the scene along the package's camera rays (normalised poses undone)
  gives what the scene's own renderer gives without supersampling (the cameras' pose
  and pixel conventions agree), colours and z-depths (scaled as the poses); the Scene's
  supersampled images and depths are close to it."""
  config = _config()
  scene = load_scene(config)
  h, w = config.procedural_size
  raw = orbit.camera_poses(config.procedural_views)
  _, centre, scale = normalize_poses(raw)
  for i in (0, 7, 23):
    rays = camera_rays(scene, [i])
    o = np.asarray(rays.origins[0], np.float64) / scale + centre
    d = np.asarray(rays.directions[0], np.float64)
    unit = d / np.linalg.norm(d, axis=-1, keepdims=True)
    t, points, normals, kind = orbit.cast(o, unit)
    image = np.clip(orbit.shade(points, normals, kind), 0., 1.)
    ref, ref_depth = orbit.render_views(raw[i:i + 1], h, w, scene.focal, supersample=1)
    same = np.all(np.abs(image - ref[0]) < 1e-4, -1)
    assert same.mean() > 0.97, (i, same.mean())  # float32 rays flip a few edge pixels.
    # Camera rays have unit z in the camera frame: t along them is the z-depth.
    z = t / np.linalg.norm(d, axis=-1) * scale
    assert np.mean(np.abs(z - ref_depth[0] * scale) < 1e-4 * z) > 0.97
    assert np.median(np.abs(scene.images[i] - ref[0])) < 0.05
    assert np.median(np.abs(scene.depths[i] / z - 1.)) < 0.02


def test_split_orbit_and_scene_path():
  """Test views lie between training views on the orbit, cameras are normalised as a
  transforms.json capture's (farthest at 1, looking at the origin), the box holds the
  objects, and the Scene is an object capture (no NDC, not forward-facing)."""
  scene = load_scene(_config())
  assert len(scene.train_idx) == 12 and len(scene.test_idx) == 6
  assert not set(scene.train_idx) & set(scene.test_idx)
  centres = scene.poses[:, :3, 3]
  np.testing.assert_allclose(np.linalg.norm(centres, axis=-1).max(), 1., rtol=1e-5)
  axes = -scene.poses[:, :3, 2]
  miss = np.linalg.norm(np.cross(axes, -centres), axis=-1)  # Distance of the origin from each axis.
  assert miss.max() < 1e-5
  azimuth = np.arctan2(centres[:, 1], centres[:, 0])
  train_az = np.sort(azimuth[scene.train_idx])
  gaps = np.diff(np.concatenate([train_az, train_az[:1] + 2 * np.pi]))
  assert gaps.max() < 2 * np.pi / len(scene.train_idx) * 1.5
  for i in scene.test_idx:  # No test camera coincides with a training camera.
    assert np.min(np.linalg.norm(centres[scene.train_idx] - centres[i], axis=-1)) > 0.05
  # The floor disc's box, moved and scaled with the cameras.
  _, centre, scale = normalize_poses(orbit.camera_poses(48))
  np.testing.assert_allclose(np.array(scene.bbox), (np.array(
      [[-2.2, -2.2, -0.1], [2.2, 2.2, 1.2]]) - centre) * scale, rtol=1e-6, atol=1e-7)
  assert not scene.use_ndc and not scene.forward_facing and scene.intrinsics is None
  assert scene.depths.shape == scene.images.shape[:3] and np.all(scene.depths > 0)


def test_orbit_loader_is_selectable_and_checked():
  scene = load_scene(Config(dataset_loader='orbit', procedural_size=(16, 20),
                            procedural_views=16, n_input_views=4, use_ndc=False,
                            normalize_poses=True))
  assert scene.images.shape == (16, 16, 20, 3) and scene.name == 'orbit'
  assert 0. <= scene.images.min() and scene.images.max() <= 1.


def test_comparison_shows_the_test_view_farthest_from_training_cameras():
  from renerf_jax.datasets import Scene  # pylint: disable=g-import-not-at-top
  from renerf_jax.round_driver import hardest_test_view  # pylint: disable=g-import-not-at-top
  poses = np.zeros((6, 3, 4), np.float32)
  poses[:, :3, :3] = np.eye(3)
  poses[:, 0, 3] = [0., 1., 2., 0.1, 5., 1.5]
  scene = Scene(name='line', images=np.zeros((6, 4, 4, 3), np.float32), poses=poses,
                focal=4., near=0., far=1., use_ndc=False, white_bkgd=False,
                train_idx=np.array([0, 1, 2]), test_idx=np.array([3, 4, 5]))
  assert hardest_test_view(scene) == 1
  scene = dataclasses.replace(scene, test_idx=np.array([5, 3]))
  assert hardest_test_view(scene) == 0
