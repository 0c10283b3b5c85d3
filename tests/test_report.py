"""Tests for renerf_jax.report (atomic writers, tables, plots, images)."""

import json
import math
import os
import stat

import imageio.v3 as iio
import jax.numpy as jnp
import numpy as np
import pytest

from renerf_jax import figures, report


def _leftovers(directory):
  """Temporary files left by atomic writers in `directory`."""
  return [p.name for p in directory.iterdir() if p.name.endswith('.tmp')]


def test_json_round_trip_with_numpy_types(tmp_path):
  obj = {
      'psnr': np.float32(21.5),
      'steps': np.int64(7),
      'ok': np.bool_(True),
      'curve': np.arange(3, dtype=np.float64),
      'jax': jnp.array([1., 2.]),
      'nested': ({'a': np.float16(0.5)}, None, 'x'),
      np.int32(3): 'int key',
      'nan': float('nan'),
  }
  path = tmp_path / 'sub' / 'results.json'
  report.write_json(path, obj)
  text = path.read_text()
  assert '\n  "psnr": 21.5' in text  # pretty printed
  back = report.read_json(path)
  assert back['psnr'] == 21.5 and isinstance(back['psnr'], float)
  assert back['steps'] == 7 and isinstance(back['steps'], int)
  assert back['ok'] is True
  assert back['curve'] == [0., 1., 2.]
  assert back['jax'] == [1., 2.]
  assert back['nested'] == [{'a': 0.5}, None, 'x']
  assert back['3'] == 'int key'
  assert math.isnan(back['nan'])
  assert _leftovers(path.parent) == []
  # Not the 0600 mode of the temporary file: ordinary umask permissions.
  umask = os.umask(0)
  os.umask(umask)
  assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask


def test_json_failure_keeps_previous_content(tmp_path):
  path = tmp_path / 'results.json'
  report.write_json(path, {'v': 1})
  before = path.read_bytes()
  with pytest.raises(TypeError):
    report.write_json(path, {'v': 2, 'bad': object()})
  assert path.read_bytes() == before
  assert json.loads(before) == {'v': 1}
  assert _leftovers(tmp_path) == []


def test_atomic_open_writer_raising_midway(tmp_path):
  path = tmp_path / 'notes.md'
  report.write_markdown(path, 'old content')
  assert path.read_text() == 'old content\n'
  with pytest.raises(RuntimeError):
    with report.atomic_open(path, 'w') as f:
      f.write('partial new cont')
      f.flush()
      raise RuntimeError('boom')
  assert path.read_text() == 'old content\n'
  assert _leftovers(tmp_path) == []
  # A fresh target that fails is never created at all.
  with pytest.raises(RuntimeError):
    with report.atomic_open(tmp_path / 'new.bin', 'wb') as f:
      f.write(b'abc')
      raise RuntimeError('boom')
  assert not (tmp_path / 'new.bin').exists()
  assert _leftovers(tmp_path) == []


def test_markdown_table_header_rows_and_formats():
  rows = [
      {'name': 'r_0', 'psnr': 20.123, 'ssim': 0.71234, 'lpips_alex': 0.2},
      {'name': 'a|b', 'psnr': np.float32(25.0), 'ssim': 0.9},
  ]
  table = report.markdown_table(
      rows, [('name', 'Image'), ('psnr', 'PSNR'), 'ssim', 'lpips_alex'])
  lines = table.strip().split('\n')
  assert lines[0] == '| Image | PSNR | ssim | lpips_alex |'
  assert lines[1] == '|---|---|---|---|'
  assert lines[2] == '| r_0 | 20.12 | 0.712 | 0.200 |'
  assert lines[3] == '| a\\|b | 25.00 | 0.900 | - |'
  assert len(lines) == 4
  custom = report.markdown_table(rows[:1], ['psnr'], floatfmt={'psnr': '.4f'})
  assert custom.split('\n')[2] == '| 20.1230 |'
  # Default columns: union of keys in order of appearance.
  assert report.markdown_table(rows).split('\n')[0] == (
      '| name | psnr | ssim | lpips_alex |')


