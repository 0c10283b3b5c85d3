"""transforms.json scenes (datasets/transforms.py) and the intrinsics and lens distortion
of their rays (cameras.distort / undistort / pixel_directions)."""
import dataclasses
import json

import imageio.v3 as iio
import jax.numpy as jnp
import numpy as np
import pytest

from conftest import BLENDER_DIR, DATA
from renerf_jax import cameras
from renerf_jax.configs import Config
from renerf_jax.datasets import camera_rays, downsample_scene, load_scene
from renerf_jax.errors import ConfigError, DataError

FOX_DIST = (0.0578421, -0.0805099, -0.000980296, 0.00015575)  # fox's transforms.json


@pytest.mark.parametrize('dist', [FOX_DIST, (-0.3, 0.1, 0.01, -0.02), (0.2, 0.05, 0., 0.)])
def test_undistort_inverts_distort(dist):
  """A round trip against the forward model, both ways, over the field of view of a
  wide lens (normalised radius up to 0.85)."""
  rng = np.random.default_rng(0)
  x, y = (jnp.asarray(v, jnp.float32) for v in rng.uniform(-0.6, 0.6, (2, 4000)))
  xd, yd = cameras.distort(x, y, dist)
  xu, yu = cameras.undistort(xd, yd, dist)
  np.testing.assert_allclose(xu, x, atol=2e-6)
  np.testing.assert_allclose(yu, y, atol=2e-6)
  xr, yr = cameras.distort(*cameras.undistort(x, y, dist), dist)
  np.testing.assert_allclose(xr, x, atol=2e-6)
  np.testing.assert_allclose(yr, y, atol=2e-6)
  # The model moves points (the test is not vacuous) and zero distortion moves none.
  assert float(jnp.max(jnp.abs(xd - x))) > 1e-3
  x0, y0 = cameras.undistort(x, y, (0., 0., 0., 0.))
  np.testing.assert_array_equal(x0, x)
  np.testing.assert_array_equal(y0, y)


def test_pixel_directions_with_intrinsics():
  h, w, f = 6, 8, 7.
  px, py = jnp.meshgrid(jnp.arange(w, dtype=jnp.float32), jnp.arange(h, dtype=jnp.float32))
  # The centred pinhole as intrinsics gives the pinhole's directions.
  np.testing.assert_allclose(
      cameras.pixel_directions(px, py, f, h, w, (f, f, w / 2, h / 2, 0., 0., 0., 0.)),
      cameras.pixel_directions(px, py, f, h, w), atol=1e-7)
  # fx != fy, an off-centre principal point and distortion: distorting the direction's
  # normalised coordinates (OpenCV axes) and applying K gives back the pixel centre.
  intr = (9., 7.5, 3.3, 2.2) + FOX_DIST
  d = cameras.pixel_directions(px, py, f, h, w, intr)
  np.testing.assert_array_equal(d[..., 2], -1.)
  xd, yd = cameras.distort(d[..., 0], -d[..., 1], FOX_DIST)
  np.testing.assert_allclose(xd * 9. + 3.3, px + 0.5, atol=1e-5)
  np.testing.assert_allclose(yd * 7.5 + 2.2, py + 0.5, atol=1e-5)
  with pytest.raises(ValueError, match='NDC'):
    cameras.pixel_rays(jnp.eye(4)[:3], px, py, f, h, w, True, 0., 1., intr)


def _fox(**kw):
  return Config(dataset_loader='transforms', data_dir=str(DATA / 'ingp_fox'), scene='fox',
                n_input_views=12, near=0.1, far=20., **kw)


