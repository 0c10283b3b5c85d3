"""The run directory on disk: its layout (rundir) and the files of a round's results
(round_driver: evaluations and pseudo-views), read back."""
import json
import os

import imageio.v2 as imageio
import numpy as np

from renerf_jax.evaluation import Evaluation
from renerf_jax import rundir
from renerf_jax.pseudo_views import PseudoViews
from renerf_jax.round_driver import load_pseudo_views, save_evaluation, save_pseudo_views


def test_save_evaluation_writes_metrics_and_renders(tmp_path):
  rng = np.random.default_rng(0)
  per_image = [{'name': 'test_003', 'psnr': 20., 'ssim': .5},
               {'name': 'test_011', 'psnr': 24., 'ssim': .7}]
  ev = Evaluation(per_image=per_image, mean={'psnr': 22., 'ssim': .6},
                  images=rng.random((2, 5, 7, 3)).astype(np.float32),
                  distances=rng.random((2, 5, 7)).astype(np.float32),
                  columns=('name', 'psnr', 'ssim'))
  save_evaluation(str(tmp_path / 'eval'), ev)
  saved = json.loads((tmp_path / 'eval' / 'metrics.json').read_text())
  assert saved == {'per_image': per_image, 'mean': {'psnr': 22., 'ssim': .6}}
  md = (tmp_path / 'eval' / 'metrics.md').read_text()
  assert 'test_011' in md and 'mean' in md and 'lpips' not in md
  png = imageio.imread(tmp_path / 'eval' / 'test_011.png')
  np.testing.assert_array_equal(png, np.round(ev.images[1] * 255).astype(np.uint8))
  assert imageio.imread(tmp_path / 'eval' / 'depth_003.png').shape == (5, 7, 3)
  save_evaluation(str(tmp_path / 'quiet'), ev, save_png=False)
  assert sorted(p.name for p in (tmp_path / 'quiet').iterdir()) == ['metrics.json',
                                                                     'metrics.md']


def test_pseudo_views_round_trip_bit_exact(tmp_path):
  rng = np.random.default_rng(1)
  pv = PseudoViews(images=rng.random((3, 4, 6, 3)).astype(np.float32),
                   poses=rng.standard_normal((3, 3, 4)).astype(np.float32),
                   masks=(rng.random((3, 4, 6)) > .5).astype(np.float32),
                   uncertainty=rng.random((3, 4, 6)).astype(np.float32))
  assert load_pseudo_views(str(tmp_path / 'views')) is None  # not written yet
  save_pseudo_views(str(tmp_path / 'views'), pv, [{'i': i} for i in range(3)])
  back = load_pseudo_views(str(tmp_path / 'views'))
  for k in ('images', 'poses', 'masks', 'uncertainty'):
    np.testing.assert_array_equal(getattr(back, k), getattr(pv, k))
  names = {p.name for p in (tmp_path / 'views').iterdir()}
  assert {'views.npz', 'views.json', 'view_002.png', 'mask_002.png',
          'uncertainty_002.png', 'panel_002.png'} <= names
  assert not any(n.endswith('.tmp') for n in names)


def test_run_directory_layout_is_the_documented_one():
  """Every path of a run, as docs/run_directory.md lists it (runs written before keep
  resuming and loading: a renamed file would orphan them)."""
  run = os.path.join('runs', 'x')
  rdir = rundir.round_dir(run, 2)
  train, ev, pv = rundir.train_dir(rdir), rundir.eval_dir(rdir), rundir.pseudo_views_dir(rdir)
  rel = lambda path: os.path.relpath(path, run).replace(os.sep, '/')
  assert [rel(p) for p in (
      rundir.config_json_path(run), rundir.config_gin_path(run),
      *rundir.rounds_table_paths(run), *rundir.eval_rounds_paths(run),
      rundir.error_vs_time_path(run), rundir.shared_baseline_path(run))] == [
          'config.json', 'config.gin', 'rounds.json', 'rounds.md', 'eval_rounds.json',
          'eval_rounds.md', 'error_vs_time.png', 'shared_baseline.json']
  assert [rel(p) for p in (
      rdir, rundir.params_path(rdir), rundir.result_path(rdir), rundir.done_path(rdir),
      rundir.point_cloud_path(rdir), rundir.copied_from_path(rdir),
      rundir.eval_extra_dir(rdir))] == [
          'round_2', 'round_2/params.msgpack', 'round_2/result.json', 'round_2/DONE',
          'round_2/point_cloud.ply', 'round_2/copied_from.json', 'round_2/eval_extra']
  assert [rel(p) for p in (
      *rundir.training_paths(train), rundir.round_log_path(run, 2),
      rundir.round_checkpoints_dir(run, 2),
      rundir.checkpoint_path(rundir.checkpoints_dir(train), 40))] == [
          'round_2/train/checkpoints', 'round_2/train/log.jsonl', 'round_2/train/log.jsonl',
          'round_2/train/checkpoints',
          'round_2/train/checkpoints/checkpoint_00000040.msgpack']
  assert [rel(p) for p in (
      rundir.metrics_path(ev), rundir.metrics_md_path(ev), rundir.render_path(ev, 'test_003'),
      rundir.depth_render_path(ev, 'test_003'))] == [
          'round_2/eval/metrics.json', 'round_2/eval/metrics.md', 'round_2/eval/test_003.png',
          'round_2/eval/depth_003.png']
  assert [rel(p) for p in (
      rundir.views_npz_path(pv), rundir.views_json_path(pv), rundir.timing_path(pv),
      *(rundir.pseudo_view_png_path(pv, k, 7) for k in ('view', 'mask', 'uncertainty',
                                                         'panel')))] == [
          'round_2/pseudo_views/views.npz', 'round_2/pseudo_views/views.json',
          'round_2/pseudo_views/timing.json', 'round_2/pseudo_views/view_007.png',
          'round_2/pseudo_views/mask_007.png', 'round_2/pseudo_views/uncertainty_007.png',
          'round_2/pseudo_views/panel_007.png']


def test_markers_and_stale_temp_files(tmp_path):
  rdir = rundir.round_dir(str(tmp_path), 0)
  assert not rundir.is_done(rdir)
  rundir.mark_done(rdir, {'round': 0})
  assert rundir.is_done(rdir)
  assert json.loads(open(rundir.done_path(rdir)).read()) == {'round': 0}
  os.makedirs(rundir.checkpoints_dir(rundir.train_dir(rdir)))
  stale = os.path.join(rundir.checkpoints_dir(rundir.train_dir(rdir)),
                       '.checkpoint_00000010.msgpack.abc123.tmp')
  open(stale, 'w').close()
  assert rundir.remove_stale_temp_files(rdir) == [stale]
  assert sorted(os.listdir(rdir)) == ['DONE', 'train']
