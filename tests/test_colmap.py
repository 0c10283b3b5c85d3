"""COLMAP captures (datasets/colmap_io.py, datasets/colmap.py), the SfM points of
nerfstudio captures (datasets/points.py), the Gaussians' SfM start: on the shared beer
and garden captures and on tiny models the tests write in both COLMAP formats."""
import os
import shutil

import imageio.v3 as iio
import jax
import numpy as np
import pytest

from colmap_helpers import write_model
from conftest import DATA
from renerf_jax import cameras, renerf
from renerf_jax.configs import Config
from renerf_jax.datasets import colmap, colmap_io, load_scene, undistort
from renerf_jax.datasets.points import read_points_ply
from renerf_jax.errors import DataError
from renerf_jax.gaussians import start

BEER = DATA / 'colmap' / 'beer'


def _rot(axis, angle):
  c, s = np.cos(angle), np.sin(angle)
  i, j = [k for k in range(3) if k != axis]
  r = np.eye(3)
  r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
  return r


def _quat(r):
  """(w, x, y, z) of a rotation matrix (Shepperd: the largest of the four first)."""
  t = np.trace(r)
  k = int(np.argmax([t, r[0, 0], r[1, 1], r[2, 2]]))
  if k == 0:
    w = 0.5 * np.sqrt(1. + t)
    q = (w, (r[2, 1] - r[1, 2]) / (4 * w), (r[0, 2] - r[2, 0]) / (4 * w),
         (r[1, 0] - r[0, 1]) / (4 * w))
  else:
    i, j, l = k - 1, k % 3, (k + 1) % 3
    v = np.zeros(3)
    v[i] = 0.5 * np.sqrt(1. + r[i, i] - r[j, j] - r[l, l])
    v[j] = (r[j, i] + r[i, j]) / (4 * v[i])
    v[l] = (r[l, i] + r[i, l]) / (4 * v[i])
    q = ((r[l, j] - r[j, l]) / (4 * v[i]),) + tuple(v)
  return tuple(float(x) for x in q)


def tiny_capture(root, ext='bin', n=10, size=(12, 16), model='SIMPLE_RADIAL',
                 per_photo=False):
  """A capture of n photos (h, w = size) on a circle around the origin in COLMAP's
  layout under root/tiny; returns (scene folder, the true OpenGL c2w [n, 3, 4])."""
  h, w = size
  scene = os.path.join(root, 'tiny')
  os.makedirs(os.path.join(scene, 'images'))
  params = {'SIMPLE_PINHOLE': (20., w / 2, h / 2), 'PINHOLE': (20., 21., w / 2, h / 2),
            'SIMPLE_RADIAL': (20., w / 2, h / 2, 0.01),
            'OPENCV': (20., 21., w / 2 + .3, h / 2 - .2, 0.01, 0., 0., 0.)}[model]
  cams, imgs, c2ws = {}, [], []
  rng = np.random.default_rng(0)
  for i in range(n):
    # OpenCV camera at angle a on a circle of radius 4, looking at the origin.
    a = 2 * np.pi * i / n
    centre = np.array([4 * np.sin(a), 0.3 * np.cos(3 * a), -4 * np.cos(a)])
    r_c2w = _rot(1, -a) @ _rot(0, 0.2 * np.sin(a)) @ _rot(2, 0.1 * np.cos(2 * a))  # tilted
    r_w2c = r_c2w.T
    t = -r_w2c @ centre
    cam_id = i + 1 if per_photo else 1
    p = params if not per_photo else (params[0] * (1 + 0.02 * i),) + params[1:]
    cams[cam_id] = (model, w, h, p)
    name = f'{i:04d}.png'
    imgs.append((i + 1, _quat(r_w2c), tuple(t), cam_id, name, np.array([0, -1, 1])))
    iio.imwrite(os.path.join(scene, 'images', name),
                rng.integers(0, 255, (h, w, 3), dtype=np.uint8))
    c2w = np.concatenate([r_c2w, centre[:, None]], 1) * np.array([1., -1., -1., 1.])
    c2ws.append(c2w)
  xyz = rng.normal(size=(6, 3)) * 0.5
  tracks = [np.array([1, 2]), np.array([2, 3, 4]), np.array([5]), np.array([1, 6, 7]),
            np.array([8, 9]), np.array([3, 10])]
  points = (np.arange(6), xyz, rng.integers(0, 255, (6, 3), dtype=np.uint8), tracks)
  write_model(os.path.join(scene, 'sparse', '0'), cams, imgs[::-1], points, ext)
  return scene, np.stack(c2ws)


