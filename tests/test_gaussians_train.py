"""Training Gaussians: optimiser, schedules, loss, the loop, ply export (density control:
test_gaussians_strategy.py)."""
import dataclasses
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from conftest import tiny_config
from gaussian_helpers import random_gaussians
from renerf_jax import metrics, rundir
from renerf_jax.datasets import load_scene
from renerf_jax.errors import DataError
from renerf_jax.gaussians import params as params_lib
from renerf_jax.gaussians import ply
from renerf_jax.gaussians import render as render_lib
from renerf_jax.gaussians import loss as gloss
from renerf_jax.gaussians import schedule as gschedule
from renerf_jax.gaussians import start as gstart
from renerf_jax.gaussians.strategy import DensityStrategy
from renerf_jax.gaussians import training as gtrain
from renerf_jax.pseudo_views import PseudoViews

STEPS = 120
# One Config for every test that compiles the train step (the Config is a static
# argument: each distinct one compiles anew). Higher colour / position lrs than 3DGS so
# 120 steps show progress; densify every 12 steps from 12 to 96, no opacity reset in
# the run (tested on its own), the tile cap loose at this image size.
CFG = tiny_config(backbone='gaussians', procedural_size=(24, 32), max_steps=STEPS,
                  print_every=1, checkpoint_every=60, eval_every=40, gs_capacity=1536,
                  gs_init_points=512, gs_tile_cap=512, gs_densify_from_frac=0.1,
                  gs_densify_until_frac=0.8, gs_densify_every_frac=0.1,
                  gs_opacity_reset_every_frac=1., gs_sh_interval_frac=0.25,
                  gs_lr_sh_dc=0.03, gs_lr_scales=0.01, gs_lr_means_init=1e-2,
                  gs_lr_means_final=1e-3)


@pytest.fixture(scope='module')
def scene():
  return load_scene(CFG)


@pytest.fixture(scope='module')
def full_run(scene, tmp_path_factory):
  out = str(tmp_path_factory.mktemp('gs') / 'a')
  return out, gtrain.train_gaussians(CFG, scene, out, None, eval_fn=lambda p: 1.,
                                     show_progress=False)


def _psnr(a, b):
  return float(-10. * np.log10(np.mean((np.asarray(a) - np.asarray(b))**2)))


_POSE = jnp.asarray(np.eye(4)[:3], jnp.float32)  # At the origin, looking down -z.
_CAM = gtrain.Camera(24, 32, 30.)
_N = 18  # Slots of the hand-made scenes of the loss tests (one compilation).
_loss_and_grads = jax.jit(gtrain.loss_and_grads, static_argnums=(0, 1))


# ----------------------------------------------------------------------------- schedules


def test_learning_rates_and_sh_schedule():
  cfg = tiny_config(max_steps=30000)
  ext = 2.5
  np.testing.assert_allclose(gschedule.means_lr(0, cfg, ext), 2.5 * 1.6e-4, rtol=1e-6)
  np.testing.assert_allclose(gschedule.means_lr(15000, cfg, ext), 2.5 * 1.6e-5, rtol=1e-5)
  np.testing.assert_allclose(gschedule.means_lr(30000, cfg, ext), 2.5 * 1.6e-6, rtol=1e-5)
  np.testing.assert_allclose(gschedule.means_lr(40000, cfg, ext), 2.5 * 1.6e-6, rtol=1e-5)
  lrs = gschedule.base_learning_rates(cfg, ext)
  want = {'means': 4e-4, 'sh_dc': 2.5e-3, 'sh_rest': 1.25e-4, 'opacity_logits': 0.05,
          'log_scales': 5e-3, 'quats': 1e-3}
  assert lrs.keys() == want.keys()
  for k, v in want.items():
    np.testing.assert_allclose(lrs[k], v, rtol=1e-12)
  assert gschedule.ADAM_EPS == 1e-15
  # 3DGS: +1 degree every 1000 iterations (1-based), up to 3; densify 500..15000 / 100.
  degrees = [int(gschedule.sh_degree_at(i, cfg)) for i in (1, 999, 1000, 1999, 2000, 3000,
                                                        29000)]
  assert degrees == [0, 0, 1, 1, 2, 3, 3]
  s = DensityStrategy.of(cfg)
  assert (s.refine_start, s.refine_stop, s.refine_every, s.reset_every) == (500, 15000,
                                                                             100, 3000)
  assert (s.grad_threshold, s.percent_dense, s.min_opacity) == (
      cfg.gs_grad_threshold, cfg.gs_percent_dense, cfg.gs_min_opacity)


