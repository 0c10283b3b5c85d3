"""The viewer's camera and image conversions (renerf_jax/view_cameras.py)."""
import numpy as np
import pytest

from renerf_jax import figures, quaternions
from renerf_jax import view_cameras as vc
from renerf_jax.cameras import pixel_directions


def _random_pose(rng):
  q = rng.normal(size=4)
  rot = quaternions.quaternion_to_rotation(q)
  return np.concatenate([rot, rng.normal(size=(3, 1))], axis=1)


def test_browser_pose_round_trip_and_axes():
  rng = np.random.default_rng(0)
  for _ in range(20):
    pose = _random_pose(rng)
    wxyz, pos = vc.browser_from_pose(pose)
    np.testing.assert_allclose(vc.pose_from_browser(wxyz, pos), pose, atol=1e-6)
  # OpenCV looks along +z with -y up; OpenGL along -z with +y up.
  pose = np.eye(4)[:3]
  wxyz, _ = vc.browser_from_pose(pose)
  rot_cv = quaternions.quaternion_to_rotation(wxyz)
  np.testing.assert_allclose(rot_cv[:, 2], [0., 0., -1.], atol=1e-12)  # forward
  np.testing.assert_allclose(-rot_cv[:, 1], [0., 1., 0.], atol=1e-12)  # up


def test_antipodal_quaternions_give_one_pose():
  q = np.array([.3, -.5, .7, .1])
  p = np.zeros(3)
  np.testing.assert_allclose(vc.pose_from_browser(q, p), vc.pose_from_browser(-q, p),
                             atol=1e-6)


def test_browser_pixel_projects_like_the_renderer():
  """A frustum's centre seen from its own camera is the canvas centre; a point on the
  top edge ray of the field of view lands on row 0; a point behind is None."""
  rng = np.random.default_rng(2)
  pose = _random_pose(rng)
  wxyz, pos = vc.browser_from_pose(pose)
  x, y = vc.browser_pixel(vc.frustum_centre(pose, .3), wxyz, pos, 1., 640, 480)
  assert (x, y) == (pytest.approx(320.), pytest.approx(240.))
  fov = .8
  top = pose[:3, :3] @ np.array([0., np.tan(fov / 2), -1.]) * 2. + pose[:3, 3]
  x, y = vc.browser_pixel(top, wxyz, pos, fov, 640, 480)
  assert (x, y) == (pytest.approx(320.), pytest.approx(0., abs=1e-9))
  assert vc.browser_pixel(pose[:3, 3] + pose[:3, 2], wxyz, pos, fov, 640, 480) is None


def test_fov_focal_round_trip_and_errors():
  for h, f in ((48, 50.), (378, 407.6), (1, 1e-3), (1000, 1e5)):
    assert vc.focal_for_fov(h, vc.fov_y(h, f)) == pytest.approx(f, rel=1e-9)
  with pytest.raises(ValueError, match='outside'):
    vc.focal_for_fov(10, np.pi)
  with pytest.raises(ValueError, match='outside'):
    vc.focal_for_fov(10, 0.)


def test_render_size():
  assert vc.render_size(4 / 3, 64) == (48, 64)
  assert vc.render_size(3 / 4, 64) == (64, 48)
  assert vc.render_size(1000., 64) == (1, 64)
  for bad in ((0., 64), (np.nan, 64), (1., 0)):
    with pytest.raises(ValueError, match='bad render size'):
      vc.render_size(*bad)


def test_view_scene_rays_match_the_browser_frustum():
  """A pixel at the image corner lies on the corner ray of the browser's field of view."""
  from renerf_jax.datasets.procedural import load_procedural  # pylint: disable=g-import-not-at-top
  from conftest import tiny_config  # pylint: disable=g-import-not-at-top
  scene = load_procedural(tiny_config())
  h, w = vc.render_size(16 / 9, 64)
  fov = 1.1
  sc = vc.view_scene(scene, h, w, vc.focal_for_fov(h, fov))
  assert (sc.height, sc.width, sc.intrinsics) == (h, w, None)
  d = np.asarray(pixel_directions(np.array([w / 2 - .5]), np.array([-.5]), sc.focal, h, w))
  # The top edge's ray (pixel row -0.5 is the image's top border) makes fov / 2 with -z.
  ang = np.arctan2(d[0, 1], -d[0, 2])
  assert ang == pytest.approx(fov / 2, abs=1e-5)