def _config(root, **kw):
  base = dict(dataset_loader='colmap', data_dir=str(root), scene='tiny', factor=1,
              n_input_views=4, use_ndc=False, near=0.05, far=100.)
  base.update(kw)
  return Config(**base)


@pytest.mark.parametrize('ext', ['bin', 'txt'])
def test_tiny_model_reads_back_in_both_formats(tmp_path, ext):
  scene, c2w = tiny_capture(tmp_path, ext)
  cams, imgs, (ids, xyz, rgb, tracks) = colmap_io.read_model(os.path.join(scene, 'sparse',
                                                                          '0'))
  assert cams[1] == ('SIMPLE_RADIAL', 16, 12, (20., 8., 6., 0.01))
  assert [r[4] for r in imgs] == [f'{i:04d}.png' for i in range(9, -1, -1)]
  assert list(imgs[0][5]) == [0, -1, 1]
  assert len(xyz) == 6 and [list(t) for t in tracks][1] == [2, 3, 4]
  s = load_scene(_config(tmp_path))
  # Sorted by name, COLMAP's world-to-camera turned into OpenGL camera-to-world.
  np.testing.assert_allclose(s.poses, c2w, atol=1e-6)
  assert s.intrinsics == pytest.approx((20., 20., 8., 6., 0.01, 0., 0., 0.))
  # Point visibility from the tracks, in the Scene's (name) order: image id k+1 is photo k.
  assert s.point_views.shape == (6, 10) and s.point_views[1].nonzero()[0].tolist() == [1, 2, 3]


def test_colmap_camera_convention_projects_points_where_colmap_does(tmp_path):
  """A point's pixel by COLMAP's convention (R X + t, then the pinhole) equals the pixel
  of the converted camera (OpenGL, cameras.image_rays' convention)."""
  q, t = _quat(_rot(0, 0.3) @ _rot(1, 0.5)), (0.2, -0.1, 3.)
  x = np.array([0.3, 0.2, 1.])
  cam = colmap.qvec_to_rotmat(q) @ x + t
  u, v = 50. * cam[0] / cam[2] + 32., 50. * cam[1] / cam[2] + 24.
  c2w = colmap.colmap_to_c2w(q, t)
  local = c2w[:, :3].T @ (x - c2w[:, 3])  # OpenGL: x right, y up, looking along -z.
  assert local[2] < 0
  assert (50. * local[0] / -local[2] + 32., -50. * local[1] / -local[2] + 24.) == \
      pytest.approx((u, v))


def test_beer_poses_agree_with_its_poses_bounds():
  cap = colmap.read_capture(str(BEER))
  raw = np.load(BEER / 'poses_bounds.npy')[:, :15].reshape(-1, 3, 5)
  llff = cameras.llff_to_opengl(raw[:, :, :4])
  assert len(cap['paths']) == 71 == len(llff)
  # Largest difference: 9e-16 (rotation), 5e-15 (translation, the capture spans 6.6).
  assert np.abs(llff - cap['poses']).max() < 1e-9
  assert {c[0] for c in cap['cameras']} == {'SIMPLE_RADIAL'}
  assert len({c[3] for c in cap['cameras']}) == 71  # A camera per photo.


def test_beer_loads_resampled_to_one_camera_and_the_sfm_start_lands_on_the_photos():
  config = Config(dataset_loader='colmap', data_dir=str(DATA / 'colmap'), scene='beer',
                  factor=1, undistort=True, use_ndc=False, normalize_poses=True, near=0.05,
                  far=1000., n_input_views=12, train_view_selection='coverage',
                  val_views=4, image_downsample=4)
  s = load_scene(config)
  assert s.images.shape == (71, 320, 180, 3) and s.intrinsics is None
  assert len(set(s.train_idx) | set(s.val_idx) | set(s.test_idx)) == 12 + 4 + 9
  pts, rgb = start.sfm_start(s, jax.random.PRNGKey(0), 10 ** 6)
  assert 500 < len(pts) < len(s.points)  # Only points that 2+ training views' tracks hold.
  # Reprojected into the training views that see them, the points land inside the photo
  # and on pixels of their colour (a wrong pose convention or scale would not).
  errors, flipped = [], []
  for v in s.train_idx[:4]:
    c2w = s.poses[v].astype(np.float64)
    local = (pts - c2w[:, 3]) @ c2w[:, :3]
    ok = local[:, 2] < -0.05
    u = s.focal * local[ok, 0] / -local[ok, 2] + s.width / 2
    y = -s.focal * local[ok, 1] / -local[ok, 2] + s.height / 2
    inside = (u >= 0) & (u < s.width) & (y >= 0) & (y < s.height)
    ui, yi = u[inside].astype(int), y[inside].astype(int)
    errors.append(np.abs(s.images[v][yi, ui] - rgb[ok][inside]).mean(-1))
    # The same points at the mirrored pixels: what a wrong axis would give.
    flipped.append(np.abs(s.images[v][s.height - 1 - yi, s.width - 1 - ui]
                          - rgb[ok][inside]).mean(-1))
  err, control = np.concatenate(errors), np.concatenate(flipped)
  assert len(err) > 500
  assert np.median(err) < 0.5 * np.median(control), (np.median(err), np.median(control))


