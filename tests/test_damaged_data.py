"""Damaged data, tried once each per loader (LLFF, Blender, transforms.json, the embedded
scenes' parameters, the 3DGS .ply reader): every case is one `error:` line naming the file
and what is wrong, exit 2 from train.py, no run directory made and the data untouched.
Greyscale and RGBA photos are converted on purpose (datasets/images.read_image): tested
here too. Damaged copies are built in tmp_path (from ../shared/data or written here);
../shared is never written."""
import json
import os
import shutil

import imageio.v3 as iio
import numpy as np
import pytest

import train
from conftest import LLFF_DIR, tree_files
from renerf_jax.configs import Config
from renerf_jax.datasets import load_scene
from renerf_jax.errors import DataError
from renerf_jax.gaussians import params as params_lib
from renerf_jax.gaussians import ply

RNG = np.random.default_rng(0)


def _llff(root, n=9, fmt='png'):
  """root/toy: n 6x8 photos in images_8/ and fern's first n poses."""
  scene = root / 'toy'
  (scene / 'images_8').mkdir(parents=True)
  for i in range(n):
    iio.imwrite(scene / 'images_8' / f'img{i:03d}.{fmt}',
                RNG.integers(0, 255, (6, 8, 3), dtype=np.uint8))
  np.save(scene / 'poses_bounds.npy', np.load(LLFF_DIR / 'fern' / 'poses_bounds.npy')[:n])
  return [f"Config.data_dir = '{root}'", "Config.scene = 'toy'"], scene


def _orchids_jpegs(root, n=9):
  """root/orchids: orchids' first n real JPEGs (504x378) and their poses."""
  scene = root / 'orchids'
  (scene / 'images_8').mkdir(parents=True)
  src = LLFF_DIR / 'orchids'
  for name in sorted(os.listdir(src / 'images_8'))[:n]:
    shutil.copy(src / 'images_8' / name, scene / 'images_8' / name)
  np.save(scene / 'poses_bounds.npy', np.load(src / 'poses_bounds.npy')[:n])
  return [f"Config.data_dir = '{root}'", "Config.scene = 'orchids'"], scene


def _blender(root, n_train=3, n_test=2, images=None):
  """root/lego: a Blender layout of 8x8 RGBA frames (or `images`: name -> array)."""
  scene = root / 'lego'
  for split, n in (('train', n_train), ('test', n_test)):
    (scene / split).mkdir(parents=True)
    frames = []
    for i in range(n):
      iio.imwrite(scene / split / f'r_{i}.png', RNG.integers(0, 255, (8, 8, 4), np.uint8))
      frames.append({'file_path': f'./{split}/r_{i}',
                     'transform_matrix': np.eye(4).tolist()})
    (scene / f'transforms_{split}.json').write_text(
        json.dumps({'camera_angle_x': 0.69, 'frames': frames}))
  for name, img in (images or {}).items():
    iio.imwrite(scene / name, img)
  return [f"Config.data_dir = '{root}'", "Config.scene = 'lego'",
          "Config.dataset_loader = 'blender'", "Config.blender_split = 'linspace'",
          'Config.n_input_views = 2', 'Config.use_ndc = False', 'Config.white_bkgd = True',
          'Config.near = 2.0', 'Config.far = 6.0'], scene


def _transforms(root, n=3, ext='png'):
  """root/s: a transforms.json capture of n 6x8 photos."""
  scene = root / 's'
  (scene / 'images').mkdir(parents=True)
  frames = []
  for i in range(n):
    iio.imwrite(scene / 'images' / f'{i:02d}.{ext}',
                RNG.integers(0, 255, (6, 8, 3), dtype=np.uint8))
    frames.append({'file_path': f'images/{i:02d}.{ext}',
                   'transform_matrix': np.eye(4).tolist()})
  (scene / 'transforms.json').write_text(json.dumps({'fl_x': 5., 'frames': frames}))
  return [f"Config.data_dir = '{root}'", "Config.scene = 's'",
          "Config.dataset_loader = 'transforms'", 'Config.n_input_views = 1',
          'Config.use_ndc = False', 'Config.near = 0.1', 'Config.far = 5.0'], scene


def _truncate(path, keep=0.5):
  data = path.read_bytes()
  path.write_bytes(data[:int(len(data) * keep)])


def _edit_json(path, fn):
  meta = json.loads(path.read_text())
  fn(meta)
  path.write_text(json.dumps(meta))


def _poses(scene, fn):
  path = scene / 'poses_bounds.npy'
  np.save(path, fn(np.load(path)))


