import os

import jax
import numpy as np
import pytest

from renerf_jax import renerf, resume, rundir
from renerf_jax.datasets import load_scene
from renerf_jax.pseudo_views import pseudo_view_poses, uncertainty_heatmap
from renerf_jax.errors import ConfigError
from conftest import tiny_config, tree_files


def test_round_state_is_a_pytree_of_arrays_with_static_bookkeeping():
  state = renerf.initial_state().replace(params={'w': np.ones(3)}, round_index=2,
                                         metrics=({'psnr': 20.},), seconds=5.)
  assert jax.tree_util.tree_leaves(state) == [state.params['w']]  # only arrays are leaves
  doubled = jax.tree_util.tree_map(lambda x: x * 2, state)
  np.testing.assert_array_equal(doubled.params['w'], 2.)
  assert doubled.metrics == ({'psnr': 20.},) and doubled.round_index == 2
  assert isinstance(doubled.seconds, float) and doubled.seconds == 5.


def test_round_step_is_pure_and_equals_the_persisted_round(tmp_path, monkeypatch):
  """The in-memory step writes nothing and gives what the run-directory edge stores."""
  config = tiny_config(num_rounds=1, max_steps=10, pseudo_until_frac=0.5, use_masks=True,
                       deform_log2_res=2, hessian_rays=128)
  scene = load_scene(config)
  monkeypatch.chdir(tmp_path)
  state = renerf.run_rounds(config, scene)
  assert os.listdir(tmp_path) == []  # no file written anywhere relative to cwd
  assert state.round_index == 1 and [m['round'] for m in state.metrics] == [0, 1]
  on_disk = resume.run_rounds(config, scene, str(tmp_path / 'run'), show_progress=False)
  jax.tree_util.tree_map(np.testing.assert_array_equal, state.params, on_disk.params)
  np.testing.assert_array_equal(state.pseudo.images, on_disk.pseudo.images)
  np.testing.assert_array_equal(state.pseudo.masks, on_disk.pseudo.masks)
  for a, b in zip(state.metrics, on_disk.metrics):
    assert a['psnr'] == b['psnr'] and a['ssim'] == b['ssim']
  assert [c['eval_psnr'] for c in state.curves[1]] == [
      c['eval_psnr'] for c in on_disk.curves[1]]


def test_pseudo_view_poses_7x_on_three_views():
  config = tiny_config()
  scene = load_scene(config)
  poses, meta = pseudo_view_poses(config, scene)
  assert poses.shape == (12, 3, 4)  # 2 pairs x 6 factors
  assert sorted({m['beta'] for m in meta}) == [0.1, 0.2, 0.4, 0.6, 0.8, 0.9]
  both, meta = pseudo_view_poses(tiny_config(pseudo_targets='interp+test'), scene)
  assert both.shape == (15, 3, 4) and meta[-1] == {'kind': 'test', 'view': 16}
  rnd, meta = pseudo_view_poses(tiny_config(pseudo_targets='test+random',
                                            pseudo_n_random=4), scene)
  assert rnd.shape == (7, 3, 4) and [m['kind'] for m in meta] == ['test'] * 3 + ['random'] * 4
  rot = rnd[3:, :, :3].astype(np.float64)
  np.testing.assert_allclose(rot @ np.swapaxes(rot, 1, 2), np.broadcast_to(np.eye(3), rot.shape),
                             atol=1e-5)
  assert len({tuple(np.round(p[:, 3], 6)) for p in rnd[3:]}) == 4  # distinct positions
  again, _ = pseudo_view_poses(tiny_config(pseudo_targets='random'), scene)
  np.testing.assert_array_equal(again, rnd[3:])  # the same poses in every round
  with pytest.raises(ConfigError, match='pseudo_n_random'):
    pseudo_view_poses(tiny_config(pseudo_targets='random', pseudo_n_random=0), scene)
  with pytest.raises(ConfigError, match='pseudo_targets'):
    pseudo_view_poses(tiny_config(pseudo_targets='interp+views'), scene)
  with pytest.raises(ConfigError, match='interp_factors'):
    pseudo_view_poses(tiny_config(interp_factors='0.5,1.5'), scene)


