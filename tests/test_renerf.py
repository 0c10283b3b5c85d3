import dataclasses
import os

import jax
import numpy as np
import pytest

from renerf_jax import renerf, rundir
from renerf_jax.datasets import load_scene
from renerf_jax.pseudo_views import pseudo_view_poses, uncertainty_heatmap
from renerf_jax.errors import ConfigError
from conftest import tiny_config


def _files(directory):
  out = {}
  for root, _, files in os.walk(directory):
    for f in files:
      p = os.path.join(root, f)
      out[os.path.relpath(p, directory)] = open(p, 'rb').read()
  return out


def test_round_state_is_a_pytree():
  config = tiny_config()
  state = renerf.initial_state(config)
  state = state.replace(params={'w': np.ones(3)}, metrics=({'psnr': 20.},))
  doubled = jax.tree_util.tree_map(lambda x: x * 2, state)
  assert float(doubled.metrics[0]['psnr']) == 40.
  np.testing.assert_array_equal(doubled.params['w'], 2.)
  assert len(jax.tree_util.tree_leaves(state)) >= 4


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
  config = tiny_config(num_rounds=1, max_steps=20, pseudo_until=10, use_masks=True,
                       deform_log2_res=2, hessian_rays=256, mask_keep_frac=0.7)
  scene = load_scene(config)
  run_dir = str(tmp_path / 'run')
  state = renerf.run_rounds(config, scene, run_dir, show_progress=False)
  assert int(state.round_index) == 1 and len(state.metrics) == 2
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
  before = _files(run_dir)
  again = renerf.run_rounds(config, scene, run_dir, show_progress=False)
  assert _files(run_dir) == before
  assert again.metrics == state.metrics
  jax.tree_util.tree_map(np.testing.assert_array_equal, again.params, state.params)


def test_all_masked_pseudo_views_still_train_on_real_views(tmp_path):
  config = tiny_config(num_rounds=1, max_steps=10, pseudo_until=10, use_masks=True,
                       deform_log2_res=1, hessian_rays=64, mask_threshold=0.)
  scene = load_scene(config)
  state = renerf.run_rounds(config, scene, str(tmp_path / 'run'), show_progress=False)
  assert state.pseudo.masks.max() == 0.
  assert np.isfinite(state.metrics[1]['psnr']) and state.metrics[1]['nan_skips'] == 0


def test_copy_baseline_shares_round_0_between_variants_only(tmp_path):
  from renerf_jax import cli  # pylint: disable=g-import-not-at-top
  from renerf_jax.errors import RunDirError  # pylint: disable=g-import-not-at-top
  config = tiny_config(max_steps=10, num_rounds=0)
  scene = load_scene(config)
  src, dst = str(tmp_path / 'src'), str(tmp_path / 'dst')
  cli.check_run_dir(config, src, create=True)
  renerf.run_rounds(config, scene, src, show_progress=False)
  # A variant that differs only from round 1 on reuses the baseline and trains round 1.
  variant = tiny_config(max_steps=10, num_rounds=1, pseudo_schedule='all',
                        pseudo_targets='test', use_masks=True)
  assert renerf.baseline_differences(variant, {}) != []  # vs defaults: differs
  renerf.copy_baseline(variant, src, dst)
  before = _files(os.path.join(dst, 'round_0'))
  assert before == _files(os.path.join(src, 'round_0'))
  state = renerf.run_rounds(variant, scene, dst, show_progress=False)
  assert len(state.metrics) == 2 and _files(os.path.join(dst, 'round_0')) == before
  assert rundir.is_done(os.path.join(dst, 'round_1'))
  # Another baseline config, an existing destination or an unfinished source: refused.
  with pytest.raises(RunDirError, match='lr_init'):
    renerf.copy_baseline(tiny_config(max_steps=10, lr_init=1e-2), src, str(tmp_path / 'x'))
  with pytest.raises(RunDirError, match='exists'):
    renerf.copy_baseline(variant, src, dst)
  with pytest.raises(RunDirError, match='not a finished round'):
    renerf.copy_baseline(variant, str(tmp_path / 'none'), str(tmp_path / 'y'))
  assert not os.path.exists(tmp_path / 'x') and not os.path.exists(tmp_path / 'y')
  # A variant that trains D differently reuses dst's round-1 pseudo-views and masks.
  dst2 = str(tmp_path / 'dst2')
  renerf.copy_baseline(variant, src, dst2)
  cli.check_run_dir(variant, dst, create=True)  # config.json: what made dst's views
  other_lambda = tiny_config(max_steps=10, num_rounds=1, pseudo_targets='test',
                             use_masks=True, hessian_lambda=1.)
  assert not renerf.share_pseudo_views(other_lambda, dst, dst2)
  assert not renerf.share_pseudo_views(variant, src, dst2)  # src has no round 1
  assert not os.path.exists(os.path.join(dst2, 'round_1'))
  early = tiny_config(max_steps=10, num_rounds=1, pseudo_schedule='early',
                      pseudo_targets='test', use_masks=True)
  assert renerf.share_pseudo_views(early, dst, dst2)
  assert not renerf.share_pseudo_views(early, dst, dst2)  # already there
  pv = lambda d: _files(os.path.join(d, 'round_1', 'pseudo_views'))
  copied = pv(dst2)
  assert 'copied_from.json' in copied
  assert {k: v for k, v in copied.items() if k != 'copied_from.json'} == pv(dst)
  state = renerf.run_rounds(early, scene, dst2, show_progress=False)
  assert pv(dst2) == copied  # used as they are, not rendered again
  np.testing.assert_array_equal(state.pseudo.masks, renerf.load_pseudo_views(
      os.path.join(dst, 'round_1', 'pseudo_views')).masks)


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