def test_sh_coefficients_above_the_degree_get_no_gradient():
  g = random_gaussians(_N, _N)
  img = jnp.full((24, 32, 3), 0.3, jnp.float32)
  mask = jnp.ones((24, 32), jnp.float32)
  for degree, used in ((0, 1), (1, 4), (3, 16)):
    _, _, _, grads, _ = _loss_and_grads(CFG, _CAM, g, img, _POSE, mask, degree)
    sh = np.concatenate([np.asarray(grads['sh_dc']), np.asarray(grads['sh_rest'])], 1)
    assert np.abs(sh[:, :used]).max() > 0.
    assert np.all(sh[:, used:] == 0.)


# ----------------------------------------------------------------------------- loss


def _ssim_float64(img0, img1):
  """metrics.ssim_map's definition evaluated in float64 numpy (shifted-slice blur)."""
  a, b = np.asarray(img0, np.float64), np.asarray(img1, np.float64)
  taps = np.asarray(metrics.gaussian_kernel_1d(metrics.SSIM_FILTER_SIZE,
                                               metrics.SSIM_FILTER_SIGMA), np.float64)

  def blur(x):
    for axis in (0, 1):
      n = x.shape[axis] - len(taps) + 1
      x = sum(w * np.take(x, np.arange(k, k + n), axis=axis) for k, w in enumerate(taps))
    return x

  m0, m1 = blur(a), blur(b)
  s00, s11, s01 = blur(a * a) - m0**2, blur(b * b) - m1**2, blur(a * b) - m0 * m1
  c1, c2 = metrics.SSIM_K1**2, metrics.SSIM_K2**2
  return ((2. * m0 * m1 + c1) * (2. * s01 + c2) /
          ((m0**2 + m1**2 + c1) * (s00 + s11 + c2)))


def test_masked_pixels_do_not_enter_the_loss():
  g = random_gaussians(_N, _N)
  rng = np.random.default_rng(1)
  img = jnp.asarray(rng.uniform(size=(24, 32, 3)), jnp.float32)
  mask = np.ones((24, 32), np.float32)
  mask[5:15, 8:20] = 0.
  other = np.asarray(img).copy()
  other[5:15, 8:20] = 1. - other[5:15, 8:20]
  f = lambda im, m: _loss_and_grads(CFG, _CAM, g, jnp.asarray(im), _POSE, jnp.asarray(m),
                                    3)
  a, b = f(img, mask), f(other, mask)
  assert float(a[0]) == float(b[0])
  jax.tree_util.tree_map(np.testing.assert_array_equal, a[3], b[3])
  np.testing.assert_array_equal(a[4], b[4])
  full = f(img, np.ones_like(mask))
  assert float(full[0]) != float(a[0])
  # With all weights 1 the masked SSIM is metrics.ssim_map. Its blur (banded matrix
  # products) sums in another order than metrics' (shifted slices): float32 values
  # differ by ~2.5e-6, as far as each is from a float64 SSIM, so the tolerance is 5e-6
  # and both are held to the float64 one.
  ssim, w = gloss.masked_ssim_map(full[2]['rgb'], img, jnp.ones((24, 32)))
  np.testing.assert_allclose(ssim, metrics.ssim_map(full[2]['rgb'], img), atol=5e-6)
  exact = _ssim_float64(full[2]['rgb'], img)
  np.testing.assert_allclose(ssim, exact, atol=5e-6)
  np.testing.assert_allclose(metrics.ssim_map(full[2]['rgb'], img), exact, atol=5e-6)
  assert np.all(np.asarray(w) == 1.)
  # An all-zero mask: no loss, no gradient of any field.
  z = f(img, np.zeros_like(mask))
  assert float(z[0]) == 0.
  for x in jax.tree_util.tree_leaves((z[3], z[4])):
    assert np.all(np.asarray(x) == 0.)