def test_rounds_schedule_resume_and_masks(tmp_path):
  config = tiny_config(num_rounds=1, max_steps=20, pseudo_until_frac=0.5, use_masks=True,
                       deform_log2_res=2, hessian_rays=256, mask_keep_frac=0.7)
  scene = load_scene(config)
  run_dir = str(tmp_path / 'run')
  state = resume.run_rounds(config, scene, run_dir, show_progress=False)
  assert state.round_index == 1 and len(state.metrics) == 2
  assert state.metrics[1]['cumulative_seconds'] > state.metrics[0]['cumulative_seconds']
  # Pseudo rays are sampled before K = 10 and removed after.
  log = rundir.read_jsonl(os.path.join(run_dir, 'round_1', 'train', 'log.jsonl'))
  assert [r['pseudo_rays'] > 0 for r in log] == [r['step'] <= 10 for r in log]
  assert all(r['pseudo_rays'] == 0 for r in
             rundir.read_jsonl(os.path.join(run_dir, 'round_0', 'train', 'log.jsonl')))
  # Masks keep ~70% of the pseudo pixels; they were stored with the pseudo-views.
  assert state.pseudo.masks.mean() == pytest.approx(0.7, abs=0.02)
  assert state.pseudo.uncertainty.max() > 0
  # Side-by-side PNG: view | uncertainty | masked view, masked pixels black in the third.
  import imageio.v3 as iio
  panel = iio.imread(os.path.join(run_dir, 'round_1', 'pseudo_views', 'panel_000.png'))
  h, w = state.pseudo.images.shape[1:3]
  assert panel.shape[:2] == (h, 3 * w + 8)
  third = panel[:, 2 * w + 8:]
  assert np.all(third[state.pseudo.masks[0].reshape(h, w) == 0] == 0)
  # A rerun skips the finished rounds and rewrites nothing.
  before = tree_files(run_dir)
  again = resume.run_rounds(config, scene, run_dir, show_progress=False)
  assert tree_files(run_dir) == before
  assert again.metrics == state.metrics
  jax.tree_util.tree_map(np.testing.assert_array_equal, again.params, state.params)


def test_all_masked_pseudo_views_still_train_on_real_views(tmp_path):
  config = tiny_config(num_rounds=1, max_steps=10, pseudo_until_frac=1., use_masks=True,
                       deform_log2_res=1, hessian_rays=64, mask_threshold=0.)
  scene = load_scene(config)
  state = resume.run_rounds(config, scene, str(tmp_path / 'run'), show_progress=False)
  assert state.pseudo.masks.max() == 0.
  assert np.isfinite(state.metrics[1]['psnr']) and state.metrics[1]['nan_skips'] == 0


def test_uncertainty_heatmap_shows_the_order_despite_outliers_and_bad_values():
  # U clustered just below the prior sigma, one huge outlier, a zero, NaN and inf.
  u = np.full((4, 5), 122.4)
  u[0, :4] = [120.0, 121.0, 122.0, 122.3]
  u[1, 0], u[1, 1], u[1, 2], u[1, 3] = 1e30, 0., np.nan, np.inf
  heat = uncertainty_heatmap(u)
  assert heat.shape == (4, 5, 3) and np.all(np.isfinite(heat))
  assert np.all((heat >= 0.) & (heat <= 1.))
  colours = [tuple(heat[0, i]) for i in range(4)]
  assert len(set(colours)) == 4  # 120 < 121 < 122 < 122.3 stay distinguishable
  np.testing.assert_array_equal(heat[1, 2], 0.)  # NaN is drawn black
  # A shared reference scale: the same U gets the same colour in every view.
  other = np.full((2, 2), 121.0)
  np.testing.assert_allclose(uncertainty_heatmap(other, u)[0, 0], heat[0, 1])