# case -> (builder, damage(scene), the line's file, what the line says)
CASES = {
    'llff_truncated_jpeg': (_orchids_jpegs, lambda s: _truncate(s / 'images_8' / 'IMG_4470.JPG'),
                            'images_8/IMG_4470.JPG', 'OSError: image file is truncated'),
    'llff_truncated_png': (_llff, lambda s: _truncate(s / 'images_8' / 'img003.png', 0.3),
                           'images_8/img003.png', 'cannot read image'),
    'llff_zero_byte_image': (_llff, lambda s: (s / 'images_8' / 'img004.png').write_bytes(b''),
                             'images_8/img004.png', 'image file is empty (0 bytes)'),
    'llff_image_of_another_size': (
        _llff, lambda s: iio.imwrite(s / 'images_8' / 'img005.png', np.zeros((7, 8, 3), np.uint8)),
        'images_8/img005.png', 'is 8x7 but'),
    'llff_missing_image': (_llff, lambda s: os.remove(s / 'images_8' / 'img008.png'),
                           'poses_bounds.npy', '8 images in'),
    'llff_empty_folder': (_llff, lambda s: [os.remove(p) for p in (s / 'images_8').iterdir()],
                          'images_8', 'no images (.png/.jpg) in'),
    'llff_poses_wrong_shape': (_llff, lambda s: _poses(s, lambda a: a[:, :15]),
                               'poses_bounds.npy', 'has shape (9, 15), expected [N, 17]'),
    'llff_poses_flat': (_llff, lambda s: _poses(s, lambda a: a.ravel()),
                        'poses_bounds.npy', 'has shape (153,), expected [N, 17]'),
    'llff_poses_nan': (_llff, lambda s: _poses(s, lambda a: np.where(
        np.arange(a.size).reshape(a.shape) == 40, np.nan, a)),
                       'poses_bounds.npy', 'has NaN or inf values (first in row 2)'),
    'llff_poses_inf': (_llff, lambda s: _poses(s, lambda a: np.where(
        np.arange(a.size).reshape(a.shape) == 70, np.inf, a)),
                       'poses_bounds.npy', 'has NaN or inf values (first in row 4)'),
    'llff_bounds_negative': (_llff, lambda s: _poses(s, lambda a: np.where(
        np.arange(a.size).reshape(a.shape) == 17 * 6 + 15, -1., a)),
                             'poses_bounds.npy', 'non-positive depth bounds (first in row 6)'),
    'llff_poses_truncated': (_llff, lambda s: _truncate(s / 'poses_bounds.npy'),
                             'poses_bounds.npy', 'cannot read'),
    'llff_poses_not_npy': (_llff, lambda s: (s / 'poses_bounds.npy').write_text('poses'),
                           'poses_bounds.npy', 'is not a .npy file (no NUMPY header)'),
    'llff_poses_zero_bytes': (_llff, lambda s: (s / 'poses_bounds.npy').write_bytes(b''),
                              'poses_bounds.npy', 'is not a .npy file (no NUMPY header)'),
    'llff_poses_strings': (_llff, lambda s: np.save(s / 'poses_bounds.npy',
                                                    np.full((9, 17), 'x')),
                           'poses_bounds.npy', 'holds no numeric array'),
    'blender_truncated_json': (_blender, lambda s: _truncate(s / 'transforms_train.json'),
                               'transforms_train.json', 'malformed'),
    'blender_truncated_image': (_blender, lambda s: _truncate(s / 'train' / 'r_2.png', 0.3),
                                'train/r_2.png', 'OSError: image file is truncated'),
    'blender_zero_byte_image': (_blender, lambda s: (s / 'test' / 'r_0.png').write_bytes(b''),
                                'test/r_0.png', 'image file is empty (0 bytes)'),
    'blender_image_of_another_size': (
        _blender, lambda s: iio.imwrite(s / 'test' / 'r_1.png', np.zeros((8, 9, 4), np.uint8)),
        'test/r_1.png', 'is 9x8 but'),
    'blender_missing_image': (_blender, lambda s: os.remove(s / 'train' / 'r_2.png'),
                              'transforms_train.json', 'frame file missing'),
    'blender_no_frames': (_blender, lambda s: _edit_json(s / 'transforms_test.json',
                                                         lambda m: m.update(frames=[])),
                          'transforms_test.json', '"frames" is not a non-empty list'),
    'blender_duplicate_frames': (
        _blender, lambda s: _edit_json(s / 'transforms_train.json',
                                       lambda m: m['frames'].append(m['frames'][0])),
        'transforms_train.json', "frame 3 repeats file_path './train/r_0'"),
    'blender_frame_without_path': (
        _blender, lambda s: _edit_json(s / 'transforms_train.json',
                                       lambda m: m['frames'][1].pop('file_path')),
        'transforms_train.json', 'frame 1 has no "file_path" string'),
    'blender_matrix_nan': (
        _blender, lambda s: _edit_json(s / 'transforms_train.json', lambda m: m['frames'][0][
            'transform_matrix'][0].__setitem__(3, float('nan'))),
        'transforms_train.json', 'bad transform_matrix for ./train/r_0'),
    'blender_matrix_not_numbers': (
        _blender, lambda s: _edit_json(s / 'transforms_test.json', lambda m: m['frames'][1]
                                       .update(transform_matrix=[['a'] * 4] * 4)),
        'transforms_test.json', 'bad transform_matrix for ./test/r_1'),
    'blender_matrix_3x3': (
        _blender, lambda s: _edit_json(s / 'transforms_test.json', lambda m: m['frames'][0]
                                       .update(transform_matrix=np.eye(3).tolist())),
        'transforms_test.json', 'bad transform_matrix for ./test/r_0'),
    'blender_camera_angle_nan': (
        _blender, lambda s: _edit_json(s / 'transforms_train.json',
                                       lambda m: m.update(camera_angle_x=float('nan'))),
        'transforms_train.json', 'camera_angle_x=nan is not an angle in (0, pi)'),
    'transforms_truncated_json': (_transforms, lambda s: _truncate(s / 'transforms.json'),
                                  'transforms.json', 'JSONDecodeError'),
    'transforms_truncated_jpeg': (
        lambda root: _transforms(root, ext='jpg'),
        lambda s: _truncate(s / 'images' / '01.jpg', 0.6),
        'images/01.jpg', 'cannot read image'),
    'transforms_zero_byte_image': (_transforms,
                                   lambda s: (s / 'images' / '02.png').write_bytes(b''),
                                   'images/02.png', 'image file is empty (0 bytes)'),
    'transforms_image_of_another_size': (
        _transforms, lambda s: iio.imwrite(s / 'images' / '01.png', np.zeros((6, 9, 3), np.uint8)),
        'images/01.png', 'is 9x6 but'),
    'transforms_missing_image': (_transforms, lambda s: os.remove(s / 'images' / '00.png'),
                                 'transforms.json', "image of frame 'images/00.png' not found"),
    'transforms_no_frames': (_transforms, lambda s: _edit_json(s / 'transforms.json',
                                                               lambda m: m.update(frames=[])),
                             'transforms.json', '"frames" is empty'),
    'transforms_duplicate_frames': (
        _transforms, lambda s: _edit_json(s / 'transforms.json',
                                          lambda m: m['frames'].append(m['frames'][1])),
        'transforms.json', "frame 3 repeats file_path 'images/01.png'"),
    'transforms_matrix_inf': (
        _transforms, lambda s: _edit_json(s / 'transforms.json', lambda m: m['frames'][2][
            'transform_matrix'][1].__setitem__(3, 1e999)),
        'transforms.json', 'transform_matrix is not a finite 4x4'),
}


