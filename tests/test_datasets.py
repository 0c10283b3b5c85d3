import json
import os
import shutil

import imageio.v3 as iio
import numpy as np
import pytest

from renerf_jax.configs import Config
from renerf_jax.datasets import camera_rays, downsample_scene, fewshot_split, load_scene
from renerf_jax.datasets.llff import bounds_warning, raise_near_bounds
from renerf_jax.errors import ConfigError, DataError
from conftest import LLFF_DIR, tiny_config


def test_fewshot_split_fern():
  train, test = fewshot_split(20, 3, 8)
  np.testing.assert_array_equal(test, [0, 8, 16])
  np.testing.assert_array_equal(train, [1, 10, 19])
  with pytest.raises(DataError, match='n_input_views=18'):
    fewshot_split(20, 18, 8)


def test_load_fern(fern_dir):
  scene = load_scene(Config(data_dir=fern_dir, scene='fern'))
  assert scene.images.shape == (20, 378, 504, 3)
  assert scene.images.dtype == np.float32 and 0. <= scene.images.min() <= scene.images.max() <= 1.
  np.testing.assert_array_equal(scene.train_idx, [1, 10, 19])
  np.testing.assert_array_equal(scene.test_idx, [0, 8, 16])
  raw = np.load(os.path.join(fern_dir, 'fern', 'poses_bounds.npy'))
  assert scene.focal == pytest.approx(raw[0, 14] / 8.)
  assert (scene.near, scene.far, scene.use_ndc) == (0., 1., True)
  rot = scene.poses[:, :3, :3]
  np.testing.assert_allclose(rot @ np.swapaxes(rot, 1, 2), np.broadcast_to(np.eye(3), rot.shape),
                             atol=1e-5)


def test_load_blender(blender_dir):
  scene = load_scene(Config(dataset_loader='blender', data_dir=blender_dir, scene='lego',
                            n_input_views=8, use_ndc=False, white_bkgd=True, near=2.,
                            far=6.))
  assert len(scene.train_idx) == 8 and len(scene.test_idx) == 200
  assert scene.images.shape[1:] == (200, 200, 3) and not scene.use_ndc
  # Composited on white: the transparent corner is white.
  np.testing.assert_allclose(scene.images[:, 0, 0], 1., atol=1e-6)
  assert scene.focal == pytest.approx(0.5 * 200 / np.tan(0.5 * 0.6911112070083618), rel=1e-4)


def test_procedural_scene():
  config = Config(dataset_loader='procedural', procedural_size=(24, 32))
  a, b = load_scene(config), load_scene(config)
  np.testing.assert_array_equal(a.images, b.images)  # deterministic
  assert a.images.shape == (17, 24, 32, 3) and a.depths.shape == (17, 24, 32)
  np.testing.assert_array_equal(a.test_idx, [0, 8, 16])
  # Texture and depth variation; the views differ from each other.
  assert a.images.std() > 0.15
  assert a.depths.max() / a.depths.min() > 3.
  assert np.abs(a.images[1] - a.images[7]).mean() > 0.05


def test_image_downsample_fern(fern_dir):
  full = load_scene(Config(data_dir=fern_dir, scene='fern'))
  half = load_scene(Config(data_dir=fern_dir, scene='fern', image_downsample=2))
  assert half.images.shape == (20, 189, 252, 3) and half.focal == pytest.approx(full.focal / 2)
  np.testing.assert_allclose(half.images[3, 10, 7], full.images[3, 20:22, 14:16].mean((0, 1)),
                             atol=1e-6)
  np.testing.assert_array_equal(half.poses, full.poses)
  np.testing.assert_array_equal(half.test_idx, full.test_idx)


def test_downsample_rays_through_block_centres():
  """A low-res pixel's ray is the mean of its k x k source rays (odd sizes: centre crop)."""
  for size, off in [((24, 30), 0.), ((25, 31), 0.5)]:
    full = load_scene(Config(dataset_loader='procedural', procedural_size=size,
                             use_ndc=False))
    low = downsample_scene(full, 3)
    assert low.images.shape[1:3] == (8, 10) and low.depths.shape[1:] == (8, 10)
    assert low.focal == pytest.approx(full.focal / 3)
    d_full = np.asarray(camera_rays(full, [2]).directions)[0]
    d_low = np.asarray(camera_rays(low, [2]).directions)[0]
    # Crop offset (0, 0) in both cases; with one spare row and column the principal point
    # moves by half a source pixel in x and y.
    block = d_full[3:6, 6:9].mean((0, 1))
    err = np.linalg.norm(d_low[1, 2] - block)
    assert err <= off * np.sqrt(2) / full.focal + 1e-5, (size, err)
    np.testing.assert_allclose(low.images[2, 1, 2], full.images[2, 3:6, 6:9].mean((0, 1)),
                               atol=1e-6)
    assert downsample_scene(full, 1) is full


