import dataclasses
import os

import jax
import numpy as np
import pytest

from renerf_jax import backbones, pseudo_views, renerf, round_driver, rundir
from renerf_jax.datasets import load_scene
from renerf_jax.evaluation import Evaluation
from renerf_jax.pseudo_views import pseudo_view_poses, uncertainty_heatmap
from renerf_jax.errors import ConfigError
from renerf_jax.nerf import synthesis
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
  on_disk = round_driver.run_rounds(config, scene, str(tmp_path / 'run'), show_progress=False)
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


def test_oracle_trains_on_the_photos_the_split_leaves_unused():
  config = tiny_config(num_rounds=1, pseudo_targets='unused', pseudo_source='photo')
  scene = load_scene(config)
  unused = pseudo_views.unused_views(scene)
  train, test = set(scene.train_idx.tolist()), set(scene.test_idx.tolist())
  assert len(unused) > 0 and not set(unused.tolist()) & (train | test)
  assert sorted(set(unused.tolist()) | train | test) == list(range(len(scene.poses)))
  poses, meta = pseudo_view_poses(config, scene)
  np.testing.assert_array_equal(poses, scene.poses[unused])
  assert [m['view'] for m in meta] == unused.tolist()
  # Every backbone's synthesis hands the photos over untouched, with no mask.
  for pv, _, _ in (synthesis.synthesize(config, scene, None),
                   backbones.synthesize_by_rendering(None, config, scene, None)):
    np.testing.assert_array_equal(pv.images, scene.images[unused])
    assert pv.masks.min() == 1.
  # A round: D trains on them (B's renders at the same poses differ from the photos).
  state = renerf.run_rounds(config, scene)
  np.testing.assert_array_equal(state.pseudo.images, scene.images[unused])
  renders, _, _ = synthesis.synthesize(dataclasses.replace(config, pseudo_source='render'), scene,
                                    state.params)
  assert renders.images.shape == state.pseudo.images.shape
  assert np.abs(renders.images - state.pseudo.images).max() > 0.05
  with pytest.raises(ConfigError, match='pseudo_targets'):
    pseudo_view_poses(dataclasses.replace(config, pseudo_targets='interp+unused'), scene)
  with pytest.raises(ConfigError, match='use_masks'):  # Before the baseline trains.
    renerf.check_rounds_config(dataclasses.replace(config, use_masks=True), scene)
  with pytest.raises(ConfigError, match='pseudo_source'):
    tiny_config(pseudo_source='photos')
  every = tiny_config(pseudo_targets='unused', n_input_views=len(scene.poses) - len(test))
  with pytest.raises(ConfigError, match='no unused photos'):
    pseudo_view_poses(every, load_scene(every))


def test_rounds_schedule_resume_and_masks(tmp_path):
  config = tiny_config(num_rounds=1, max_steps=20, pseudo_until_frac=0.5, use_masks=True,
                       deform_log2_res=2, hessian_rays=256, mask_keep_frac=0.7)
  scene = load_scene(config)
  run_dir = str(tmp_path / 'run')
  state = round_driver.run_rounds(config, scene, run_dir, show_progress=False)
  assert state.round_index == 1 and len(state.metrics) == 2
  assert state.metrics[1]['cumulative_seconds'] > state.metrics[0]['cumulative_seconds']
  # Pseudo rays are sampled before K = 10 and removed after.
  log = rundir.read_jsonl(rundir.round_log_path(run_dir, 1))
  assert [r['pseudo_rays'] > 0 for r in log] == [r['step'] <= 10 for r in log]
  assert all(r['pseudo_rays'] == 0 for r in
             rundir.read_jsonl(rundir.round_log_path(run_dir, 0)))
  # Masks keep ~70% of the pseudo pixels; they were stored with the pseudo-views.
  assert state.pseudo.masks.mean() == pytest.approx(0.7, abs=0.02)
  assert state.pseudo.uncertainty.max() > 0
  # Side-by-side PNG: view | uncertainty | masked view, masked pixels black in the third.
  import imageio.v3 as iio
  panel = iio.imread(rundir.pseudo_view_png_path(
      rundir.pseudo_views_dir(rundir.round_dir(run_dir, 1)), 'panel', 0))
  h, w = state.pseudo.images.shape[1:3]
  assert panel.shape[:2] == (h, 3 * w + 8)
  third = panel[:, 2 * w + 8:]
  assert np.all(third[state.pseudo.masks[0].reshape(h, w) == 0] == 0)
  # A rerun skips the finished rounds and rewrites nothing.
  before = tree_files(run_dir)
  again = round_driver.run_rounds(config, scene, run_dir, show_progress=False)
  assert tree_files(run_dir) == before
  assert again.metrics == state.metrics
  jax.tree_util.tree_map(np.testing.assert_array_equal, again.params, state.params)