def test_overlapping_view_sets_render_each_view_once_with_identical_pixels(monkeypatch):
  from renerf_jax import memo  # pylint: disable=g-import-not-at-top
  from renerf_jax import pseudo_views as pv_lib  # pylint: disable=g-import-not-at-top
  from renerf_jax import training  # pylint: disable=g-import-not-at-top
  monkeypatch.setattr(pv_lib, '_VIEW_CACHE', memo.LruCache(max_bytes=1 << 30))
  calls = []
  real = pv_lib.render_flat
  monkeypatch.setattr(pv_lib, 'render_flat',
                      lambda *a, **k: calls.append(1) or real(*a, **k))
  config = tiny_config(render_chunk=300)  # 32 x 40 = 1280 rays: a padded last chunk
  scene = load_scene(config)
  params = training.init_state(config, jax.random.PRNGKey(3)).params
  poses7, _ = pseudo_view_poses(dataclasses.replace(config, interp_factors='7x'), scene)
  poses3, _ = pseudo_view_poses(dataclasses.replace(config, interp_factors='3x_c'), scene)
  seven, info7 = pv_lib.render_pseudo_views(config, scene, params, poses7, False)
  assert info7 == {'rendered_views': 12, 'cached_views': 0, 'cached_seconds': 0.}
  assert len(calls) == 12
  # 3x_c ({.1, .9}) is part of 7x: all four views come from the cache, bit for bit, and
  # the seconds they took to render are reported.
  other = dataclasses.replace(config, interp_factors='3x_c', seed=5, pseudo_schedule='all')
  three, info3 = pv_lib.render_pseudo_views(other, scene, params, poses3, False)
  assert info3['cached_views'] == 4 and info3['rendered_views'] == 0 and len(calls) == 12
  assert info3['cached_seconds'] > 0.
  idx = [int(np.flatnonzero(np.all(poses7 == p, axis=(1, 2)))[0]) for p in poses3]
  np.testing.assert_array_equal(three.images, seven.images[idx])
  # The same views rendered in a fresh cache, alone: the same pixels (a view's rays start
  # a chunk, whatever else the round renders).
  monkeypatch.setattr(pv_lib, '_VIEW_CACHE', memo.LruCache(max_bytes=1 << 30))
  alone, _ = pv_lib.render_pseudo_views(config, scene, params, poses3[1:2], False)
  np.testing.assert_array_equal(alone.images[0], seven.images[idx[1]])
  # Other params or render settings: rendered again.
  moved = jax.tree_util.tree_map(lambda x: x * 1.01, params)
  _, info = pv_lib.render_pseudo_views(config, scene, moved, poses3[1:2], False)
  assert info['rendered_views'] == 1
  _, info = pv_lib.render_pseudo_views(dataclasses.replace(config, num_samples=4), scene,
                                       params, poses3[1:2], False)
  assert info['rendered_views'] == 1


def test_lru_cache_keeps_recent_entries_within_its_budgets():
  from renerf_jax import memo  # pylint: disable=g-import-not-at-top
  cache = memo.LruCache(max_items=3, max_bytes=100)
  for k in 'abc':
    cache.put(k, np.zeros(3, np.float64))  # 24 bytes each
  assert cache.get('a') is not None  # 'a' is now the most recent
  cache.put('d', np.zeros(3))
  assert 'b' not in cache and all(k in cache for k in 'acd') and len(cache) == 3
  cache.put('e', np.zeros(7))  # 56 bytes: 'c' and 'a' go to stay within 100 bytes
  assert [k in cache for k in 'acde'] == [False, False, True, True]
  cache.put('huge', np.zeros(20))  # 160 bytes: larger than the budget, not stored
  assert 'huge' not in cache and 'd' in cache
  assert cache.get('nothing') is None
  assert memo.digest(np.arange(3)) != memo.digest(np.arange(3.))  # dtype counts
  assert memo.digest('a', np.zeros(2)) == memo.digest('a', np.zeros(2))


def test_finished_rounds_of_a_run_with_the_same_config_are_copied_not_retrained(tmp_path):
  config = tiny_config(max_steps=10, num_rounds=1, pseudo_until=5)
  scene = load_scene(config)
  src, dst = str(tmp_path / 'src'), str(tmp_path / 'dst')
  from renerf_jax import cli  # pylint: disable=g-import-not-at-top
  cli.check_run_dir(config, src, create=True)
  renerf.run_rounds(config, scene, src, show_progress=False)
  more = dataclasses.replace(config, num_rounds=2)  # the same run, one round further
  renerf.copy_baseline(more, src, dst)
  # Another D recipe, or another B: nothing is copied.
  assert renerf.copy_finished_rounds(dataclasses.replace(more, pseudo_schedule='all'),
                                     src, dst) == []
  other_b = str(tmp_path / 'other_b')
  renerf.run_rounds(dataclasses.replace(config, num_rounds=0, seed=4), scene, other_b,
                    show_progress=False)
  assert renerf.copy_finished_rounds(more, src, other_b) == []
  assert not os.path.exists(os.path.join(dst, 'round_1'))
  assert renerf.copy_finished_rounds(more, src, dst) == [1]  # round 2 is not in src
  copied = _files(os.path.join(dst, 'round_1'))
  assert copied.pop('copied_from.json')
  assert copied == _files(os.path.join(src, 'round_1'))
  assert renerf.copy_finished_rounds(more, src, dst) == []  # already there
  state = renerf.run_rounds(more, scene, dst, show_progress=False)  # trains round 2 only
  assert len(state.metrics) == 3 and rundir.is_done(os.path.join(dst, 'round_2'))
  assert state.metrics[1] == renerf.run_rounds(config, scene, src,
                                               show_progress=False).metrics[1]