def test_per_image_table_mean_row():
  per_image = [
      {'name': 'a', 'psnr': 20., 'ssim': np.float64(0.5)},
      {'name': 'b', 'psnr': 30., 'ssim': 0.7, 'note': 'x'},
  ]
  rows = report.per_image_table(per_image)
  assert [r['name'] for r in rows] == ['a', 'b', 'mean']
  assert rows[-1]['psnr'] == pytest.approx(25.)
  assert rows[-1]['ssim'] == pytest.approx(0.6)
  assert 'note' not in rows[-1]
  assert per_image[0]['name'] == 'a' and len(per_image) == 2  # not mutated
  table = report.markdown_table(rows, ['name', 'psnr', 'ssim'])
  assert table.strip().split('\n')[-1] == '| mean | 25.00 | 0.600 |'


def test_plots_are_valid_pngs(tmp_path):
  curves = {
      'ours': [(10., 15.), (1., 12.), (100., 22.)],
      'baseline': [(5., 11.), (50., 18.)],
  }
  path = tmp_path / 'psnr_vs_time.png'
  figures.plot_error_vs_time(curves, path, metric='psnr')
  assert path.stat().st_size > 0
  img = iio.imread(path)
  assert img.ndim == 3 and img.shape[0] > 50 and img.shape[1] > 50
  assert img.std() > 0  # not a blank canvas
  path2 = tmp_path / 'metrics.png'
  figures.plot_metrics_vs_time(
      {'psnr': curves, 'ssim': {'ours': [(1., .5, .02), (2., .6, .03)]},  # error bars
       'lpips': {'ours': [(1., .4), (2., .3)]}}, path2, title='run')
  img2 = iio.imread(path2)
  assert img2.shape[1] > img2.shape[0]  # three side-by-side panels
  assert _leftovers(tmp_path) == []


def test_save_image_png_round_trip(tmp_path):
  img = np.linspace(0., 1., 8 * 6 * 3).reshape(8, 6, 3)
  path = tmp_path / 'img.png'
  figures.save_image_png(path, img)
  back = iio.imread(path)
  assert back.dtype == np.uint8 and back.shape == (8, 6, 3)
  np.testing.assert_array_equal(back, np.round(img * 255).astype(np.uint8))
  gray = tmp_path / 'gray.png'
  figures.save_image_png(gray, np.array([[np.nan, 2.], [-1., 0.5]]))
  np.testing.assert_array_equal(iio.imread(gray), [[0, 255], [0, 128]])
  assert _leftovers(tmp_path) == []


@pytest.mark.parametrize('x', [
    np.full((5, 7), 3.0),
    np.array([[np.nan, 1.], [np.inf, -np.inf]]),
    np.full((3, 3), np.nan),
    np.arange(12.).reshape(3, 4),
])
def test_colorize_is_finite_and_in_range(x):
  rgb = figures.colorize(x)
  assert rgb.shape == x.shape + (3,)
  assert np.all(np.isfinite(rgb))
  assert rgb.min() >= 0. and rgb.max() <= 1.
  as_u8 = figures.to_uint8(rgb)
  assert as_u8.dtype == np.uint8


def test_colorize_ordering_and_invalid_color():
  x = np.array([[0., 1.], [2., np.nan]])
  rgb = figures.colorize(x, cmap='gray')
  assert rgb[0, 0].sum() < rgb[0, 1].sum() < rgb[1, 0].sum()
  np.testing.assert_allclose(rgb[1, 1], 0.)
  # Explicit range clips values outside [lo, hi].
  clipped = figures.colorize(x, lo=0.5, hi=1., cmap='gray')
  np.testing.assert_allclose(clipped[0, 0], 0., atol=1e-6)
  np.testing.assert_allclose(clipped[1, 0], 1., atol=1e-6)