@pytest.mark.parametrize('case', sorted(CASES))
def test_damaged_data_is_one_line_and_exit_2_before_anything_is_written(case, tmp_path,
                                                                        capsys):
  build, damage, where, what = CASES[case]
  bindings, scene = build(tmp_path / 'data')
  damage(scene)
  before = tree_files(tmp_path / 'data', digest=True)
  run_dir = tmp_path / 'run'
  with pytest.raises(SystemExit) as e:
    train.main([f'--run_dir={run_dir}'] + [f'--gin_bindings={b}' for b in bindings])
  err = capsys.readouterr().err
  assert e.value.code == 2 and err.count('\n') == 1 and err.startswith('error: '), err
  assert f'{scene}/{where}'.rstrip('/') in err and what in err, err
  assert not run_dir.exists() and tree_files(tmp_path / 'data', digest=True) == before


def test_the_embedded_scenes_parameters_are_checked_before_rendering():
  """procedural_size / procedural_views outside their domain are Config lines; a split
  that leaves no training view is one DataError line naming the Config values."""
  for loader in ('procedural', 'orbit'):
    with pytest.raises(DataError) as e:
      load_scene(Config(dataset_loader=loader, use_ndc=loader == 'procedural',
                        procedural_views=1, n_input_views=1))
    assert str(e.value) == (f'the {loader} scene: Config.n_input_views=1 but only 0 '
                            'non-test images are available of 1 (every Config.llffhold=8-th '
                            'is a test view)')
  for binding, line in [('procedural_views = 0', 'Config.procedural_views=0 must be >= 1'),
                        ('procedural_size = (0, 8)', 'Config.procedural_size=(0, 8) must '
                         'be a tuple of 2 values, each an integer >= 1'),
                        ('procedural_size = 48', 'Config.procedural_size=48 must be a '
                         'tuple of 2 values, each an integer >= 1')]:
    with pytest.raises(Exception) as e:
      Config(**{binding.split(' = ')[0]: eval(binding.split(' = ')[1])})  # pylint: disable=eval-used
    assert str(e.value).splitlines()[0] == line