def test_fox_loads_with_the_sparse_split_and_its_camera():
  scene = load_scene(_fox())
  meta = json.loads((DATA / 'ingp_fox' / 'fox' / 'transforms.json').read_text())
  names = sorted(f['file_path'] for f in meta['frames'])
  assert scene.images.shape == (len(names), 480, 270, 3) and len(names) == 50
  # ../shared/data/README.md: test = every 8th frame by name, 12 train views evenly
  # spaced over the rest.
  np.testing.assert_array_equal(scene.test_idx, np.arange(0, 50, 8))
  rest = np.array([i for i in range(50) if i % 8])
  np.testing.assert_array_equal(scene.train_idx,
                                rest[np.round(np.linspace(0, len(rest) - 1, 12)).astype(int)])
  by_name = {f['file_path']: f for f in meta['frames']}
  np.testing.assert_allclose(
      scene.poses[7], np.asarray(by_name[names[7]]['transform_matrix'])[:3], atol=1e-6)
  assert scene.intrinsics == (meta['fl_x'], meta['fl_y'], meta['cx'], meta['cy'],
                              meta['k1'], meta['k2'], meta['p1'], meta['p2'])
  assert scene.bbox == ((-6.,) * 3, (6.,) * 3) and not scene.use_ndc  # aabb_scale 4
  # Box-filtering by 2 halves the focal lengths and moves the principal point with the
  # pixel grid; the ray through the principal point is the camera's optical axis.
  small = downsample_scene(scene, 2)
  fx, fy, cx, cy = small.intrinsics[:4]
  assert (fx, fy, cx, cy) == pytest.approx((meta['fl_x'] / 2, meta['fl_y'] / 2,
                                            meta['cx'] / 2, meta['cy'] / 2))
  rays = camera_rays(small, [0])
  # The pixel whose centre lies nearest the principal point looks along -z (camera axes).
  i, j = int(np.floor(cy)), int(np.floor(cx))
  d_cam = np.asarray(rays.directions[0, i, j]) @ np.asarray(small.poses[0, :, :3])
  assert np.hypot(d_cam[0], d_cam[1]) < 1.5 / fx and d_cam[2] < 0.


def test_blender_scene_loads_through_transforms_as_through_blender():
  kw = dict(data_dir=str(BLENDER_DIR), scene='lego', n_input_views=8, white_bkgd=True,
            near=2., far=6.)
  a = load_scene(Config(dataset_loader='transforms', **kw))
  b = load_scene(Config(dataset_loader='blender', **kw))
  np.testing.assert_array_equal(a.images, b.images)
  np.testing.assert_allclose(a.poses, b.poses, atol=1e-6)
  np.testing.assert_array_equal(a.train_idx, b.train_idx)
  np.testing.assert_array_equal(a.test_idx, b.test_idx)
  assert a.focal == pytest.approx(b.focal, rel=1e-6) and a.intrinsics is None
  assert a.bbox == b.bbox


def _write_scene(root, frames, images=None, **top):
  """A transforms.json scene in root/s with 8x6 images (or the given ones)."""
  d = root / 's'
  (d / 'images').mkdir(parents=True)
  for i, name in enumerate(images or [f['file_path'] for f in frames
                                      if isinstance(f, dict) and 'file_path' in f]):
    iio.imwrite(d / name, np.full((6, 8, 3), 40 * i, np.uint8))
  (d / 'transforms.json').write_text(json.dumps(dict(top, frames=frames)))
  return Config(dataset_loader='transforms', data_dir=str(root), scene='s',
                n_input_views=1, near=0.1, far=5.)


def _frame(i, **kw):
  return dict(file_path=f'images/{i:02d}.png', transform_matrix=np.eye(4).tolist(), **kw)


def test_camera_angle_fallback_and_per_frame_intrinsics(tmp_path):
  cfg = _write_scene(tmp_path / 'a', [_frame(i) for i in range(3)], camera_angle_x=0.9)
  scene = load_scene(cfg)
  assert scene.focal == pytest.approx(0.5 * 8 / np.tan(0.45)) and scene.intrinsics is None
  # Per-frame keys override the file's; equal per-frame intrinsics load as one camera.
  frames = [_frame(i, fl_x=5., fl_y=6., cx=4.5, cy=3.) for i in range(3)]
  scene = load_scene(_write_scene(tmp_path / 'b', frames, fl_x=1., w=8, h=6))
  assert scene.intrinsics == (5., 6., 4.5, 3., 0., 0., 0., 0.)


