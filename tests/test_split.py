"""The few-shot split (datasets/split.py): test views, the 'linspace' and 'coverage'
training views, the validation views, and what uses them (the oracle's unused views,
the validation metrics of a round)."""
import dataclasses

import numpy as np
import pytest

from conftest import BLENDER_DIR, LLFF_DIR, tiny_config
from renerf_jax import pseudo_views, renerf
from renerf_jax.configs import Config
from renerf_jax.datasets import load_scene
from renerf_jax.datasets.scene import fewshot_split
from renerf_jax.datasets.split import (camera_distances, coverage_views, leave_out_view,
                                       split_views)
from renerf_jax.errors import ConfigError, DataError


def ring(n, radius=2., wobble=0.):
  """n cameras on a circle in the xz-plane looking at the origin (OpenGL c2w), the
  ring's order shuffled by index so that 'linspace' is not coverage."""
  poses = []
  for a in np.linspace(0, 2 * np.pi, n, endpoint=False):
    back = np.array([np.sin(a), 0., np.cos(a)])  # +z of the camera: away from the origin
    right = np.cross([0., 1., 0.], back)
    poses.append(np.stack([right, [0., 1., 0.], back, radius * back + [0, wobble, 0]], 1))
  return np.stack(poses)


def test_linspace_is_regnerfs_split():
  train, val, test = split_views(np.zeros((20, 3, 4)), 3, 8)
  assert test.tolist() == [0, 8, 16] and train.tolist() == [1, 10, 19] and not len(val)
  assert [a.tolist() for a in fewshot_split(20, 3, 8)] == [[1, 10, 19], [0, 8, 16]]


def test_coverage_spreads_the_views_round_a_ring():
  poses = ring(48)
  order = np.random.default_rng(0).permutation(48)  # Photo names need not follow the ring.
  poses = poses[order]
  train, val, test = split_views(poses, 4, 8, 'coverage', val_views=3)
  assert len(set(train.tolist()) | set(val.tolist()) | set(test.tolist())) == 4 + 3 + 6
  angles = np.sort(np.degrees(np.arctan2(poses[train, 0, 3], poses[train, 2, 3])) % 360)
  gaps = np.diff(np.concatenate([angles, angles[:1] + 360]))
  assert gaps.min() > 60  # 90 degrees apart up to the test views taken out (every 8th).
  lin = split_views(poses, 4, 8, 'linspace')[0]
  lin_angles = np.sort(np.degrees(np.arctan2(poses[lin, 0, 3], poses[lin, 2, 3])) % 360)
  lin_gaps = np.diff(np.concatenate([lin_angles, lin_angles[:1] + 360]))
  assert lin_gaps.min() < gaps.min()  # Evenly by (shuffled) index is not coverage.
  again = split_views(poses, 4, 8, 'coverage', val_views=3)
  assert all(np.array_equal(a, b) for a, b in zip(again, (train, val, test)))


def test_coverage_first_view_and_distance():
  poses = ring(8)
  poses[3, :3, 3] *= 0.1  # The camera nearest the centres' mean.
  assert coverage_views(poses, np.arange(8), 1).tolist() == [3]
  d = camera_distances(ring(4))
  assert d[0, 0] == pytest.approx(0.) and d[0, 2] == pytest.approx(2. + 2.)  # Opposite.
  assert coverage_views(poses, np.arange(8), 0).tolist() == []


def test_validation_views_are_spread_over_the_unused_photos():
  train, val, test = split_views(np.zeros((20, 3, 4)), 3, 8, val_views=4)
  unused = sorted(set(range(20)) - set(train) - set(test))
  assert val.tolist() == [unused[0], unused[4], unused[9], unused[13]]
  with pytest.raises(DataError, match='val_views=15 but only 14 images'):
    split_views(np.zeros((20, 3, 4)), 3, 8, val_views=15)


def test_fern_validation_views_and_the_oracle_never_uses_them():
  config = Config(data_dir=str(LLFF_DIR), val_views=4)
  s = load_scene(config)
  assert len(s.val_idx) == 4 and not set(s.val_idx) & (set(s.train_idx) | set(s.test_idx))
  assert not set(pseudo_views.unused_views(s)) & set(s.val_idx)
  assert len(pseudo_views.unused_views(s)) == 20 - 3 - 3 - 4


def test_leave_out_view_holds_one_training_view_out_as_the_only_validation_view():
  """Config.leave_out_view = j (issue 64's probe): the j-th training view is neither
  trained on nor an oracle target, it is the validation view; the test views stay."""
  base = load_scene(Config(data_dir=str(LLFF_DIR)))
  for j in range(3):
    s = load_scene(Config(data_dir=str(LLFF_DIR), leave_out_view=j))
    assert s.val_idx.tolist() == [base.train_idx[j]]
    assert s.train_idx.tolist() == [v for i, v in enumerate(base.train_idx) if i != j]
    np.testing.assert_array_equal(s.test_idx, base.test_idx)
    assert base.train_idx[j] not in pseudo_views.unused_views(s)
  train, val = leave_out_view(np.array([4, 9]), np.zeros(0), -1)  # Off: as it is.
  assert (train.tolist(), val.tolist()) == ([4, 9], [])
  with pytest.raises(DataError, match='leave_out_view=0: the split has 1 training views'):
    leave_out_view(np.array([4]), np.zeros(0), 0)
  with pytest.raises(DataError, match='has 2 validation views already'):
    leave_out_view(np.array([4, 9]), np.array([5, 6]), 1)
  with pytest.raises(DataError, match='leave_out_view=3: the split has 3 training views'):
    load_scene(Config(data_dir=str(LLFF_DIR), leave_out_view=3))
  with pytest.raises(ConfigError, match='set Config.val_views = 0'):
    Config(data_dir=str(LLFF_DIR), leave_out_view=0, val_views=2)


