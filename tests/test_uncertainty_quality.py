"""Tests for renerf_jax.uncertainty.quality and experiments/uncertainty_quality.py."""
import json
import subprocess
import sys

import numpy as np
import pytest

from conftest import REPO
from renerf_jax import cameras
from renerf_jax.uncertainty import quality as uq


def _err(n, seed=0):
  return np.random.default_rng(seed).gamma(0.7, size=n)


def test_u_equal_to_the_error_is_the_oracle():
  err = _err(5000)
  assert uq.ause(err, err) == 0.
  assert abs(uq.ause(3. * err + 1., err)) <= 1e-12  # any increasing map of the error
  assert uq.aurg(err, err) > 0.2
  np.testing.assert_allclose(uq.sparsification_curve(err, err)[0], 1.)


def test_u_independent_of_the_error_is_random():
  err = _err(200_000, 1)
  u = np.random.default_rng(2).normal(size=err.size)
  assert abs(uq.aurg(u, err)) < 0.01
  assert uq.ause(u, err) > 0.2
  assert abs(uq.mask_lift(u, err, 0.8) - 1.) < 0.03


def test_constant_u_is_exactly_random():
  err = _err(1000, 3)
  np.testing.assert_allclose(uq.sparsification_curve(np.ones(1000), err), 1., atol=1e-12)
  assert abs(uq.aurg(np.zeros(1000), err)) < 1e-12
  assert abs(uq.mask_lift(np.ones(1000), err, 0.8) - 1.) < 1e-12


def test_reversed_u_is_worse_than_random():
  err = _err(2000, 4)
  assert uq.aurg(-err, err) < -0.2
  assert uq.ause(-err, err) > uq.ause(np.zeros(2000), err)
  assert uq.mask_lift(-err, err, 0.8) < 1.


def test_perfect_mask_lift_by_hand():
  err = np.arange(1., 11.)  # 1..10
  # Keep the 8 least uncertain: mean (1 + ... + 8) / 8 = 4.5; masked (9 + 10) / 2 = 9.5.
  assert uq.mask_lift(err, err, 0.8) == pytest.approx(9.5 / 4.5, abs=1e-12)
  # A shuffled U with the same order gives the same lift.
  u = np.array([0.1, 0.3, 0.35, 0.4, 2., 3., 4., 5., 50., 51.])
  assert uq.mask_lift(u, err, 0.8) == pytest.approx(9.5 / 4.5, abs=1e-12)
  # The kept pixels error-free: the lift is infinite.
  assert uq.mask_lift(np.arange(10.), np.r_[np.zeros(8), 1., 1.], 0.8) == np.inf


def test_curve_by_hand_with_ties():
  err = np.array([1., 2., 3., 4.])
  u = np.array([0., 1., 1., 2.])  # pixels 2 and 3 tie: each counts as 2.5.
  # Remove 1/4: keep 1, 2.5, 2.5 -> mean 2; remove 1/2: keep 1, 2.5 -> 1.75; full mean 2.5.
  np.testing.assert_allclose(uq.sparsification_curve(u, err, [0., 0.25, 0.5]),
                             [1., 2. / 2.5, 1.75 / 2.5])
  # Fractional counts interpolate: removing 1/8 keeps 3.5 pixels (1 + 2.5 + 2.5 + 2).
  np.testing.assert_allclose(uq.sparsification_curve(u, err, [0.125]), [8. / 3.5 / 2.5])


def test_non_finite_u_is_most_uncertain():
  err = np.array([1., 1., 1., 10.])
  u_nan = np.array([0., 1., 2., np.nan])
  u_inf = np.array([0., 1., 2., np.inf])
  assert uq.ause(u_nan, err) == pytest.approx(0., abs=1e-12)
  assert uq.ause(u_inf, err) == pytest.approx(0., abs=1e-12)
  # NaN ranks above +inf.
  assert uq.mask_lift(np.array([np.inf, 0., 0., np.nan]), np.array([1., 1., 1., 10.]),
                      0.75) == pytest.approx(10.)
  assert np.all(np.isfinite(uq.sparsification_curve(np.full(4, np.nan), err)))


def test_degenerate_inputs():
  zero = np.zeros(50)
  u = np.random.default_rng(5).normal(size=50)
  assert uq.ause(u, zero) == 0. and uq.aurg(u, zero) == 0. and uq.mask_lift(u, zero, .8) == 1.
  assert np.all(uq.sparsification_curve(u, zero) == 0.)
  # One pixel: every curve is 1, the areas 0.
  assert uq.ause([3.], [2.]) == 0. and uq.aurg([3.], [2.]) == 0.
  np.testing.assert_allclose(uq.sparsification_curve([3.], [2.]), 1.)
  assert np.isnan(uq.mask_lift([1.], [2.], 0.)) and np.isnan(uq.mask_lift([], [], 0.5))
  q = uq.quality(u, np.abs(u), 0.8)
  assert q['ause'] == pytest.approx(uq.ause(u, np.abs(u)))
  assert q['aurg'] == pytest.approx(uq.aurg(u, np.abs(u)))
  with pytest.raises(ValueError):
    uq.ause(np.zeros(3), np.zeros(4))


def test_rgb_squared_error():
  rgb = np.array([[1.5, 0., 0.5]])
  gt = np.array([[1., 0., 0.]])
  np.testing.assert_allclose(uq.rgb_squared_error(rgb, gt), [0.25 / 3.])