def test_all_masked_pseudo_views_still_train_on_real_views(tmp_path):
  config = tiny_config(num_rounds=1, max_steps=10, pseudo_until_frac=1., use_masks=True,
                       deform_log2_res=1, hessian_rays=64, mask_threshold=0.)
  scene = load_scene(config)
  state = round_driver.run_rounds(config, scene, str(tmp_path / 'run'), show_progress=False)
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


def test_the_round_driver_runs_any_backbone_through_its_interface(tmp_path, monkeypatch):
  """A toy backbone (a constant colour per model) goes through the same round_step,
  resume and reports: the driver calls nothing of the NeRF's own."""
  from renerf_jax import backbones, fit  # pylint: disable=g-import-not-at-top
  from renerf_jax.nerf import training  # pylint: disable=g-import-not-at-top
  calls = []

  def train(config, scene, out_dir, pseudo, window, init_params, eval_fn, time_offset,
            desc, show_progress):
    del init_params, time_offset, show_progress
    calls.append(('train', desc, out_dir is not None, window,
                  None if pseudo is None else pseudo.images.shape[0]))
    views = [scene.images[scene.train_idx]] + ([] if pseudo is None else [pseudo.images])
    colour = np.mean(np.concatenate([v.reshape(-1, 3) for v in views]), axis=0,
                     dtype=np.float64)
    state = training.TrainState(step=np.int32(config.max_steps),
                                params={'colour': np.float32(colour)}, opt_state=None,
                                nan_skips=np.int32(0))
    return fit.TrainResult(state=state, train_seconds=1.,
                           curve=[{'step': 1, 'eval_psnr': eval_fn(state.params)}])

  def render_views(config, scene, params, poses, show_progress=False):
    del config, show_progress
    shape = (len(poses), scene.height, scene.width)
    return {'rgb': np.broadcast_to(params['colour'], shape + (3,)),
            'depth': np.ones(shape, np.float32), 'acc': np.ones(shape, np.float32)}

  def synthesize(config, scene, params, show_progress=False):
    poses, meta = pseudo_view_poses(config, scene)
    rgb = render_views(config, scene, params, poses)['rgb']
    pv = renerf.PseudoViews(images=np.array(rgb, np.float32), poses=poses,
                            masks=np.ones(rgb.shape[:3], np.float32),
                            uncertainty=np.zeros(rgb.shape[:3], np.float32))
    return pv, {'seconds': 0.5}, meta

  def evaluate(config, scene, params, show_progress=False):
    del show_progress
    mse = float(np.mean((params['colour'] - scene.images[scene.test_idx])**2))
    rgb = render_views(config, scene, params, scene.poses[scene.test_idx])['rgb']
    return Evaluation(per_image=[{'name': 'test_000', 'psnr': -10. * np.log10(mse)}],
                      mean={'psnr': -10. * np.log10(mse)}, images=np.asarray(rgb),
                      distances=np.ones(rgb.shape[:3], np.float32),
                      columns=('name', 'psnr'))

  toy = backbones.Backbone(
      name='nerf', init_params=lambda config: {'colour': np.zeros(3, np.float32)},
      train=train, synthesize=synthesize,
      cheap_eval_fn=lambda config, scene: lambda p: evaluate(config, scene, p).mean['psnr'],
      evaluate=evaluate, render_views=render_views)
  from renerf_jax.nerf import backbone as nerf_backbone  # pylint: disable=g-import-not-at-top
  monkeypatch.setattr(nerf_backbone, 'BACKBONE', toy)  # what the registry hands out
  config = tiny_config(num_rounds=2, max_steps=10)
  scene = load_scene(config)
  state = renerf.run_rounds(config, scene)
  assert [c[:2] for c in calls] == [('train', 'baseline'), ('train', 'round 1'),
                                    ('train', 'round 2')]
  assert calls[0][4] is None and calls[1][4] == calls[2][4] == 12  # 7x on 3 views
  assert calls[1][3] == fit.pseudo_window(renerf.round_config(config, 1))
  assert [m['cumulative_seconds'] for m in state.metrics] == [1., 2.5, 4.]
  real = scene.images[scene.train_idx].reshape(-1, 3).mean(0, dtype=np.float64)
  np.testing.assert_allclose(state.params['colour'], real, rtol=1e-5)  # D = B here.
  calls.clear()
  on_disk = round_driver.run_rounds(config, scene, str(tmp_path / 'run'), show_progress=False)
  assert [c[2] for c in calls] == [True] * 3  # Trained into the round directories.
  np.testing.assert_array_equal(on_disk.params['colour'], state.params['colour'])
  assert os.path.isfile(rundir.render_path(  # the edge
      rundir.eval_dir(rundir.round_dir(str(tmp_path / 'run'), 2)), 'test_000'))
  again = round_driver.run_rounds(config, scene, str(tmp_path / 'run'), show_progress=False)
  assert len(calls) == 3  # Finished rounds are loaded through init_params, not retrained.
  np.testing.assert_array_equal(again.params['colour'], state.params['colour'])
  assert [m['psnr'] for m in again.metrics] == [m['psnr'] for m in state.metrics]