def test_image_downsample_too_large():
  with pytest.raises(DataError, match='image_downsample=30'):
    load_scene(Config(dataset_loader='procedural', procedural_size=(24, 32),
                      image_downsample=30))
  with pytest.raises(Exception, match='image_downsample=0'):
    Config(image_downsample=0)


# ---------------------------------------------------------------- bad input
def _fake_llff(tmp_path, n=9, size=(6, 8), fmt='png'):
  root = tmp_path / 'data'
  scene = root / 'toy'
  (scene / 'images_8').mkdir(parents=True)
  rng = np.random.default_rng(0)
  for i in range(n):
    iio.imwrite(scene / 'images_8' / f'img{i:03d}.{fmt}',
                rng.integers(0, 255, size + (3,), dtype=np.uint8))
  fern = np.load(LLFF_DIR / 'fern' / 'poses_bounds.npy')[:n]
  np.save(scene / 'poses_bounds.npy', fern)
  return root


def _cfg(root, **kw):
  return Config(data_dir=str(root), scene='toy', n_input_views=3, **kw)


def test_fake_llff_loads(tmp_path):
  scene = load_scene(_cfg(_fake_llff(tmp_path)))
  assert scene.images.shape == (9, 6, 8, 3)


def test_missing_data_dir(tmp_path):
  with pytest.raises(DataError, match='data directory not found'):
    load_scene(_cfg(tmp_path / 'nope'))


def test_missing_images_folder(tmp_path):
  root = _fake_llff(tmp_path)
  shutil.rmtree(root / 'toy' / 'images_8')
  with pytest.raises(DataError, match='images_8'):
    load_scene(_cfg(root))


def test_pose_count_mismatch(tmp_path):
  root = _fake_llff(tmp_path)
  os.remove(root / 'toy' / 'images_8' / 'img008.png')
  with pytest.raises(DataError, match='8 images .* but 9 poses'):
    load_scene(_cfg(root))


def test_poses_wrong_shape(tmp_path):
  root = _fake_llff(tmp_path)
  np.save(root / 'toy' / 'poses_bounds.npy', np.zeros((9, 15)))
  with pytest.raises(DataError, match=r'shape \(9, 15\)'):
    load_scene(_cfg(root))


@pytest.mark.parametrize('bad', [np.nan, np.inf, -np.inf])
def test_poses_with_nan(tmp_path, bad):
  root = _fake_llff(tmp_path)
  arr = np.load(root / 'toy' / 'poses_bounds.npy')
  arr[4, 3] = bad
  np.save(root / 'toy' / 'poses_bounds.npy', arr)
  with pytest.raises(DataError, match='NaN or inf.*row 4'):
    load_scene(_cfg(root))


def test_corrupt_png(tmp_path):
  root = _fake_llff(tmp_path)
  path = root / 'toy' / 'images_8' / 'img003.png'
  path.write_bytes(path.read_bytes()[:40])
  with pytest.raises(DataError, match='img003.png'):
    load_scene(_cfg(root))


def test_grayscale_and_rgba_images_are_converted(tmp_path):
  root = _fake_llff(tmp_path)
  iio.imwrite(root / 'toy' / 'images_8' / 'img001.png', np.full((6, 8), 128, np.uint8))
  iio.imwrite(root / 'toy' / 'images_8' / 'img002.png', np.full((6, 8, 4), 200, np.uint8))
  scene = load_scene(_cfg(root))
  np.testing.assert_allclose(scene.images[1], 128 / 255., atol=1e-6)
  np.testing.assert_allclose(scene.images[2], 200 / 255., atol=1e-6)


def test_images_of_different_sizes(tmp_path):
  root = _fake_llff(tmp_path)
  iio.imwrite(root / 'toy' / 'images_8' / 'img005.png', np.zeros((7, 8, 3), np.uint8))
  with pytest.raises(DataError, match='img005.png.*one size'):
    load_scene(_cfg(root))


def test_too_many_input_views(tmp_path):
  with pytest.raises(DataError, match='n_input_views=9'):
    load_scene(Config(data_dir=str(_fake_llff(tmp_path)), scene='toy', n_input_views=9))