def test_garden_points_and_the_sfm_start_of_the_training_views():
  config = Config(dataset_loader='transforms', data_dir=str(DATA / 'mipnerf360'),
                  scene='garden', use_ndc=False, normalize_poses=True,
                  near=0.05, far=1000., n_input_views=30, train_view_selection='coverage',
                  val_views=4, image_downsample=8)
  s = load_scene(config)
  assert s.points.shape == (27046, 3) and s.point_views is None
  lo, hi = np.array(s.bbox[0]), np.array(s.bbox[1])
  inside = np.all((s.points >= lo) & (s.points <= hi), axis=1).mean()
  assert 0.9 < inside < 1.  # The 1st-99th percentile box of the points.
  pts, rgb = start.sfm_start(s, jax.random.PRNGKey(1), 5000)
  assert pts.shape == (5000, 3) and rgb.shape == (5000, 3)
  # The ply's points are in the json's frame: reprojected into training views they land
  # on pixels of their colour (against the mirrored pixels as a control).
  err, control = [], []
  for v in s.train_idx[:6]:
    c2w = s.poses[v].astype(np.float64)
    local = (pts - c2w[:, 3]) @ c2w[:, :3]
    ok = local[:, 2] < -0.05
    u = s.focal * local[ok, 0] / -local[ok, 2] + s.width / 2
    y = -s.focal * local[ok, 1] / -local[ok, 2] + s.height / 2
    inside = (u >= 0) & (u < s.width) & (y >= 0) & (y < s.height)
    ui, yi = u[inside].astype(int), y[inside].astype(int)
    err.append(np.abs(s.images[v][yi, ui] - rgb[ok][inside]).mean(-1))
    control.append(np.abs(s.images[v][s.height - 1 - yi, s.width - 1 - ui]
                          - rgb[ok][inside]).mean(-1))
  err, control = np.concatenate(err), np.concatenate(control)
  assert len(err) > 1000 and np.median(err) < 0.6 * np.median(control)
  again, _ = start.sfm_start(s, jax.random.PRNGKey(1), 5000)
  np.testing.assert_array_equal(pts, again)  # Seeded.
  g = start.init_gaussians(Config(backbone='gaussians', gs_init='sfm', gs_init_points=5000,
                                  gs_capacity=8000), s, jax.random.PRNGKey(1))
  assert int(g.active.sum()) == 5000
  np.testing.assert_allclose(np.asarray(g.means[:5000]), pts)
  # Colour = SH_C0 * DC + 0.5: the points' colours from every side at the start.
  np.testing.assert_allclose(0.28209479177387814 * np.asarray(g.sh[:5000, 0]) + 0.5, rgb,
                             atol=1e-5)


def test_sfm_start_needs_points_and_says_so_before_training():
  from tiny_scene import TINY  # pylint: disable=g-import-not-at-top
  s = load_scene(TINY)
  with pytest.raises(DataError, match="gs_init='sfm' needs SfM points"):
    start.sfm_start(s, jax.random.PRNGKey(0), 10)
  with pytest.raises(DataError, match="gs_init='sfm' needs SfM points"):
    renerf.check_rounds_config(Config(backbone='gaussians', gs_init='sfm',
                                      lpips_nets=()), s)


def test_per_photo_cameras_need_undistort(tmp_path):
  tiny_capture(tmp_path, per_photo=True)
  with pytest.raises(DataError, match='set Config.undistort = True'):
    load_scene(_config(tmp_path))
  s = load_scene(_config(tmp_path, undistort=True))
  assert s.intrinsics is None and s.focal > 20. * 1.18  # The largest photo's focal.


@pytest.mark.parametrize('model', ['SIMPLE_PINHOLE', 'PINHOLE', 'OPENCV'])
def test_camera_models(tmp_path, model):
  tiny_capture(tmp_path, model=model)
  s = load_scene(_config(tmp_path))
  if model == 'SIMPLE_PINHOLE':
    assert s.intrinsics is None and s.focal == 20.
  else:
    assert s.intrinsics[:2] == pytest.approx((20., 21.))