def test_backbone_is_validated_and_the_nerf_renders_rgb_depth_acc():
  from renerf_jax import backbones  # pylint: disable=g-import-not-at-top
  from renerf_jax.gaussians import backbone as gaussians_backbone  # pylint: disable=g-import-not-at-top
  from renerf_jax.nerf import backbone as nerf_backbone  # pylint: disable=g-import-not-at-top
  with pytest.raises(ConfigError, match='Config.backbone'):
    tiny_config(backbone='splats')
  assert backbones.get_backbone(tiny_config(backbone='gaussians')) is gaussians_backbone.BACKBONE
  config = tiny_config()
  backbone = backbones.get_backbone(config)
  assert backbone is nerf_backbone.BACKBONE and set(backbones.REGISTRY) == {'nerf', 'gaussians'}
  scene = load_scene(config)
  params = backbone.init_params(config)
  out = backbone.render_views(config, scene, params, scene.poses[scene.test_idx[:2]])
  h, w = scene.height, scene.width
  assert out['rgb'].shape == (2, h, w, 3) and out['depth'].shape == (2, h, w)
  assert out['acc'].shape == (2, h, w) and np.all((out['acc'] >= 0) & (out['acc'] <= 1))
  ev = backbone.evaluate(config, scene, params, show_progress=False)
  first = np.clip(out['rgb'][0], 0., 1.)
  psnr = -10. * np.log10(np.mean((first - scene.images[scene.test_idx[0]])**2))
  np.testing.assert_allclose(ev.per_image[0]['psnr'], psnr, rtol=1e-4)
  # The render it was scored on (its rays are made for all test views at once, here for
  # two: XLA's own dot kernels may differ in the last bit between the two batchings).
  np.testing.assert_allclose(ev.images[0], first, rtol=0, atol=1e-6)


def test_synthesis_by_rendering_masks_with_one_minus_acc_only():
  """Pseudo-views of a non-NeRF backbone: its renders, unmasked, or masked where the
  render is least opaque; the Laplace signal (a NeRF's field) is refused in one line."""
  from renerf_jax import backbones  # pylint: disable=g-import-not-at-top
  config = tiny_config(use_masks=True, mask_signal='one_minus_acc', mask_keep_frac=0.75)
  scene = load_scene(config)
  h, w = scene.height, scene.width

  def render_views(config, scene, params, poses, show_progress=False):
    del config, scene, params, show_progress
    acc = np.broadcast_to(np.linspace(0., 1., h * w, dtype=np.float32).reshape(h, w),
                          (len(poses), h, w))
    return {'rgb': np.full((len(poses), h, w, 3), 1.5, np.float32), 'acc': acc,
            'depth': np.ones((len(poses), h, w), np.float32)}

  pv, timing, meta = backbones.synthesize_by_rendering(render_views, config, scene, None)
  assert pv.images.shape == (12, h, w, 3) and len(meta) == 12
  np.testing.assert_array_equal(pv.images, 1.)  # Clipped to [0, 1].
  assert abs(float(np.mean(pv.masks)) - 0.75) < 2. / (h * w)
  assert np.all(pv.masks[:, -1, -1] == 1.) and np.all(pv.masks[:, 0, 0] == 0.)  # Opaque kept.
  np.testing.assert_allclose(pv.uncertainty, 1. - render_views(None, None, None, meta)['acc'])
  plain, _, _ = backbones.synthesize_by_rendering(render_views, tiny_config(), scene, None)
  np.testing.assert_array_equal(plain.masks, 1.)
  with pytest.raises(ConfigError, match='one_minus_acc'):
    backbones.synthesize_by_rendering(render_views, tiny_config(use_masks=True), scene, None)