def test_zero_mask_pseudo_view_step_changes_no_parameter(scene):
  # Shapes of the pseudo-view run below (3 real + 2 pseudo): the same compiled step.
  state = gtrain.init_state(CFG, gtrain.init_gaussians(CFG, scene, jax.random.PRNGKey(1)),
                            1.)
  data = {'images': jnp.full((5, 24, 32, 3), 0.7, jnp.float32),
          'poses': jnp.asarray(scene.poses[:5]), 'masks': jnp.zeros((5, 24, 32)),
          'is_pseudo': jnp.ones((5,), bool)}
  params, opt = jax.device_get((state.params, state.opt_state))
  new, stats = gtrain.train_step(CFG, gtrain.Camera.of(scene), True, state, data,
                                 jnp.float32(1.), jax.random.PRNGKey(0))
  jax.tree_util.tree_map(np.testing.assert_array_equal, params, new.params)
  jax.tree_util.tree_map(np.testing.assert_array_equal, opt, new.opt_state)
  assert int(new.step) == 1 and int(new.nan_skips) == 0 and int(new.pseudo_images) == 1
  assert float(stats['pseudo_rays']) == 0. and float(new.stats.count.sum()) == 0.


def test_inactive_slots_change_neither_image_nor_gradients():
  n, extra = 12, 6
  g = random_gaussians(n, n + extra)
  garbage = g.replace(means=g.means.at[n:].set(jnp.nan), sh=g.sh.at[n:].set(1e30),
                      opacity_logits=g.opacity_logits.at[n:].set(40.))
  visible = g.replace(active=jnp.ones(n + extra, bool))
  img = jnp.full((24, 32, 3), 0.4, jnp.float32)
  mask = jnp.ones((24, 32), jnp.float32)
  f = lambda gg: _loss_and_grads(CFG, _CAM, gg, img, _POSE, mask, 3)
  a, b, c = f(g), f(garbage), f(visible)
  np.testing.assert_array_equal(a[2]['rgb'], b[2]['rgb'])
  assert np.abs(np.asarray(a[2]['rgb'] - c[2]['rgb'])).max() > 1e-3
  assert float(a[0]) == float(b[0])
  for x, y in zip(jax.tree_util.tree_leaves((a[3], a[4])),
                  jax.tree_util.tree_leaves((b[3], b[4]))):
    np.testing.assert_array_equal(x, y)
    assert np.all(np.asarray(x)[n:] == 0.)
  assert np.abs(np.asarray(a[4][:n])).max() > 0.  # Screen-space gradients exist.