@pytest.mark.parametrize('case,message', [
    ('no_frames', 'no "frames" list'),
    ('no_matrix', "frame 'images/01.png' has no \"transform_matrix\""),
    ('missing_image', "image of frame 'images/02.png' not found"),
    ('size', 'is 8x6 pixels but the file gives w x h = 10x6'),
    ('two_cameras', 'differ from the first frame'),
    ('no_focal', 'has no focal length'),
    ('bad_number', '"fl_x" is not a number'),
    ('bad_matrix', 'transform_matrix is not a finite 4x4'),
    ('fisheye', "camera model 'OPENCV_FISHEYE' is not supported"),
    ('k3', 'distortion coefficient "k3" is not supported'),
    ('path_type', 'frame 1 has no "file_path" string'),
    ('too_few', 'transforms.json: Config.n_input_views=9 but only 2 non-test images'),
])
def test_bad_transforms_files_fail_in_one_line_naming_the_file(tmp_path, case, message):
  frames = [_frame(i, fl_x=5.) for i in range(3)]
  top, images = {}, None
  if case == 'no_frames':
    frames = None
  elif case == 'no_matrix':
    del frames[1]['transform_matrix']
  elif case == 'missing_image':
    images = ['images/00.png', 'images/01.png']
  elif case == 'size':
    top = dict(w=10, h=6)
  elif case == 'two_cameras':
    frames[2]['fl_x'] = 6.
  elif case == 'no_focal':
    for f in frames:
      del f['fl_x']
  elif case == 'bad_number':
    frames[0]['fl_x'] = 'five'
  elif case == 'bad_matrix':
    frames[1]['transform_matrix'] = [[1., 0.], [0., float('nan')]]
  elif case == 'fisheye':
    top = dict(camera_model='OPENCV_FISHEYE')
  elif case == 'k3':
    frames[2]['k3'] = 0.01
  elif case == 'path_type':
    images = ['images/00.png', 'images/02.png']
    frames[1]['file_path'] = 7
  root = tmp_path / case
  if frames is None:
    cfg = _write_scene(root, [_frame(0)])
    (root / 's' / 'transforms.json').write_text(json.dumps({'fl_x': 5.}))
  else:
    cfg = _write_scene(root, frames, images, **top)
  if case == 'too_few':
    cfg = dataclasses.replace(cfg, n_input_views=9)
  with pytest.raises(DataError) as e:
    load_scene(cfg)
  text = str(e.value)
  assert message in text and '\n' not in text
  assert 'transforms.json' in text or 'images/' in text


def test_gaussians_refuse_cameras_with_intrinsics():
  from renerf_jax.gaussians.training import Camera  # pylint: disable=g-import-not-at-top
  scene = load_scene(_fox())
  with pytest.raises(DataError, match="scene 'fox': the Gaussians render centred pinhole"):
    Camera.of(scene)
  assert Camera.of(dataclasses.replace(scene, intrinsics=None)).focal == scene.focal


def test_normalized_poses_put_the_focus_point_at_the_origin_and_cameras_within_one():
  from renerf_jax.datasets import transforms  # pylint: disable=g-import-not-at-top
  raw = load_scene(_fox())
  scene = load_scene(_fox(normalize_poses=True))
  dist = np.linalg.norm(scene.poses[:, :3, 3], axis=-1)
  assert float(dist.max()) == pytest.approx(1., abs=1e-6) and float(dist.min()) > 0.3
  np.testing.assert_allclose(transforms.focus_point(scene.poses.astype(np.float64)), 0.,
                             atol=1e-5)
  np.testing.assert_array_equal(scene.poses[:, :3, :3], raw.poses[:, :3, :3])
  # Relative camera geometry is kept up to the one scale; the box moves with it.
  _, centre, scale = transforms.normalize_poses(raw.poses.astype(np.float64))
  np.testing.assert_allclose(scene.poses[:, :3, 3],
                             (raw.poses[:, :3, 3] - centre) * scale, atol=1e-5)
  np.testing.assert_allclose(np.asarray(scene.bbox),
                             (np.asarray(raw.bbox) - centre) * scale, atol=1e-5)
  np.testing.assert_array_equal(scene.images, raw.images)