def test_gaussian_configs_load_with_rounds_and_refuse_the_laplace_masks_up_front():
  from renerf_jax.configs import load_config  # pylint: disable=g-import-not-at-top
  for name in ('gaussians_llff3.gin', 'gaussians_llff3_cpu.gin'):
    config = load_config([name], ['Config.num_rounds = 1'])
    assert config.backbone == 'gaussians'
  # The bound on K from the near/far annealing (step 512) is the NeRF's: the CPU config's
  # K is step 405 of 1500.
  assert config.max_steps == 1500 and int(round(config.pseudo_until_frac * 1500)) < 512
  config = tiny_config(backbone='gaussians', num_rounds=1, use_masks=True)
  with pytest.raises(ConfigError, match='one_minus_acc'):
    renerf.check_rounds_config(config, load_scene(config))  # Before B trains.


def test_synthesis_charges_the_seconds_its_render_and_hessian_functions_report():
  """A render_fn / sigma_fn that reuses earlier work reports what the work cost; the
  round's synthesis seconds count that, never less (sharing never makes a round look
  cheaper)."""
  config = tiny_config(interp_factors='0.5')  # 2 views on 3 training views
  scene = load_scene(config)
  h, w = scene.height, scene.width
  fake = lambda cfg, params, rays: (np.full((h * w, 3), .25, np.float32), 100.)
  pv, timing, _ = synthesis.synthesize(config, scene, None, render_fn=fake)
  assert pv.images.shape == (2, h, w, 3) and np.all(pv.images == .25)
  assert timing['render_seconds'] >= 200. and timing['seconds'] >= timing['render_seconds']


def test_round_config_d_seed_policies_and_init_seed_keys():
  """Config.d_seed: 'offset' gives D seed + 1000 r for its draws and its initialisation,
  'same_init' B's initialisation with new draws, 'same' B's Config; Config.init_seed
  seeds the initialisation alone (equal to seed: the same keys as unset)."""
  from renerf_jax import fit  # pylint: disable=g-import-not-at-top
  from renerf_jax.configs import Config  # pylint: disable=g-import-not-at-top
  b = Config(seed=3)
  assert renerf.round_config(b, 0) == b
  d = renerf.round_config(b, 2)
  assert (d.seed, d.init_seed) == (2003, -1)
  d = renerf.round_config(Config(seed=3, d_seed='same_init'), 1)
  assert (d.seed, d.init_seed) == (1003, 3)
  assert renerf.round_config(Config(seed=3, d_seed='same'), 1) == Config(seed=3,
                                                                         d_seed='same')
  d = renerf.round_config(Config(seed=3, init_seed=7), 1)
  assert (d.seed, d.init_seed) == (1003, 1007)
  d = renerf.round_config(Config(seed=3, init_seed=7, d_seed='same_init'), 1)
  assert (d.seed, d.init_seed) == (1003, 7)
  keys = lambda c: [np.asarray(k) for k in fit.init_and_step_keys(c)]
  ref = np.asarray(jax.random.split(jax.random.PRNGKey(3)))
  np.testing.assert_array_equal(np.stack(keys(b)), ref)
  np.testing.assert_array_equal(np.stack(keys(Config(seed=3, init_seed=3))), ref)
  k_init, k_step = keys(Config(seed=9, init_seed=3))
  np.testing.assert_array_equal(k_init, ref[0])
  np.testing.assert_array_equal(k_step, np.asarray(jax.random.split(jax.random.PRNGKey(9)))[1])
  # The seed-matched control: round 1's Config with no rounds, B's steps or the given.
  c = renerf.control_config(Config(seed=3, num_rounds=2, seed_control=True))
  assert c == Config(seed=1003, num_rounds=0, seed_control=False)
  assert renerf.control_config(Config(seed=3), 2 * c.max_steps).max_steps == 2 * c.max_steps
  assert renerf.control_config(Config(seed=3, d_seed='same')) == Config(seed=3,
                                                                        d_seed='same')
  with pytest.raises(ConfigError, match="Config.renerf_init='continue'"):
    renerf.check_rounds_config(tiny_config(num_rounds=1, seed_control=True,
                                           renerf_init='continue'),
                               load_scene(tiny_config()))
  with pytest.raises(ConfigError, match="Config.d_seed='new'"):
    Config(d_seed='new')
  with pytest.raises(ConfigError, match='Config.init_seed=-2'):
    Config(init_seed=-2)