def test_all_inactive_renders_the_background_with_zero_gradients():
  g = random_gaussians(0, _N)
  img = jnp.full((24, 32, 3), 0.4, jnp.float32)
  loss, mse, out, grads, grad2d = _loss_and_grads(
      CFG, _CAM, g, img, _POSE, jnp.ones((24, 32), jnp.float32), 3)
  assert np.all(np.asarray(out['rgb']) == 0.) and np.all(np.asarray(out['acc']) == 0.)
  assert np.isfinite(float(loss)) and np.isfinite(float(mse)) and float(loss) > 0.
  for x in jax.tree_util.tree_leaves((grads, grad2d)):
    assert np.all(np.asarray(x) == 0.)
  bg = jnp.asarray([0.2, 0.5, 0.9], jnp.float32)
  plain = render_lib.render(g, _POSE, 30., 24, 32, 3, bg, 16,
                            means2d_offset=jnp.zeros((_N, 2)))
  np.testing.assert_array_equal(plain['rgb'], np.broadcast_to(bg, (24, 32, 3)))
  views = gtrain.render_views(dataclasses.replace(CFG, gs_background=(0.2, 0.5, 0.9)),
                              _Scene(), g, np.asarray(_POSE)[None])
  np.testing.assert_allclose(views['rgb'][0], np.broadcast_to(bg, (24, 32, 3)))
  assert np.all(views['depth'] == 0.) and np.all(views['acc'] == 0.)
  # Scenes composited on white (Blender) render on white, whatever gs_background says,
  # in training's loss as in render_views.
  white = dataclasses.replace(CFG, gs_background=(0.2, 0.5, 0.9), white_bkgd=True)
  views = gtrain.render_views(white, _Scene(), g, np.asarray(_POSE)[None])
  np.testing.assert_array_equal(views['rgb'][0], np.ones((24, 32, 3), np.float32))
  _, _, out, _, _ = _loss_and_grads(white, _CAM, g, img, _POSE,
                                    jnp.ones((24, 32), jnp.float32), 3)
  np.testing.assert_array_equal(out['rgb'], np.ones((24, 32, 3), np.float32))


class _Scene:
  """The camera of _CAM as a Scene would give it."""
  height, width, focal = _CAM.h, _CAM.w, _CAM.focal


# ----------------------------------------------------------------------------- training


def test_training_raises_the_train_psnr(scene, full_run):
  out, res = full_run
  p0 = gtrain.init_gaussians(CFG, scene, jax.random.split(jax.random.PRNGKey(CFG.seed))[0])
  poses, gt = scene.poses[scene.train_idx], scene.images[scene.train_idx]
  before = _psnr(gtrain.render_views(CFG, scene, p0, poses)['rgb'], gt)
  views = gtrain.render_views(CFG, scene, res.state.params, poses)
  after = _psnr(views['rgb'], gt)
  assert after > before + 3., (before, after)
  assert views['depth'].shape == (3, 24, 32) and np.all(np.isfinite(views['depth']))
  assert views['acc'].max() <= 1. and views['depth'].max() > 1.
  s = res.state
  assert int(s.step) == STEPS and int(s.nan_skips) == 0
  assert int(s.params.active.sum()) > CFG.gs_init_points  # Densification added some.
  recs = rundir.read_jsonl(rundir.log_path(out))
  assert [r['step'] for r in recs] == list(range(1, STEPS + 1))
  for key in ('step', 'train_seconds', 'time', 'loss', 'psnr', 'lr', 'nan_skips',
              'pseudo_rays', 'num_gaussians', 'cap_bound'):
    assert key in recs[-1], key
  assert [r['step'] for r in res.curve] == [40, 80, 120]
  assert recs[-1]['sh_degree'] == 3 and recs[0]['sh_degree'] == 0
  assert recs[0]['cap_bound'] == 0. and 0. <= recs[-1]['cap_bound'] <= 1.
  assert recs[-1]['pseudo_rays'] == 0 and recs[-1]['pseudo_images'] == 0


def test_resume_is_bit_for_bit(scene, full_run, tmp_path, monkeypatch):
  _, full = full_run
  real_step, calls = gtrain.train_step, []

  def step(*args, **kwargs):
    calls.append(int(args[3].step))
    if len(calls) == 71:
      raise KeyboardInterrupt('killed at step 70')
    return real_step(*args, **kwargs)
  monkeypatch.setattr(gtrain, 'train_step', step)
  out = str(tmp_path / 'b')
  with pytest.raises(KeyboardInterrupt):
    gtrain.train_gaussians(CFG, scene, out, None, show_progress=False)
  assert [s for s, _ in rundir.list_checkpoints(rundir.checkpoints_dir(out))] == [60]
  calls.clear()
  resumed = gtrain.train_gaussians(CFG, scene, out, None, show_progress=False)
  assert calls == list(range(60, STEPS))
  jax.tree_util.tree_map(np.testing.assert_array_equal, jax.device_get(full.state),
                         jax.device_get(resumed.state))
  assert [r['step'] for r in rundir.read_jsonl(rundir.log_path(out))] == list(
      range(1, STEPS + 1))


