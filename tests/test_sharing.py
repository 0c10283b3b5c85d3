"""Work shared between the variants of a table (experiments/sharing.py)."""
import dataclasses
import os

import jax
import numpy as np
import pytest

from conftest import tiny_config, tree_files
from experiments import sharing
from renerf_jax import round_driver, rundir
from renerf_jax.datasets import camera_rays, load_scene
from renerf_jax.pseudo_views import pseudo_view_poses
from renerf_jax.round_driver import load_pseudo_views


def test_sharing_rules_derive_from_the_config_field_categories():
  from renerf_jax import configs  # pylint: disable=g-import-not-at-top
  # Every Config field has a known category; the model fields affect the baseline.
  for f in dataclasses.fields(configs.Config):
    assert configs.field_category(f.name) in configs.AFFECTS, f.name
  assert 'lr_init' not in sharing.ROUND_FIELDS and 'seed' not in sharing.ROUND_FIELDS
  assert {'num_rounds', 'pseudo_until_frac', 'pseudo_mix', 'use_masks', 'hessian_rays'} <= set(
      sharing.ROUND_FIELDS)
  # Logging and evaluation settings change what a baseline reports: not shared across.
  assert 'eval_stride' not in sharing.ROUND_FIELDS
  # How D is trained never changes round 1's pseudo-views; what is rendered does.
  assert {'pseudo_frac', 'pseudo_schedule', 'renerf_init'} <= set(
      sharing.NOT_PSEUDO_VIEW_FIELDS)
  assert not {'interp_factors', 'hessian_lambda', 'mask_keep_frac'} & set(
      sharing.NOT_PSEUDO_VIEW_FIELDS)
  assert 'hessian_rays' not in sharing.HESSIAN_IRRELEVANT
  assert 'mask_keep_frac' in sharing.HESSIAN_IRRELEVANT
  assert 'num_samples' not in sharing.RENDER_IRRELEVANT
  assert 'hessian_rays' in sharing.RENDER_IRRELEVANT
  assert set(configs.fields_where('resumable')) == {
      'num_rounds', 'auto_max_rounds', 'auto_min_gain_se', 'seed_control', 'print_every',
      'render_chunk', 'hessian_chunk', 'eval_n_views', 'eval_every', 'eval_stride',
      'checkpoint_every', 'lpips_nets'}


def test_copy_baseline_shares_round_0_between_variants_only(tmp_path):
  from renerf_jax import cli  # pylint: disable=g-import-not-at-top
  from renerf_jax.errors import RunDirError  # pylint: disable=g-import-not-at-top
  config = tiny_config(max_steps=10, num_rounds=0)
  scene = load_scene(config)
  src, dst = str(tmp_path / 'src'), str(tmp_path / 'dst')
  cli.check_run_dir(config, src, create=True)
  round_driver.run_rounds(config, scene, src, show_progress=False)
  # A variant that differs only from round 1 on reuses the baseline and trains round 1.
  variant = tiny_config(max_steps=10, num_rounds=1, pseudo_schedule='all',
                        pseudo_targets='test', use_masks=True)
  assert sharing.baseline_differences(variant, {}) != []  # vs defaults: differs
  sharing.copy_baseline(variant, src, dst)
  before = tree_files(rundir.round_dir(dst, 0))
  assert before == tree_files(rundir.round_dir(src, 0))
  state = round_driver.run_rounds(variant, scene, dst, show_progress=False)
  assert len(state.metrics) == 2 and tree_files(rundir.round_dir(dst, 0)) == before
  assert rundir.is_done(rundir.round_dir(dst, 1))
  # Another baseline config, an existing destination or an unfinished source: refused.
  with pytest.raises(RunDirError, match='lr_init'):
    sharing.copy_baseline(tiny_config(max_steps=10, lr_init=1e-2), src, str(tmp_path / 'x'))
  with pytest.raises(RunDirError, match='exists'):
    sharing.copy_baseline(variant, src, dst)
  with pytest.raises(RunDirError, match='not a finished round'):
    sharing.copy_baseline(variant, str(tmp_path / 'none'), str(tmp_path / 'y'))
  assert not os.path.exists(tmp_path / 'x') and not os.path.exists(tmp_path / 'y')
  # A variant that trains D differently reuses dst's round-1 pseudo-views and masks.
  dst2 = str(tmp_path / 'dst2')
  sharing.copy_baseline(variant, src, dst2)
  cli.check_run_dir(variant, dst, create=True)  # config.json: what made dst's views
  other_lambda = tiny_config(max_steps=10, num_rounds=1, pseudo_targets='test',
                             use_masks=True, hessian_lambda=1.)
  assert not sharing.share_pseudo_views(other_lambda, dst, dst2)
  assert not sharing.share_pseudo_views(variant, src, dst2)  # src has no round 1
  assert not os.path.exists(rundir.round_dir(dst2, 1))
  early = tiny_config(max_steps=10, num_rounds=1, pseudo_schedule='early',
                      pseudo_targets='test', use_masks=True)
  assert sharing.share_pseudo_views(early, dst, dst2)
  assert not sharing.share_pseudo_views(early, dst, dst2)  # already there
  pv = lambda d: tree_files(rundir.pseudo_views_dir(rundir.round_dir(d, 1)))
  copied = pv(dst2)
  assert 'copied_from.json' in copied
  assert {k: v for k, v in copied.items() if k != 'copied_from.json'} == pv(dst)
  state = round_driver.run_rounds(early, scene, dst2, show_progress=False)
  assert pv(dst2) == copied  # used as they are, not rendered again
  np.testing.assert_array_equal(state.pseudo.masks, load_pseudo_views(
      rundir.pseudo_views_dir(rundir.round_dir(dst, 1))).masks)