def test_layer_images_are_finite_pictures():
  rng = np.random.default_rng(1)
  out = {'rgb': rng.uniform(-.1, 1.1, (6, 8, 3)), 'depth': rng.uniform(0, 5, (6, 8)),
         'acc': rng.uniform(0, 1, (6, 8))}
  out['depth'][0, 0] = np.inf
  out['acc'][1] = 0.  # Empty rays: depth undefined there.
  photo = rng.uniform(0, 1, (6, 8, 3))
  for layer in vc.LAYERS:
    img = vc.layer_image(layer, out, photo)
    assert img.shape == (6, 8, 3) and np.all(np.isfinite(img))
    assert img.min() >= 0. and img.max() <= 1.
  np.testing.assert_array_equal(vc.layer_image('acc', out)[..., 0],
                                np.clip(out['acc'], 0, 1).astype(np.float32))
  # The error is zero where the render equals the photo: the colour map's low end.
  same = vc.layer_image('error', {'rgb': photo}, photo)
  np.testing.assert_allclose(same, np.broadcast_to(same[0, 0], same.shape))
  with pytest.raises(ValueError, match='needs the photo'):
    vc.layer_image('error', out)
  with pytest.raises(ValueError, match='unknown layer'):
    vc.layer_image('normals', out)
  # An all-empty render still draws (no finite depth).
  empty = {'rgb': np.zeros((2, 2, 3)), 'depth': np.zeros((2, 2)), 'acc': np.zeros((2, 2))}
  assert np.all(np.isfinite(vc.layer_image('depth', empty)))


def test_split_view_and_letterbox():
  a, b = np.zeros((4, 10, 3)), np.ones((4, 10, 3)) * .5
  s = vc.split_view(a, b, .3)
  np.testing.assert_array_equal(s[:, :3], 0.)
  np.testing.assert_array_equal(s[:, 3], 1.)  # The divider.
  np.testing.assert_array_equal(s[:, 4:], .5)
  np.testing.assert_array_equal(vc.split_view(a, b, 0.), b)
  np.testing.assert_array_equal(vc.split_view(a, b, 1.), a)
  with pytest.raises(ValueError, match='shapes differ'):
    vc.split_view(a, b[:, :5])
  img = np.ones((4, 8, 3))
  wide = vc.letterbox(img, 4.)  # A wider window: bars left and right.
  assert wide.shape == (4, 16, 3) and wide[:, :4].max() == 0. and wide[:, 4:12].min() == 1.
  tall = vc.letterbox(img, 1.)  # A squarer window: bars above and below.
  assert tall.shape == (8, 8, 3) and tall[:2].max() == 0. and tall[2:6].min() == 1.


def test_frustum_scale_and_up():
  poses = np.tile(np.eye(4)[:3], (3, 1, 1))
  poses[:, 0, 3] = [0., 2., 4.]
  assert vc.frustum_scale(poses) == pytest.approx(.5)
  assert vc.frustum_scale(poses[:1]) == 1.
  assert vc.frustum_scale(np.tile(np.eye(4)[:3], (2, 1, 1))) == 1.  # Coincident.
  np.testing.assert_allclose(vc.mean_up(poses), [0., 1., 0.])


def test_masked_view_tints_only_masked_pixels():
  img = np.full((2, 2, 3), .5)
  mask = np.array([[1., 0.], [1., 1.]])
  out = vc.masked_view(img, mask)
  np.testing.assert_allclose(out[0, 0], .5)
  assert not np.allclose(out[0, 1], .5)
  assert figures.to_uint8(np.array([[[np.nan, 2., -1.]]])).tolist() == [[[0, 255, 0]]]