def test_pseudo_views_are_drawn_only_inside_the_window(scene, tmp_path):
  idx = scene.test_idx[:2]
  masks = np.ones((2, 24, 32), np.float32)
  masks[1, :, :16] = 0.
  pseudo = PseudoViews(images=jnp.asarray(scene.images[idx]),
                       poses=jnp.asarray(scene.poses[idx]), masks=jnp.asarray(masks),
                       uncertainty=jnp.zeros((2, 24, 32), jnp.float32))
  out = str(tmp_path / 'p')
  res = gtrain.train_gaussians(CFG, scene, out, pseudo, window=(10, 40),
                               show_progress=False)
  recs = rundir.read_jsonl(rundir.log_path(out))
  drawn = [r['step'] for r in recs if r['pseudo_rays'] > 0]
  assert drawn and all(11 <= s <= 40 for s in drawn)  # Steps 10..39 (step = done).
  assert {r['pseudo_rays'] for r in recs if r['pseudo_rays'] > 0} <= {768, 384}
  counts = [r['pseudo_images'] for r in recs]
  assert counts[9] == 0 and counts[-1] == counts[39] == len(drawn) == int(
      res.state.pseudo_images)
  assert 3 <= len(drawn) <= 24  # ~2/5 of 30 steps.


def test_world_bounds_hold_the_scene_and_the_random_init(scene):
  """The procedural scene's true surface points seen by the training views lie in
  Scene.world_bounds (made from the training cameras only), where init_gaussians
  spreads its Gaussians; the NDC bbox is unchanged."""
  lo, hi = (np.asarray(b) for b in scene.world_bounds)
  assert scene.bbox == ((-1.,) * 3, (1.,) * 3) and scene.use_ndc
  h, w, f = scene.height, scene.width, scene.focal
  ys, xs = np.mgrid[:h, :w] + 0.5
  dirs = np.stack([(xs - w / 2) / f, -(ys - h / 2) / f, -np.ones_like(xs)], -1)
  pts = np.concatenate([(dirs @ c2w[:3, :3].T) * d[..., None] + c2w[:3, 3]
                        for c2w, d in zip(scene.poses[scene.train_idx],
                                          scene.depths[scene.train_idx])]).reshape(-1, 3)
  inside = np.all((pts >= lo - 1e-4) & (pts <= hi + 1e-4), -1)
  assert inside.mean() > 0.99
  g = gtrain.init_gaussians(CFG, scene, jax.random.PRNGKey(0))
  m = np.asarray(g.means)[np.asarray(g.active)]
  assert len(m) == CFG.gs_init_points and g.means.shape == (CFG.gs_capacity, 3)
  assert np.all((m >= lo - 1e-5) & (m <= hi + 1e-5))


def test_views_seeing_counts_the_cameras_whose_image_holds_a_point():
  """Cameras at the origin and at x = 1 looking down -z, a third at the origin looking
  along +x (24x32 pixels, focal 30): in front beyond near and inside the image counts."""
  look_x = np.array([[0., 0., -1., 0.], [0., 1., 0., 0.], [1., 0., 0., 0.]])
  shifted = np.eye(4)[:3].copy()
  shifted[0, 3] = 1.
  poses = np.stack([np.eye(4)[:3], shifted])
  points = np.array([[0., 0., -2.], [0., 0., 1.], [0., 0., -0.05], [-1.5, 0., -2.],
                     [1., 0., -2.], [1.5, 0., -2.], [0., 1., -2.]])
  np.testing.assert_array_equal(gstart.views_seeing(points, poses, 30., 24, 32, 0.1),
                                [2, 0, 0, 0, 2, 1, 0])
  np.testing.assert_array_equal(
      gstart.views_seeing(np.array([[2., 0., 0.], [0., 0., -2.]]), look_x[None], 30.,
                          24, 32, 0.1), [1, 0])