def test_overlapping_view_sets_render_each_view_once_with_identical_pixels(monkeypatch):
  from renerf_jax.nerf import synthesis as pv_lib  # pylint: disable=g-import-not-at-top
  from renerf_jax.nerf import training  # pylint: disable=g-import-not-at-top
  cache = sharing.ViewCache()
  calls = []
  real = pv_lib.render_flat
  monkeypatch.setattr(pv_lib, 'render_flat',
                      lambda *a, **k: calls.append(1) or real(*a, **k))
  config = tiny_config(render_chunk=300)  # 32 x 40 = 1280 rays: a padded last chunk
  scene = load_scene(config)
  params = training.init_state(config, jax.random.PRNGKey(3)).params
  poses7, _ = pseudo_view_poses(dataclasses.replace(config, interp_factors='7x'), scene)
  poses3, _ = pseudo_view_poses(dataclasses.replace(config, interp_factors='3x_c'), scene)
  seven, info7 = pv_lib.render_pseudo_views(config, scene, params, poses7, False, cache)
  assert (cache.hits, cache.misses) == (0, 12) and len(calls) == 12
  # The pixels of the plain render (no render_fn).
  plain, _ = pv_lib.render_pseudo_views(config, scene, params, poses7[:2], False)
  np.testing.assert_array_equal(plain.images, seven.images[:2])
  calls.clear()
  # 3x_c ({.1, .9}) is part of 7x: all four views come from the cache, bit for bit, and
  # the seconds they took to render are reported.
  other = dataclasses.replace(config, interp_factors='3x_c', seed=5, pseudo_schedule='all')
  three, info3 = pv_lib.render_pseudo_views(other, scene, params, poses3, False, cache)
  assert (cache.hits, cache.misses) == (4, 12) and not calls
  idx = [int(np.flatnonzero(np.all(poses7 == p, axis=(1, 2)))[0]) for p in poses3]
  # A hit reports the seconds of the render that made it, each time.
  view = jax.tree_util.tree_map(lambda v: np.asarray(v).reshape((-1,) + v.shape[3:]),
                                camera_rays(scene, None, poses3[:1]))
  (rgb_a, s_a), (rgb_b, s_b) = cache(config, params, view), cache(config, params, view)
  assert s_a == s_b > 0. and (cache.hits, cache.misses) == (6, 12) and not calls
  np.testing.assert_array_equal(rgb_a, three.images[0].reshape(-1, 3))
  np.testing.assert_array_equal(rgb_a, rgb_b)
  assert info3['render_seconds'] > 0.
  np.testing.assert_array_equal(three.images, seven.images[idx])
  # The same views rendered in a fresh cache, alone: the same pixels (a view's rays start
  # a chunk, whatever else the round renders).
  alone, _ = pv_lib.render_pseudo_views(config, scene, params, poses3[1:2], False,
                                        sharing.ViewCache())
  np.testing.assert_array_equal(alone.images[0], seven.images[idx[1]])
  # Other params or render settings: rendered again.
  moved = jax.tree_util.tree_map(lambda x: x * 1.01, params)
  pv_lib.render_pseudo_views(config, scene, moved, poses3[1:2], False, cache)
  assert (cache.hits, cache.misses) == (6, 13)
  pv_lib.render_pseudo_views(dataclasses.replace(config, num_samples=4), scene, params,
                             poses3[1:2], False, cache)
  assert (cache.hits, cache.misses) == (6, 14)


def test_lru_cache_keeps_recent_entries_within_its_budgets():
  cache = sharing.LruCache(max_items=3, max_bytes=100)
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
  assert sharing.digest(np.arange(3)) != sharing.digest(np.arange(3.))  # dtype counts
  assert sharing.digest('a', np.zeros(2)) == sharing.digest('a', np.zeros(2))