def test_blender_test_stride_keeps_every_kth_test_frame():
  """Config.test_stride: the few-shot Blender protocol's 25 of lego's 200 test views,
  the same frames (images and poses) as the full test split's every 8th."""
  kw = dict(data_dir=str(BLENDER_DIR), scene='lego', n_input_views=8, white_bkgd=True,
            near=2., far=6.)
  full = load_scene(Config(dataset_loader='transforms', **kw))
  for loader in ('transforms', 'blender'):
    sub = load_scene(Config(dataset_loader=loader, test_stride=8, **kw))
    assert len(sub.test_idx) == 25 and len(full.test_idx) == 200
    np.testing.assert_array_equal(sub.images[sub.test_idx], full.images[full.test_idx[::8]])
    np.testing.assert_allclose(sub.poses[sub.test_idx], full.poses[full.test_idx[::8]],
                               atol=1e-6)
    np.testing.assert_array_equal(sub.images[sub.train_idx], full.images[full.train_idx])
  with pytest.raises(ConfigError, match='Config.test_stride=0'):
    Config(dataset_loader='transforms', test_stride=0, **kw)


def test_blender_standard_split_is_the_literatures_eight_ids():
  """Config.blender_split: 'standard' (the default) trains on DietNeRF's frames 26, 86,
  2, 55, 75, 93, 16, 73 (images and poses of exactly those train frames) in both
  loaders; 'linspace' keeps the evenly spaced split; bad values fail in one line."""
  from renerf_jax.datasets.blender import read_split  # pylint: disable=g-import-not-at-top
  paths, poses, _ = read_split(str(BLENDER_DIR / 'lego'), 'train')
  ids = [26, 86, 2, 55, 75, 93, 16, 73]
  kw = dict(data_dir=str(BLENDER_DIR), scene='lego', n_input_views=8, white_bkgd=True,
            near=2., far=6., test_stride=8)
  for loader in ('transforms', 'blender'):
    std = load_scene(Config(dataset_loader=loader, **kw))
    np.testing.assert_allclose(std.poses[std.train_idx], poses[ids], atol=1e-6)
    old = load_scene(Config(dataset_loader=loader, blender_split='linspace', **kw))
    np.testing.assert_allclose(old.poses[old.train_idx],
                               poses[np.round(np.linspace(0, 99, 8)).astype(int)], atol=1e-6)
    np.testing.assert_array_equal(std.images[std.test_idx], old.images[old.test_idx])
  three = load_scene(Config(dataset_loader='blender', **dict(kw, n_input_views=3)))
  np.testing.assert_allclose(three.poses[three.train_idx], poses[ids[:3]], atol=1e-6)
  with pytest.raises(DataError, match="blender_split='standard' has 8 training frames"):
    load_scene(Config(dataset_loader='blender', **dict(kw, n_input_views=9)))
  with pytest.raises(ConfigError, match="Config.blender_split='even'"):
    Config(blender_split='even')


# ------------------------------------------------------------------ undistorted photos

_INTR = (41., 40.2, 33.1, 22.4, 0.06, -0.08, -0.001, 0.0015)  # A 48x64 photo's camera.


def _pattern(x, y):
  """A smooth colour pattern on the undistorted normalised image plane."""
  return np.stack([0.5 + 0.4 * np.sin(3. * x), 0.5 + 0.4 * np.cos(2. * y + x),
                   0.5 + 0.3 * np.sin(2. * x * y)], -1)


def _photo(h, w, intrinsics):
  """The pattern as a camera of `intrinsics` photographs it (each pixel centre's ray)."""
  v, u = np.mgrid[:h, :w] + 0.5
  fx, fy, cx, cy = intrinsics[:4]
  x, y = cameras.undistort((u - cx) / fx, (v - cy) / fy, intrinsics[4:], iterations=20)
  return _pattern(np.asarray(x), np.asarray(y))[None].astype(np.float32)


def test_undistorted_photos_are_the_pinhole_views_of_the_same_rays():
  """A distorted, off-centre photo of a smooth pattern, resampled, matches the pattern
  seen by the centred pinhole camera of the returned focal (bilinear error only); that
  focal is the smallest whose pixels all land in the photo."""
  from renerf_jax.datasets import undistort  # pylint: disable=g-import-not-at-top
  h, w = 48, 64
  out, focal = undistort.undistort_images(_photo(h, w, _INTR), _INTR)
  assert out.shape == (1, h, w, 3) and out.dtype == np.float32
  v, u = np.mgrid[:h, :w] + 0.5
  want = _pattern((u - 0.5 * w) / focal, (v - 0.5 * h) / focal)
  np.testing.assert_allclose(out[0], want, atol=2e-3)
  # The border: 2 pixels of principal-point offset and the distortion cost a zoom.
  assert _INTR[0] < focal < 1.2 * _INTR[0]
  sx, sy = undistort._sources(focal, h, w, _INTR)  # pylint: disable=protected-access
  assert sx.min() >= 0. and sx.max() <= w - 1 and sy.min() >= 0. and sy.max() <= h - 1
  sx, sy = undistort._sources(0.999 * focal, h, w, _INTR)  # pylint: disable=protected-access
  assert sx.min() < 0. or sx.max() > w - 1 or sy.min() < 0. or sy.max() > h - 1