def test_blender_frame_with_missing_file(tmp_path, blender_dir):
  scene = tmp_path / 'lego'
  (scene / 'train').mkdir(parents=True)
  shutil.copy(os.path.join(blender_dir, 'lego', 'train', 'r_0.png'), scene / 'train')
  for split in ('train', 'test'):
    meta = json.load(open(os.path.join(blender_dir, 'lego', f'transforms_{split}.json')))
    meta['frames'] = meta['frames'][:2]
    meta['frames'][0]['file_path'] = './train/r_0'
    meta['frames'][1]['file_path'] = './train/r_missing'
    json.dump(meta, open(scene / f'transforms_{split}.json', 'w'))
  with pytest.raises(DataError, match='r_missing.png'):
    load_scene(Config(dataset_loader='blender', data_dir=str(tmp_path), scene='lego',
                      n_input_views=1, use_ndc=False))


# ---------------------------------------------------------------- spurious near bounds
def test_raise_near_bounds():
  b = np.array([[2., 100.], [20., 80.], [5., 10.]])
  np.testing.assert_array_equal(raise_near_bounds(b, 14.), [[14., 100.], [20., 80.],
                                                            [14., 14.]])


def test_bounds_warning_names_file_and_spares_llff_captures():
  """On ../shared/data's copies: LLFF's own captures pass, the re-processed room and trex
  (spurious near bounds) are flagged."""
  for name in ('fern', 'orchids', 'fortress'):
    b = np.load(LLFF_DIR / name / 'poses_bounds.npy')[:, 15:]
    assert bounds_warning(b, name) is None, name
  for name in ('room', 'trex'):
    b = np.load(LLFF_DIR / name / 'poses_bounds.npy')[:, 15:]
    msg = bounds_warning(b, f'{name}/poses_bounds.npy')
    assert msg.startswith(f'{name}/poses_bounds.npy: near bounds vary')
    assert 'Config.llff_min_near' in msg


def test_llff_min_near_rescales_only_its_scene(tmp_path, caplog):
  """A near bound 10x too small in one image shrinks the scene 10x (warned); the override
  restores the scale of the clean capture, and only for the scene it names."""
  root = _fake_llff(tmp_path)
  clean = load_scene(_cfg(root))
  arr = np.load(root / 'toy' / 'poses_bounds.npy')
  true_near = arr[:, 15].min()
  arr[2, 15] = true_near / 10.
  np.save(root / 'toy' / 'poses_bounds.npy', arr)
  with caplog.at_level('WARNING'):
    spurious = load_scene(_cfg(root))
  assert 'poses_bounds.npy: near bounds vary 10' in caplog.text
  spread = lambda s: np.abs(s.poses[:, :3, 3]).max()
  assert spread(spurious) == pytest.approx(10. * spread(clean), rel=1e-4)
  fixed = load_scene(_cfg(root, llff_min_near=(('toy', float(true_near)), ('other', 1e3))))
  np.testing.assert_allclose(fixed.poses, clean.poses, atol=1e-6)
  assert fixed.focus_depth == pytest.approx(clean.focus_depth)
  assert _cfg(root, llff_min_near=(('other', 1e3),)).llff_min_near == ()
  for bad in [(('toy', 0.),), (('toy', float('inf')),), (('toy', True),), ((14., 'toy'),),
              ('toy',)]:
    with pytest.raises(ConfigError, match='llff_min_near'):
      _cfg(root, llff_min_near=bad)


def test_camera_rays_cached_generator_equals_a_fresh_jit():
  """camera_rays keeps one jitted generator per camera; its rays are bit-identical to a
  jit built for the call (as it was before), for NDC and for distorted intrinsics."""
  import dataclasses  # pylint: disable=g-import-not-at-top
  import jax  # pylint: disable=g-import-not-at-top
  import jax.numpy as jnp  # pylint: disable=g-import-not-at-top
  from renerf_jax import cameras  # pylint: disable=g-import-not-at-top
  from renerf_jax.datasets import camera_rays  # pylint: disable=g-import-not-at-top
  from renerf_jax.datasets.procedural import load_procedural  # pylint: disable=g-import-not-at-top
  base = load_procedural(tiny_config())
  scenes = [base,
            dataclasses.replace(base, use_ndc=True, near=np.float32(0.), far=np.float32(1.),
                                focal=np.float32(base.focal) * np.float32(1.1)),
            dataclasses.replace(base, use_ndc=False,
                                intrinsics=(41.3, 39.7, 20.2, 15.9, .05, -.01, .002, 0.))]
  for sc in scenes:
    fresh = jax.jit(jax.vmap(lambda c2w, sc=sc: cameras.image_rays(
        c2w, sc.height, sc.width, sc.focal, sc.use_ndc, sc.near, sc.far, sc.intrinsics)))
    want = fresh(jnp.asarray(sc.poses[:2], jnp.float32))
    for _ in range(2):  # The second call reuses the cached generator.
      got = camera_rays(sc, [0, 1])
      for a, b in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(want)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