def test_the_random_start_among_points_that_k_training_views_see(scene):
  """Config.gs_init_views = 2: every initial Gaussian is seen by 2 or more training views
  (the box-uniform start has points that fewer see), the same for the same key; a box
  that no camera sees is refused in one line."""
  train = scene.poses[scene.train_idx]
  count = lambda m: gstart.views_seeing(m, train, scene.focal, scene.height, scene.width,
                                        scene.near)
  box = gtrain.init_gaussians(CFG, scene, jax.random.PRNGKey(0))
  assert np.mean(count(np.asarray(box.means)[np.asarray(box.active)]) < 2) > 0.05
  cfg = dataclasses.replace(CFG, gs_init_views=2)
  g = gtrain.init_gaussians(cfg, scene, jax.random.PRNGKey(0))
  m = np.asarray(g.means)[np.asarray(g.active)]
  assert len(m) == CFG.gs_init_points and g.means.shape == (CFG.gs_capacity, 3)
  assert np.all(count(m) >= 2)
  lo, hi = (np.asarray(b) for b in scene.world_bounds)
  assert np.all((m >= lo - 1e-5) & (m <= hi + 1e-5))
  assert np.all(np.asarray(g.log_scales)[:len(m)] < np.log(np.max(hi - lo)))
  again = gtrain.init_gaussians(cfg, scene, jax.random.PRNGKey(0))
  np.testing.assert_array_equal(np.asarray(again.means), np.asarray(g.means))
  # Without knn both starts (box-uniform, seen points) share the box spacing
  # (params.box_spacing).
  flat = gtrain.init_gaussians(dataclasses.replace(cfg, gs_init_knn=False), scene,
                               jax.random.PRNGKey(0))
  flat_box = gtrain.init_gaussians(dataclasses.replace(CFG, gs_init_knn=False), scene,
                                   jax.random.PRNGKey(0))
  spacing = np.mean(hi - lo) / CFG.gs_init_points**(1. / 3.)
  np.testing.assert_allclose(np.exp(np.asarray(flat.log_scales)), spacing, rtol=1e-5)
  np.testing.assert_array_equal(np.asarray(flat.log_scales), np.asarray(flat_box.log_scales))
  behind = train[:, :3, 3].mean(0) + 100. * train[:, :3, 2].mean(0)  # Behind them all.
  with pytest.raises(DataError, match='gs_init_views=2: only 0 of 2048 random points'):
    gstart.seen_points(jax.random.PRNGKey(0), 512, behind - 1., behind + 1., scene, 2,
                       rounds=1)


# ----------------------------------------------------------------------------- ply