def test_finished_rounds_of_a_run_with_the_same_config_are_copied_not_retrained(tmp_path):
  config = tiny_config(max_steps=10, num_rounds=1, pseudo_until_frac=0.5)
  scene = load_scene(config)
  src, dst = str(tmp_path / 'src'), str(tmp_path / 'dst')
  from renerf_jax import cli  # pylint: disable=g-import-not-at-top
  cli.check_run_dir(config, src, create=True)
  round_driver.run_rounds(config, scene, src, show_progress=False)
  more = dataclasses.replace(config, num_rounds=2)  # the same run, one round further
  sharing.copy_baseline(more, src, dst)
  # Another D recipe, or another B: nothing is copied.
  assert sharing.copy_finished_rounds(dataclasses.replace(more, pseudo_schedule='all'),
                                     src, dst) == []
  other_b = str(tmp_path / 'other_b')
  round_driver.run_rounds(dataclasses.replace(config, num_rounds=0, seed=4), scene, other_b,
                          show_progress=False)
  assert sharing.copy_finished_rounds(more, src, other_b) == []
  assert not os.path.exists(rundir.round_dir(dst, 1))
  assert sharing.copy_finished_rounds(more, src, dst) == [1]  # round 2 is not in src
  copied = tree_files(rundir.round_dir(dst, 1))
  assert copied.pop('copied_from.json')
  assert copied == tree_files(rundir.round_dir(src, 1))
  assert sharing.copy_finished_rounds(more, src, dst) == []  # already there
  state = round_driver.run_rounds(more, scene, dst, show_progress=False)  # trains round 2 only
  assert len(state.metrics) == 3 and rundir.is_done(rundir.round_dir(dst, 2))
  assert state.metrics[1] == round_driver.run_rounds(config, scene, src,
                                                     show_progress=False).metrics[1]


def test_hessian_pass_is_shared_only_when_nothing_it_depends_on_differs(monkeypatch):
  from renerf_jax.uncertainty import laplace  # pylint: disable=g-import-not-at-top
  from renerf_jax.uncertainty import masks as unc  # pylint: disable=g-import-not-at-top
  from tiny_scene import LAM, take, tiny_setup  # pylint: disable=g-import-not-at-top
  config, params, pool = tiny_setup()
  config = dataclasses.replace(config, deform_log2_res=1, hessian_rays=24,
                               hessian_lambda=LAM, mask_keep_frac=0.5, render_chunk=64)
  calls = []
  real = laplace.hessian_diagonal
  monkeypatch.setattr(laplace, 'hessian_diagonal',
                      lambda *a, **k: calls.append(1) or real(*a, **k))
  cache = sharing.HessianCache()
  masks = lambda cfg, p, rays: unc.compute_masks(cfg, p, pool['rays'], rays, -1., 1.,
                                                 hessian_chunk=8, sigma_fn=cache)
  pseudo = take(pool['rays'], np.arange(1, 600, 7))
  first = masks(config, params, pseudo)
  # Another view-selection variant of the same baseline: other pseudo-views and keep
  # fraction, same Hessian.
  other = dataclasses.replace(config, interp_factors='2x', mask_keep_frac=0.7)
  second = masks(other, params, take(pool['rays'], np.arange(50)))
  assert len(calls) == 1 and (cache.hits, cache.misses) == (1, 1)
  assert second.hessian_seconds == first.hessian_seconds > 0.  # the pass's, reported
  again = masks(config, params, pseudo)
  np.testing.assert_array_equal(again.uncertainty, first.uncertainty)
  np.testing.assert_array_equal(again.mask, first.mask)
  # ... and equal to the pass computed without the cache.
  fresh = unc.compute_masks(config, params, pool['rays'], pseudo, -1., 1., hessian_chunk=8)
  np.testing.assert_array_equal(fresh.uncertainty, first.uncertainty)
  # Anything the pass depends on triggers a new one: params, lambda, the rays (seed).
  calls.clear()
  masks(config, jax.tree_util.tree_map(lambda x: x * 1.01, params), pseudo)
  masks(dataclasses.replace(config, hessian_lambda=2 * LAM), params, pseudo)
  masks(dataclasses.replace(config, seed=3), params, pseudo)
  assert len(calls) == 3
  # Bounded: the oldest entries go.
  assert len(cache.cache) == sharing.HESSIAN_CACHE_SIZE


def test_table_synthesis_of_a_gaussians_baseline_is_its_backbone_renders():
  """The tables' memoised synthesis serves the NeRF only; Gaussians get their own
  Backbone.synthesize (their renders at the pseudo-view poses), not a NeRF render."""
  from renerf_jax import backbones  # pylint: disable=g-import-not-at-top
  from renerf_jax.gaussians import training as gtrain  # pylint: disable=g-import-not-at-top
  cfg = tiny_config(backbone='gaussians', procedural_size=(24, 32), gs_capacity=64,
                    gs_init_points=32, gs_tile_cap=64, interp_factors='0.5', lpips_nets=())
  scene = load_scene(cfg)
  params = gtrain.init_gaussians(cfg, scene, jax.random.PRNGKey(0))
  pv, timing, _ = sharing.memo_synthesize(cfg, scene, params)
  want, _, _ = backbones.get_backbone(cfg).synthesize(cfg, scene, params)
  assert pv.images.shape == (2, 24, 32, 3) and timing['seconds'] > 0.
  np.testing.assert_array_equal(pv.images, want.images)
  np.testing.assert_array_equal(pv.poses, want.poses)