def test_intrinsics_follow_the_photos_size(tmp_path):
  """Photos at half the camera's size (images_2/): the intrinsics are halved."""
  scene, _ = tiny_capture(tmp_path, size=(12, 16))
  os.makedirs(os.path.join(scene, 'images_2'))
  for f in os.listdir(os.path.join(scene, 'images')):
    img = iio.imread(os.path.join(scene, 'images', f))
    iio.imwrite(os.path.join(scene, 'images_2', f), img[::2, ::2])
  s = load_scene(_config(tmp_path, factor=2))
  assert s.images.shape[1:3] == (6, 8)
  assert s.intrinsics[:4] == pytest.approx((10., 10., 4., 3.))


def _one_line(fn):
  with pytest.raises(DataError) as e:
    fn()
  assert '\n' not in str(e.value)
  return str(e.value)


def test_bad_colmap_inputs_give_one_line_naming_the_file(tmp_path):
  scene, _ = tiny_capture(tmp_path)
  model = os.path.join(scene, 'sparse', '0')
  good = str(tmp_path / 'good')
  shutil.copytree(model, good)
  load = lambda: load_scene(_config(tmp_path))
  # Truncated binary files.
  for name in ('cameras.bin', 'images.bin', 'points3D.bin'):
    with open(os.path.join(good, name), 'rb') as f:
      data = f.read()
    with open(os.path.join(model, name), 'wb') as f:
      f.write(data[:len(data) - 5])
    assert name in _one_line(load) and 'truncated' in _one_line(load)
    shutil.copy(os.path.join(good, name), os.path.join(model, name))
  # An image listed but missing on disk.
  os.rename(os.path.join(scene, 'images', '0003.png'), str(tmp_path / 'away.png'))
  msg = _one_line(load)
  assert 'images.bin' in msg and "'0003.png' not found" in msg
  os.rename(str(tmp_path / 'away.png'), os.path.join(scene, 'images', '0003.png'))
  # Unsupported and unknown camera models.
  for model_name in ('OPENCV_FISHEYE', 'FOV'):
    write_model(model, {1: (model_name, 16, 12, (20., 20., 8., 6.) + (0.,) * (
        colmap_io.MODEL_PARAMS[model_name] - 4))}, colmap_io.read_images_bin(
            os.path.join(good, 'images.bin')), colmap_io.read_points_bin(
                os.path.join(good, 'points3D.bin')))
    msg = _one_line(load)
    assert f'camera model {model_name} is not supported' in msg and 'cameras.bin' in msg
  with open(os.path.join(model, 'cameras.bin'), 'r+b') as f:
    f.seek(12)
    f.write((99).to_bytes(4, 'little'))
  assert 'unknown model id 99' in _one_line(load)
  # An empty model.
  write_model(model, {}, [], (np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3), np.uint8), []))
  assert 'images.bin: the model holds no images' in _one_line(load)
  shutil.rmtree(model)
  assert 'sparse: no COLMAP model' in _one_line(load)


def test_bad_text_values_and_sizes_are_one_line(tmp_path):
  scene, _ = tiny_capture(tmp_path, ext='txt')
  model = os.path.join(scene, 'sparse', '0')
  load = lambda: load_scene(_config(tmp_path))
  pts = os.path.join(model, 'points3D.txt')
  with open(pts) as f:
    good = f.read()
  with open(pts, 'w') as f:
    f.write(good.replace(' 0.5', ' 0.5', 1).split('\n', 1)[0].rsplit(' ', 100)[0][:0]
            + '1 0.0 0.0 0.0 300 2 3 0.5\n')
  assert 'points3D.txt: line 1: a colour outside 0-255' in _one_line(load)
  with open(pts, 'w') as f:
    f.write(good)
  cams = os.path.join(model, 'cameras.txt')
  with open(cams, 'a') as f:
    f.write('7 PINHOLE 0 12 20 20 8 6\n')
  assert 'camera 7 is 0x12 pixels' in _one_line(load)
  # A blank line before an image line is skipped, as COLMAP's reader does.
  with open(cams) as f:
    lines = f.read().splitlines()[:-1]
  with open(cams, 'w') as f:
    f.write('\n'.join(lines) + '\n')
  imgs = os.path.join(model, 'images.txt')
  with open(imgs) as f:
    text = f.read()
  with open(imgs, 'w') as f:
    f.write('\n' + text)
  assert len(load_scene(_config(tmp_path)).poses) == 10