def test_ndc_t_to_z_depth_inverts_the_ndc_map():
  rng = np.random.default_rng(6)
  h, w, focal = 20, 30, 25.
  c2w = cameras.view_matrix(np.array([0.1, -0.2, 1.]), np.array([0., 1., 0.]),
                            np.array([0.3, -0.1, 0.2]))
  px, py = rng.uniform(0, w, 40), rng.uniform(0, h, 40)
  world = cameras.pixel_rays(c2w[None], px, py, focal, h, w, False, 0., 1.)
  ndc = cameras.pixel_rays(c2w[None], px, py, focal, h, w, True, 0., 1.)
  depth = rng.uniform(1.5, 20., 40)  # camera z-depth
  o, d = np.asarray(world.origins, np.float64), np.asarray(world.directions, np.float64)
  p = o + depth[:, None] * d
  # The NDC image of p (cameras.convert_to_ndc's map) lies on the NDC ray at some t.
  p_ndc = np.stack([-2. * focal / w * p[:, 0] / p[:, 2], -2. * focal / h * p[:, 1] / p[:, 2],
                    1. + 2. / p[:, 2]], -1)
  on, dn = np.asarray(ndc.origins, np.float64), np.asarray(ndc.directions, np.float64)
  t = np.sum((p_ndc - on) * dn, -1) / np.sum(dn * dn, -1)
  np.testing.assert_allclose(on + t[:, None] * dn, p_ndc, atol=1e-4)
  np.testing.assert_allclose(uq.ndc_t_to_z_depth(t, o, d), depth, rtol=1e-4)
  assert np.isinf(uq.ndc_t_to_z_depth(np.ones(1), o[:1], d[:1])[0])
  err = uq.depth_abs_error(np.array([np.inf, 1., np.nan]), np.array([2., 2., 2.]), 5.)
  np.testing.assert_allclose(err, [3., 1., 3.])


TINY = ['Config.procedural_size = (32, 40)', 'Config.image_downsample = 1',
        'Config.max_steps = 6', 'Config.batch_size = 64', 'Config.num_samples = 8',
        'Config.n_random_poses = 20', 'Config.batch_size_random = 32', 'Config.patch_size = 4',
        'Config.anneal_nearfar_steps = 2', 'Config.lr_delay_steps = 2',
        'Config.depth_tv_maxstep = 2', 'Config.eval_every = 3', 'Config.checkpoint_every = 3',
        'Config.render_chunk = 512', 'Config.deform_log2_res = 2', 'Config.hessian_rays = 256',
        'Config.hessian_chunk = 256', 'Config.grid_levels = 4', 'Config.grid_max_res = 64',
        'Config.grid_log2_hashmap_size = 10', 'Config.grid_mlp_width = 16',
        "Config.lpips_nets = ('alex',)"]


def test_script_end_to_end_on_the_procedural_scene(tmp_path):
  bindings = [f'--gin_bindings={b}' for b in TINY + ['Config.val_views = 2']]
  cmd = [sys.executable, '-m', 'experiments.uncertainty_quality', '--name', 'uq', '--out',
         str(tmp_path), '--scenes', 'procedural', '--seeds', '0'] + bindings
  res = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=600,
                       check=False)
  assert res.returncode == 0, res.stderr[-3000:]
  out = json.loads((tmp_path / 'uq.json').read_text())
  rows = {r['variant']: r for r in out['rows'] if r['scene'] == 'procedural'}
  assert set(rows) == set(out['variants'])
  for r in rows.values():
    assert np.isfinite(r['ause']) and np.isfinite(r['aurg']) and np.isfinite(r['depth_ause'])
  assert out['best'] in out['variants']
  for name in ('uq.md', 'uq_procedural.png', 'uq_procedural_panel.png'):
    assert (tmp_path / name).stat().st_size > 0
  # A second invocation reuses the run and the signals.
  res = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=600,
                       check=False)
  assert res.returncode == 0 and 'reused' in res.stderr + res.stdout
  test_views = np.load(tmp_path / 'uq' / 'procedural' / 'seed0_signals.npz')['err'].shape[0]
  # On the validation views, with B copied from the first run instead of trained.
  val = [sys.executable, '-m', 'experiments.uncertainty_quality', '--name', 'uq_val',
         '--out', str(tmp_path), '--scenes', 'procedural', '--seeds', '0', '--views',
         'validation', '--baseline_from', str(tmp_path / 'uq' / '{scene}' / 'seed{seed}')]
  res = subprocess.run(val + bindings, cwd=REPO, capture_output=True, text=True,
                       timeout=600, check=False)
  assert res.returncode == 0, res.stderr[-3000:]
  run = tmp_path / 'uq_val' / 'procedural' / 'seed0'
  shared = json.loads((run / 'shared_baseline.json').read_text())
  assert shared['from'] == str(tmp_path / 'uq' / 'procedural' / 'seed0')
  assert np.load(str(run) + '_signals.npz')['err'].shape[0] == 2 != test_views
  out = json.loads((tmp_path / 'uq_val.json').read_text())
  assert out['views'] == 'validation' and out['runs'][0]['views'] == 'validation'
  assert 'the validation views' in (tmp_path / 'uq_val.md').read_text()


def test_script_validation_views_refused_without_any(tmp_path, capsys):
  from experiments import uncertainty_quality  # pylint: disable=g-import-not-at-top
  with pytest.raises(SystemExit) as e:
    uncertainty_quality.main(['--name', 'uq', '--out', str(tmp_path), '--scenes',
                              'procedural', '--seeds', '0', '--views', 'validation'] +
                             [f'--gin_bindings={b}' for b in TINY])
  assert e.value.code == 2
  err = capsys.readouterr().err.strip().splitlines()
  assert err[-1:] == ["error: --views validation: scene 'procedural' has no validation views "
                 '(set Config.val_views)']