def test_undistorting_a_centred_pinhole_photo_keeps_it():
  from renerf_jax.datasets import undistort  # pylint: disable=g-import-not-at-top
  photo = np.random.default_rng(0).random((2, 10, 14, 3)).astype(np.float32)
  out, focal = undistort.undistort_images(photo, (20., 20., 7., 5., 0., 0., 0., 0.))
  assert focal == pytest.approx(20., rel=2e-4)
  np.testing.assert_allclose(out, photo, atol=2e-3)


def test_undistortion_refuses_cameras_it_cannot_resample(tmp_path, monkeypatch):
  """A principal point outside the photo: one DataError line naming the file; a camera
  that even a quarter of its focal fits (a folding distortion) is refused, not bisected."""
  from renerf_jax.datasets import undistort  # pylint: disable=g-import-not-at-top
  with pytest.raises(ValueError, match='no centred pinhole camera'):
    undistort.pinhole_focal(10, 14, (20., 20., -30., 5., 0., 0., 0., 0.))
  frames = [_frame(i, fl_x=5., cx=-30., cy=3., k1=0.1) for i in range(3)]
  cfg = dataclasses.replace(_write_scene(tmp_path, frames, w=8, h=6), undistort=True)
  with pytest.raises(DataError, match='transforms.json: Config.undistort: no centred') as e:
    load_scene(cfg)
  assert '\n' not in str(e.value)
  monkeypatch.setattr(undistort, '_inside', lambda *a: True)
  with pytest.raises(ValueError, match='folds the image'):
    undistort.pinhole_focal(10, 14, (20., 20., 7., 5., 0., 0., 0., 0.))


def test_fox_undistorted_renders_as_a_centred_pinhole_camera():
  """Config.undistort: fox's photos resampled to a centred pinhole camera of their size
  (the Gaussians' camera); a pixel's pinhole ray is the distorted camera's ray (the
  NeRF's cameras.pixel_directions) through the photo position it was sampled at."""
  from renerf_jax.gaussians.training import Camera  # pylint: disable=g-import-not-at-top
  raw = load_scene(_fox())
  scene = load_scene(_fox(undistort=True))
  assert scene.intrinsics is None and scene.images.shape == raw.images.shape
  fx, fy, cx, cy = raw.intrinsics[:4]
  assert fx < scene.focal < 1.1 * fx
  assert Camera.of(scene).focal == scene.focal
  h, w = scene.height, scene.width
  for r, c in ((0, 0), (h - 1, w - 1), (h // 2, w // 2), (17, 200 % w), (401, 3)):
    d = np.asarray(cameras.pixel_directions(c, r, scene.focal, h, w))
    xd, yd = cameras.distort(d[0] / -d[2], -d[1] / -d[2], raw.intrinsics[4:])
    sx, sy = fx * xd + cx - 0.5, fy * yd + cy - 0.5  # Pixel indices (centres at i + 0.5).
    np.testing.assert_allclose(
        np.asarray(cameras.pixel_directions(sx, sy, raw.focal, h, w, raw.intrinsics)),
        d, atol=1e-5)
    x0, y0 = int(np.floor(sx)), int(np.floor(sy))
    ax, ay = sx - x0, sy - y0
    img = raw.images[:, y0:y0 + 2, x0:x0 + 2]
    want = ((1 - ay) * ((1 - ax) * img[:, 0, 0] + ax * img[:, 0, -1])
            + ay * ((1 - ax) * img[:, -1, 0] + ax * img[:, -1, -1]))
    np.testing.assert_allclose(scene.images[:, r, c], want, atol=1e-5)