def test_greyscale_and_rgba_photos_are_converted_not_refused(tmp_path):
  """A folder may mix greyscale (L, LA), RGB and RGBA files: grey is replicated to 3
  channels, an alpha channel composites (Blender, transforms.json) or is dropped (LLFF);
  a file without one is opaque."""
  grey = np.full((8, 8), 100, np.uint8)
  grey_alpha = np.stack([np.full((8, 8), 100, np.uint8), np.full((8, 8), 0, np.uint8)], -1)
  rgb = np.full((8, 8, 3), 30, np.uint8)
  bindings, _ = _blender(tmp_path / 'b', images={'train/r_0.png': grey,
                                                 'train/r_2.png': grey_alpha,
                                                 'test/r_0.png': rgb})
  cfg = Config(**{b.split(' = ')[0][len('Config.'):]: eval(b.split(' = ')[1])  # pylint: disable=eval-used
                  for b in bindings})
  scene = load_scene(cfg)  # train frames 0 and 2 (linspace), then test 0 and 1.
  np.testing.assert_allclose(scene.images[0], 100 / 255., atol=1e-6)  # opaque grey
  np.testing.assert_allclose(scene.images[1], 1., atol=1e-6)  # transparent: white
  np.testing.assert_allclose(scene.images[2], 30 / 255., atol=1e-6)  # opaque RGB
  _, scene_dir = _transforms(tmp_path / 't', ext='png')
  iio.imwrite(scene_dir / 'images' / '01.png', grey[:6])
  iio.imwrite(scene_dir / 'images' / '02.png', np.dstack([rgb[:6], np.full((6, 8), 255,
                                                                           np.uint8)]))
  scene = load_scene(Config(dataset_loader='transforms', data_dir=str(tmp_path / 't'),
                            scene='s', n_input_views=1, near=0.1, far=5.))
  np.testing.assert_allclose(scene.images[1], 100 / 255., atol=1e-6)
  np.testing.assert_allclose(scene.images[2], 30 / 255., atol=1e-6)


def _ply_file(path, n=4):
  g = params_lib.Gaussians(
      means=RNG.normal(size=(n, 3)).astype(np.float32),
      log_scales=np.full((n, 3), -3., np.float32),
      quats=np.tile(np.float32([1, 0, 0, 0]), (n, 1)),
      opacity_logits=np.zeros(n, np.float32),
      sh=RNG.normal(size=(n, params_lib.NUM_SH, 3)).astype(np.float32),
      active=np.ones(n, bool))
  ply.write_ply(str(path), g)
  return path.read_bytes()


@pytest.mark.parametrize('case,what', [
    ('no_colours', 'not the binary little-endian 3DGS layout (no f_dc_0, f_dc_1, f_dc_2, '
                   'f_rest_0, ...)'),
    ('nan_position', 'vertex 2 has a NaN or inf y'),
    ('inf_scale', 'vertex 0 has a NaN or inf scale_1'),
    ('truncated', 'bytes of vertex data for 4 vertices'),
    ('zero_bytes', 'not a ply file'),
    ('text', 'not a ply file'),
])
def test_damaged_ply_is_one_data_error_line(case, what, tmp_path):
  path = tmp_path / 'point_cloud.ply'
  data = _ply_file(path)
  header_end = data.index(b'end_header\n') + len(b'end_header\n')
  width = len(ply.PROPERTIES)
  rows = np.frombuffer(data[header_end:], '<f4').reshape(-1, width).copy()
  if case == 'no_colours':  # A point cloud of positions only, as SfM writes some.
    keep = [i for i, p in enumerate(ply.PROPERTIES) if not p.startswith('f_')]
    header = data[:header_end].decode().splitlines()
    header = [h for h in header if not h.startswith('property float f_')]
    path.write_bytes(('\n'.join(header) + '\n').encode() + rows[:, keep].tobytes())
  elif case in ('nan_position', 'inf_scale'):
    r, c = (2, 1) if case == 'nan_position' else (0, ply.PROPERTIES.index('scale_1'))
    rows[r, c] = np.nan if case == 'nan_position' else np.inf
    path.write_bytes(data[:header_end] + rows.tobytes())
  elif case == 'truncated':
    path.write_bytes(data[:-7])
  else:
    path.write_bytes(b'' if case == 'zero_bytes' else b'x y z\n1 2 3\n')
  with pytest.raises(DataError) as e:
    ply.read_ply(str(path))
  message = str(e.value)
  assert message.startswith(f'{path}: ') and what in message and '\n' not in message