def test_each_photo_is_resampled_through_its_own_camera():
  """Two photos of one view direction field g(x) = x (x = (u - cx) / f) through
  different focals: resampled to the shared pinhole camera they are the same image, that
  camera's g; resampling both through the first photo's camera would not be."""
  h, w = 8, 40
  intr = [(30., 30., 20., 4., 0., 0., 0., 0.), (36., 36., 20., 4., 0., 0., 0., 0.)]
  u = np.arange(w) + 0.5
  photos = np.stack([np.broadcast_to(((u - i[2]) / i[0])[None, :, None], (h, w, 1))
                     for i in intr]).astype(np.float64)
  out, focal = undistort.undistort_each(photos, intr)
  assert focal == pytest.approx(36., rel=1e-3)  # The narrower photo decides.
  want = (u - w / 2) / focal
  np.testing.assert_allclose(out[:, 3, 1:-1, 0], np.stack([want[1:-1]] * 2), atol=1e-3)
  # Through the first photo's camera alone the two photos stay two cameras' images.
  wrong, _ = undistort.undistort_images(photos, intr[0])
  assert np.abs(wrong[1, 3, 1:-1, 0] - wrong[0, 3, 1:-1, 0]).max() > 0.05


def test_train_cli_refuses_a_bad_capture_with_exit_2_and_writes_nothing(tmp_path, capsys):
  import train  # pylint: disable=g-import-not-at-top
  scene, _ = tiny_capture(tmp_path)
  os.remove(os.path.join(scene, 'images', '0005.png'))
  run_dir = tmp_path / 'run'
  with pytest.raises(SystemExit) as e:
    train.main(['--gin_configs=gin_configs/demo.gin', f'--run_dir={run_dir}',
                "--gin_bindings=Config.dataset_loader = 'colmap'",
                f"--gin_bindings=Config.data_dir = '{tmp_path}'",
                "--gin_bindings=Config.scene = 'tiny'", '--gin_bindings=Config.factor = 1',
                '--gin_bindings=Config.n_input_views = 4'])
  assert e.value.code == 2
  err = capsys.readouterr().err.strip().splitlines()
  assert len(err) == 1 and "'0005.png' not found" in err[0]
  assert not run_dir.exists()


def test_ply_reader_ascii_and_binary(tmp_path):
  xyz = np.array([[0., 1., 2.], [3., -4., 5.5]])
  rgb = np.array([[255, 0, 10], [1, 2, 3]], np.uint8)
  head = ('ply\nformat {}\nelement vertex 2\nproperty float x\nproperty float y\n'
          'property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n'
          'end_header\n')
  ascii_path = tmp_path / 'a.ply'
  ascii_path.write_text(head.format('ascii 1.0') + ''.join(
      f'{a} {b} {c} {r} {g} {bl}\n' for (a, b, c), (r, g, bl) in zip(xyz, rgb)))
  bin_path = tmp_path / 'b.ply'
  rows = np.zeros(2, [('x', '<f4'), ('y', '<f4'), ('z', '<f4'), ('r', 'u1'), ('g', 'u1'),
                      ('b', 'u1')])
  rows['x'], rows['y'], rows['z'] = xyz.T
  rows['r'], rows['g'], rows['b'] = rgb.T
  bin_path.write_bytes(head.format('binary_little_endian 1.0').encode() + rows.tobytes())
  for path in (ascii_path, bin_path):
    p, c = read_points_ply(str(path))
    np.testing.assert_allclose(p, xyz)
    np.testing.assert_allclose(c, rgb / 255., atol=1e-7)
  bin_path.write_bytes(head.format('binary_little_endian 1.0').encode() + rows.tobytes()[:-3])
  assert 'truncated' in _one_line(lambda: read_points_ply(str(bin_path)))
  no_colour = tmp_path / 'c.ply'
  no_colour.write_text('ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n'
                       'property float y\nproperty float z\nend_header\n0 0 0\n')
  assert 'no "red" property' in _one_line(lambda: read_points_ply(str(no_colour)))
  bad = tmp_path / 'e.ply'
  bad.write_text('ply\nformat ascii 1.0\nelement vertex abc\nend_header\n')
  assert "bad header line 'element vertex abc'" in _one_line(lambda: read_points_ply(str(bad)))
  nan = tmp_path / 'd.ply'
  nan.write_text(head.format('ascii 1.0') + '0 nan 0 1 2 3\n1 1 1 1 1 1\n')
  assert 'non-finite position' in _one_line(lambda: read_points_ply(str(nan)))