def test_ply_round_trip(tmp_path):
  g = random_gaussians(7, 10, seed=4)
  path = str(tmp_path / 'sub' / 'point_cloud.ply')
  assert ply.write_ply(path, g) == 7
  assert [p for p in os.listdir(tmp_path / 'sub')] == ['point_cloud.ply']
  with open(path, 'rb') as f:
    data = f.read()
  names = ([f'f_rest_{i}' for i in range(45)])
  want = ('ply\nformat binary_little_endian 1.0\nelement vertex 7\n' +
          ''.join(f'property float {p}\n' for p in
                  ['x', 'y', 'z', 'nx', 'ny', 'nz', 'f_dc_0', 'f_dc_1', 'f_dc_2'] + names +
                  ['opacity', 'scale_0', 'scale_1', 'scale_2', 'rot_0', 'rot_1', 'rot_2',
                   'rot_3']) + 'end_header\n').encode()
  assert data.startswith(want) and len(data) == len(want) + 7 * 62 * 4
  rows = np.frombuffer(data[len(want):], '<f4').reshape(7, 62)
  # Channel-major f_rest: f_rest_0..14 are red's coefficients 1..15, then green's.
  np.testing.assert_array_equal(rows[:, 9:24], np.asarray(g.sh)[:7, 1:, 0])
  np.testing.assert_array_equal(rows[:, 24:39], np.asarray(g.sh)[:7, 1:, 1])
  np.testing.assert_array_equal(rows[:, 3:6], 0.)
  back = ply.read_ply(path, capacity=10)
  for k in ('means', 'log_scales', 'quats', 'opacity_logits', 'sh'):
    np.testing.assert_array_equal(getattr(back, k)[:7], np.asarray(getattr(g, k))[:7])
    assert np.all(getattr(back, k)[7:] == 0.)
  np.testing.assert_array_equal(back.active, np.asarray(g.active))
  with pytest.raises(ValueError):
    ply.read_ply(path, capacity=5)


def test_renerf_rounds_run_on_gaussians_and_resume(scene, tmp_path):
  """Config.backbone = 'gaussians' through the round driver and its run directory: B's
  renders become the pseudo-views, D draws them only before K, finished rounds load."""
  from flax import serialization  # pylint: disable=g-import-not-at-top
  from renerf_jax import backbones, round_driver  # pylint: disable=g-import-not-at-top
  cfg = dataclasses.replace(CFG, num_rounds=1, interp_factors='0.5',
                            lpips_nets=())  # LPIPS-alex needs 31 px a side.
  run_dir = str(tmp_path / 'run')
  state = round_driver.run_rounds(cfg, scene, run_dir, show_progress=False)
  assert [m['round'] for m in state.metrics] == [0, 1]
  assert all(np.isfinite(m['psnr']) and m['nan_skips'] == 0 for m in state.metrics)
  assert isinstance(state.params, params_lib.Gaussians)
  backbone = backbones.get_backbone(cfg)
  with open(rundir.params_path(rundir.round_dir(run_dir, 0)), 'rb') as f:
    b_params = serialization.from_bytes(backbone.init_params(cfg), f.read())
  assert state.pseudo.images.shape == (2, 24, 32, 3)  # 2 pairs x the factor 0.5
  np.testing.assert_array_equal(state.pseudo.masks, 1.)  # No masks on 3DGS.
  want = np.clip(backbone.render_views(cfg, scene, b_params, state.pseudo.poses)['rgb'],
                 0., 1.)
  np.testing.assert_allclose(state.pseudo.images, want, atol=1e-6)
  log = rundir.read_jsonl(rundir.round_log_path(run_dir, 1))
  k = int(round(cfg.pseudo_until_frac * cfg.max_steps))
  drawn = [r['step'] for r in log if r['pseudo_rays'] > 0]
  assert drawn and max(drawn) <= k  # Pseudo-views only in D's first K steps.
  assert log[-1]['pseudo_images'] == log[k - 1]['pseudo_images'] == len(drawn)
  assert all(r['pseudo_rays'] == 0
             for r in rundir.read_jsonl(rundir.round_log_path(run_dir, 0)))
  r1 = rundir.round_dir(run_dir, 1)
  assert os.path.isfile(rundir.metrics_path(rundir.eval_dir(r1)))
  exported = ply.read_ply(rundir.point_cloud_path(r1))
  active = np.asarray(state.params.active)
  np.testing.assert_array_equal(exported.means, np.asarray(state.params.means)[active])
  again = round_driver.run_rounds(cfg, scene, run_dir, show_progress=False)
  jax.tree_util.tree_map(np.testing.assert_array_equal, again.params, state.params)
  assert [m['psnr'] for m in again.metrics] == [m['psnr'] for m in state.metrics]