def test_blender_validation_views_come_from_transforms_val(tmp_path):
  for loader in ('transforms', 'blender'):
    config = Config(dataset_loader=loader, data_dir=str(BLENDER_DIR), scene='lego',
                    n_input_views=8, test_stride=8, white_bkgd=True, use_ndc=False,
                    near=2., far=6., val_views=3)
    s = load_scene(config)
    assert len(s.train_idx) == 8 and len(s.test_idx) == 25 and len(s.val_idx) == 3
    base = load_scene(dataclasses.replace(config, val_views=0))
    np.testing.assert_array_equal(s.poses[:33], base.poses)  # Train and test unchanged.
    assert not any(np.allclose(s.poses[v], base.poses[t]) for v in s.val_idx
                   for t in base.test_idx)
  with pytest.raises(DataError, match='blender_split'):
    load_scene(Config(dataset_loader='transforms', data_dir=str(BLENDER_DIR), scene='lego',
                      n_input_views=8, use_ndc=False, train_view_selection='coverage'))


def test_a_round_reports_validation_metrics_beside_the_test_metrics():
  config = tiny_config(procedural_views=17, n_input_views=3, val_views=2, max_steps=4)
  scene = load_scene(config)
  state = renerf.round_step(config, scene, renerf.initial_state())
  m = state.metrics[0]
  assert {'val_psnr', 'val_ssim', 'psnr'} <= set(m)
  val_scene = renerf.validation_scene(scene)
  assert val_scene.test_idx.tolist() == scene.val_idx.tolist() and not len(val_scene.val_idx)
  assert m['val_psnr'] != m['psnr']  # Other views.
  plain = renerf.round_step(dataclasses.replace(config, val_views=0),
                            load_scene(dataclasses.replace(config, val_views=0)),
                            renerf.initial_state())
  assert 'val_psnr' not in plain.metrics[0]
  assert plain.metrics[0]['psnr'] == m['psnr']  # Validation views change no training.


def test_convergence_scores_b_on_validation_views(monkeypatch):
  from experiments import convergence  # pylint: disable=g-import-not-at-top
  runs = {(n, s): {'metrics': {'psnr': 20. + s, 'val_psnr': 10. + n / 1000 + s, 'ssim': .5,
                               'val_ssim': .5, 'lpips_alex': .3, 'val_lpips_alex': .3,
                               'round_seconds': 1.}}
          for n in (1000, 2000) for s in (0, 1)}
  monkeypatch.setattr(convergence, 'finished', lambda root, sc, n, s: runs[(n, s)])
  rows = convergence.summarize('r', ['fern'], [0, 1], [1000, 2000])
  assert rows[0]['psnr'] == pytest.approx(11.5) and rows[0]['gain_2x_psnr'] == pytest.approx(1.)
  assert not rows[0]['converged']  # 1 dB more on validation views.
  test_rows = convergence.summarize('r', ['fern'], [0, 1], [1000, 2000], on='test')
  assert test_rows[0]['psnr'] == pytest.approx(20.5) and test_rows[0]['converged']
  del runs[(1000, 1)]['metrics']['val_psnr']
  with pytest.raises(ValueError, match='seed1: no validation metrics'):
    convergence.summarize('r', ['fern'], [0, 1], [1000, 2000])


def test_compare_choices_pairs_candidates_on_validation_views():
  from experiments import compare_choices  # pylint: disable=g-import-not-at-top
  run = lambda v, t: {'metrics': {'val_psnr': v, 'val_ssim': .5 + v / 100, 'val_lpips_alex':
                                  .3 - v / 100, 'psnr': t}}
  results = {'a': {0: run(20., 25.), 1: run(21., 25.), 2: run(22., 25.)},
             'b': {0: run(21., 20.), 1: run(22.5, 20.), 2: run(23., 20.)}}
  rows = compare_choices.compare(results, 'a')
  b = rows[1]
  assert b['val_psnr'] == pytest.approx((22.1666667, 1.0408330))
  assert b['delta_psnr']['mean'] == pytest.approx(7 / 6) and b['delta_psnr']['wins'] == 3
  assert b['delta_lpips_alex']['wins'] == 3  # Lower LPIPS is better.
  assert b['test_psnr'] == (20., 0.)  # Beside the choice, not in it.
  assert 'delta_psnr' not in rows[0]
  text = compare_choices.markdown(rows, 'a', 'fox', 4000, 'cmd')
  assert '| b | 3 | 22.17 +- 1.04 |' in text and 'Holm' in text
  del results['b'][1]['metrics']['val_psnr']
  with pytest.raises(ValueError, match='b: no validation metrics'):
    compare_choices.compare(results, 'a')
