import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from renerf_jax import fit, rundir
from renerf_jax.nerf import training
from renerf_jax.datasets import load_scene, ray_pool
from renerf_jax.errors import ConfigError
from conftest import REPO, tiny_config


def test_learning_rate_schedule():
  c = tiny_config(lr_init=2e-3, lr_final=2e-5, lr_delay_steps=512, lr_delay_mult=0.01,
                  max_steps=69768)
  lr = lambda s: float(training.learning_rate(jnp.float32(s), c))
  assert lr(0) == pytest.approx(2e-3 * 0.01, rel=1e-4)
  # After the delay, pure log-linear decay.
  t = 512 / 69768
  assert lr(512) == pytest.approx(np.exp(np.log(2e-3) * (1 - t) + np.log(2e-5) * t), rel=1e-4)
  assert lr(69768) == pytest.approx(2e-5, rel=1e-4)
  assert lr(256) < lr(512)


def test_learning_rate_cooldown_holds_then_decays_over_the_last_steps():
  c = tiny_config(lr_init=1e-2, lr_final=1e-3, lr_delay_steps=200, lr_delay_mult=0.01,
                  max_steps=1250, lr_decay_start_frac=0.8)
  lr = lambda s: float(training.learning_rate(jnp.float32(s), c))
  # Constant lr_init from the end of the warm-up to the start of the cool-down (step 1000).
  for s in (200, 600, 1000):
    assert lr(s) == pytest.approx(1e-2, rel=1e-5)
  assert lr(100) < 1e-2
  # Log-linear over the last 250 steps: the geometric mean halfway, lr_final at the end.
  assert lr(1125) == pytest.approx(np.sqrt(1e-2 * 1e-3), rel=1e-4)
  assert lr(1250) == pytest.approx(1e-3, rel=1e-4)
  assert lr(1e6) == pytest.approx(1e-3, rel=1e-4)
  # frac 0 is the mip-NeRF schedule over all steps.
  c0 = tiny_config(lr_init=1e-2, lr_final=1e-3, lr_delay_steps=200, lr_delay_mult=0.01,
                   max_steps=1250)
  assert float(training.learning_rate(jnp.float32(625), c0)) == pytest.approx(
      np.sqrt(1e-2 * 1e-3), rel=1e-4)
  for bad in (1., -0.1):
    with pytest.raises(ConfigError, match='lr_decay_start_frac'):
      tiny_config(lr_decay_start_frac=bad)


def test_masked_mse_all_masked_is_finite_zero_with_zero_gradient():
  rgb, gt = jnp.ones((5, 3)) * .3, jnp.zeros((5, 3))
  mask = jnp.zeros((5, 1))
  assert float(training.masked_mse(rgb, gt, mask)) == 0.
  g = jax.grad(lambda x: training.masked_mse(x, gt, mask))(rgb)
  assert np.all(np.asarray(g) == 0.)
  half = jnp.array([[1.], [1.], [0.], [0.], [0.]])
  assert float(training.masked_mse(rgb, gt, half)) == pytest.approx(0.09, rel=1e-6)


def _setup(**kw):
  config = tiny_config(depth_tv_loss_mult=0., anneal_nearfar=False, **kw)
  scene = load_scene(config)
  pools = {'real': ray_pool(scene, scene.train_idx)}
  return config, scene, pools


def _run(config, scene, pools, n):
  state = training.init_state(config, jax.random.PRNGKey(config.seed))
  cam = training.Camera.of(scene)
  for i in range(n):
    state, stats = training.train_step(config, cam, False, state, pools, jax.random.PRNGKey(i))
  return state, stats


def test_non_finite_step_is_skipped_and_counted():
  config, scene, pools = _setup()
  state, _ = _run(config, scene, pools, 2)
  before = jax.tree_util.tree_map(np.array, state.params)  # copies (state is donated)
  bad = dict(pools, real=dict(pools['real'], rgb=pools['real']['rgb'] * np.nan))
  cam = training.Camera.of(scene)
  state, stats = training.train_step(config, cam, False, state, bad, jax.random.PRNGKey(7))
  assert not bool(stats['finite'])
  assert int(state.nan_skips) == 1 and int(state.step) == 3
  jax.tree_util.tree_map(np.testing.assert_array_equal, before,
                         jax.tree_util.tree_map(np.asarray, state.params))
  state, stats = training.train_step(config, cam, False, state, pools, jax.random.PRNGKey(8))
  assert bool(stats['finite']) and int(state.nan_skips) == 1


def test_all_masked_batch_trains_without_nan():
  config, scene, pools = _setup()
  masked = dict(pools, real=dict(pools['real'], lossmult=pools['real']['lossmult'] * 0.))
  state, stats = _run(config, scene, masked, 2)
  assert bool(stats['finite']) and int(state.nan_skips) == 0
  assert float(stats['mse']) == 0.


def test_same_seed_same_parameters():
  config, scene, pools = _setup()
  a, _ = _run(config, scene, pools, 5)
  b, _ = _run(config, scene, pools, 5)
  jax.tree_util.tree_map(np.testing.assert_array_equal, a.params, b.params)
  c, _ = _run(tiny_config(depth_tv_loss_mult=0., anneal_nearfar=False, seed=1), scene,
              pools, 5)
  assert not np.allclose(jax.tree_util.tree_leaves(a.params)[0],
                         jax.tree_util.tree_leaves(c.params)[0])


def test_train_model_resumes_from_a_mid_run_checkpoint(tmp_path, monkeypatch):
  config, scene, pools = _setup(max_steps=20, checkpoint_every=10, eval_every=0)
  full = training.train_model(config, scene, str(tmp_path / 'a'), pools, show_progress=False)
  # The same run interrupted at step 13 (after its step-10 checkpoint) ...
  real_step, calls = training.train_step, []

  def step(*args, **kwargs):
    calls.append(int(args[3].step))
    if len(calls) == 14:
      raise KeyboardInterrupt('killed at step 13')
    return real_step(*args, **kwargs)
  monkeypatch.setattr(training, 'train_step', step)
  with pytest.raises(KeyboardInterrupt):
    training.train_model(config, scene, str(tmp_path / 'b'), pools, show_progress=False)
  ckpts = rundir.list_checkpoints(rundir.checkpoints_dir(str(tmp_path / 'b')))
  assert [s for s, _ in ckpts] == [10]
  # ... and run again: it restores step 10, trains steps 10..19 once more, and ends where
  # the uninterrupted run ended, bit for bit.
  calls.clear()
  resumed = training.train_model(config, scene, str(tmp_path / 'b'), pools,
                                 show_progress=False)
  assert calls == list(range(10, 20)) and int(resumed.state.step) == 20
  jax.tree_util.tree_map(np.testing.assert_array_equal, full.state.params,
                         resumed.state.params)
  jax.tree_util.tree_map(np.testing.assert_array_equal, full.state.opt_state,
                         resumed.state.opt_state)



def test_train_model_resumes_before_a_damaged_checkpoint(tmp_path, capsys, monkeypatch):
  """A finished run whose last checkpoint (step 20) was cut short: the rerun sets it aside
  (one warning line), restores step 15, trains steps 15..19 once more and ends where the
  uninterrupted run ended, bit for bit (tests/test_damaged_runs.py: the other cases)."""
  config, scene, pools = _setup(max_steps=20, checkpoint_every=5, eval_every=0)
  full = training.train_model(config, scene, str(tmp_path / 'a'), pools, show_progress=False)
  ckpt_dir = rundir.checkpoints_dir(str(tmp_path / 'a'))
  assert [s for s, _ in rundir.list_checkpoints(ckpt_dir)] == [15, 20]
  path = rundir.checkpoint_path(ckpt_dir, 20)
  with open(path, 'r+b') as f:
    f.truncate(1000)
  capsys.readouterr()
  real_step, calls = training.train_step, []
  monkeypatch.setattr(training, 'train_step',
                      lambda *a, **k: calls.append(int(a[3].step)) or real_step(*a, **k))
  resumed = training.train_model(config, scene, str(tmp_path / 'a'), pools,
                                 show_progress=False)
  assert calls == list(range(15, 20)) and int(resumed.state.step) == 20
  assert capsys.readouterr().err.startswith(f'warning: {path} is damaged (')
  jax.tree_util.tree_map(np.testing.assert_array_equal, full.state.params,
                         resumed.state.params)
  assert [s for s, _ in rundir.list_checkpoints(ckpt_dir)] == [15, 20]

_SHARD_SCRIPT = r'''
import jax, numpy as np
from conftest import tiny_config
from renerf_jax import fit, rundir
from renerf_jax.nerf import training
from renerf_jax.datasets import load_scene, ray_pool
config = tiny_config(depth_tv_loss_mult=0., anneal_nearfar=False, density_noise=0.)
scene = load_scene(config)
pools = {'real': ray_pool(scene, scene.train_idx)}
state = training.init_state(config, jax.random.PRNGKey(0))
cam = training.Camera.of(scene)
for i in range(3):
  state, stats = training.train_step(config, cam, False, state, pools, jax.random.PRNGKey(i))
print(jax.device_count(), float(stats['loss']))
'''


def test_data_parallel_on_two_host_devices_matches_one():
  out = []
  for n in (1, 2):
    env = dict(os.environ, XLA_FLAGS=f'--xla_force_host_platform_device_count={n}',
               JAX_PLATFORMS='cpu', PYTHONPATH=os.pathsep.join([str(REPO), str(REPO / 'tests')]))
    res = subprocess.run([sys.executable, '-c', _SHARD_SCRIPT], env=env, capture_output=True,
                         text=True, timeout=300, check=True)
    devices, loss = res.stdout.split()
    assert int(devices) == n
    out.append(float(loss))
  assert out[0] == pytest.approx(out[1], rel=1e-4)


@pytest.mark.parametrize('schedule,window', [('early', (0, 30)), ('all', (0, 100)),
                                             ('late', (70, 100))])
def test_pseudo_windows_of_the_ablation_schedules(schedule, window):
  c = tiny_config(max_steps=100, pseudo_until_frac=0.3, pseudo_schedule=schedule)
  assert fit.pseudo_window(c) == window


def test_trunc_exp_value_clipped_gradient_and_huge_inputs():
  from renerf_jax.nerf.model import raw_to_outputs, trunc_exp
  x = jnp.array([-30., 0., 2., 20., 1e10])
  y = np.asarray(trunc_exp(x))
  assert np.all(np.isfinite(y))
  np.testing.assert_allclose(y[:4], np.exp([-30., 0., 2., 20.]), rtol=1e-5)
  g = np.asarray(jax.vmap(jax.grad(trunc_exp))(x))
  assert np.all(np.isfinite(g))
  np.testing.assert_allclose(g, np.exp(np.clip([-30., 0., 2., 20., 1e10], -15., 15.)),
                             rtol=1e-6)
  _, soft = raw_to_outputs(jnp.zeros(3), jnp.array([-1., 0., 1.]), 0.001, -1., 'softplus')
  _, ex = raw_to_outputs(jnp.zeros(3), jnp.array([-1., 0., 1.]), 0.001, -1., 'exp')
  np.testing.assert_allclose(soft, np.log1p(np.exp([-2., -1., 0.])), rtol=1e-6)
  np.testing.assert_allclose(ex, np.exp([-2., -1., 0.]), rtol=1e-6)


def test_train_model_compiles_the_step_once(tmp_path):
  """The initial state is placed like train_step's output, so step 1 does not recompile."""
  config, scene, pools = _setup(max_steps=3, field='grid', density_activation='exp',
                                grid_levels=4, grid_max_res=32)
  before = training.train_step._cache_size()
  result = training.train_model(config, scene, str(tmp_path), pools, show_progress=False)
  assert int(result.state.step) == 3
  assert training.train_step._cache_size() - before == 1


def _pseudo_pools(config, usable):
  """Pools of the tiny scene with 4 pseudo-views whose masked pixels have colour 7."""
  from renerf_jax.pseudo_views import PseudoViews  # pylint: disable=g-import-not-at-top
  from renerf_jax.nerf.pools import make_pools  # pylint: disable=g-import-not-at-top
  scene = load_scene(config)
  m, h, w = 4, scene.height, scene.width
  rng = np.random.default_rng(0)
  masks = (rng.random((m, h, w)) < usable).astype(np.float32)
  images = np.where(masks[..., None] > 0, np.full((m, h, w, 3), 0.5), 7.).astype(np.float32)
  poses = np.asarray(scene.poses[scene.test_idx[:1]].repeat(m, 0), np.float32)
  pv = PseudoViews(images=images, poses=poses, masks=masks, uncertainty=np.zeros_like(masks))
  return make_pools(config, scene, pv), masks


def test_pixel_mix_draws_every_usable_pixel_alike_and_no_masked_one():
  config = tiny_config(batch_size=256, pseudo_mix='pixels')
  pools, masks = _pseudo_pools(config, usable=0.3)
  assert set(pools) == {'real', 'mixed', 'random_poses'}
  n_real = pools['real']['rgb'].shape[0]
  n_usable = int(masks.sum())
  assert pools['mixed']['rgb'].shape[0] == n_real + n_usable
  share = n_usable / (n_real + n_usable)  # 4 * 0.3 / (3 + 4 * 0.3) ~ 0.29
  draw = jax.jit(lambda k: training.draw_batch(config, pools, True, k, k))
  counts, masked = [], 0
  for i in range(200):
    batch, n_pseudo = draw(jax.random.PRNGKey(i))
    assert set(batch) == {'rays', 'rgb', 'lossmult'}
    counts.append(float(n_pseudo))
    masked += int(np.sum(np.asarray(batch['rgb']) == 7.))
    assert np.all(np.asarray(batch['lossmult']) == 1.)
  assert masked == 0  # never drawn (not drawn with weight 0)
  observed = np.sum(counts) / (200 * config.batch_size)
  sampling_sd = np.sqrt(share * (1 - share) / (200 * config.batch_size))
  assert abs(observed - share) < 4 * sampling_sd, (observed, share)
  # Off the window: real rays only.
  batch, n_pseudo = jax.jit(lambda k: training.draw_batch(config, pools, False, k, k))(
      jax.random.PRNGKey(0))
  assert float(n_pseudo) == 0 and batch['rgb'].shape[0] == config.batch_size


def test_fraction_mix_draws_a_fixed_share_with_masked_pixels_at_weight_zero():
  config = tiny_config(batch_size=256, pseudo_mix='fraction', pseudo_frac=0.25)
  pools, _ = _pseudo_pools(config, usable=0.3)
  assert set(pools) == {'real', 'pseudo', 'random_poses'}
  batch, n_pseudo = jax.jit(lambda k: training.draw_batch(config, pools, True, k, k))(
      jax.random.PRNGKey(1))
  assert float(n_pseudo) == 64
  rgb, lossmult = np.asarray(batch['rgb'][192:]), np.asarray(batch['lossmult'][192:, 0])
  assert np.all((rgb[:, 0] == 7.) == (lossmult == 0.))  # masked: drawn, weight 0
  assert np.any(lossmult == 0.)


def test_all_masked_pseudo_views_leave_a_pixel_mix_of_real_rays_only():
  config = tiny_config(batch_size=128, pseudo_mix='pixels')
  pools, _ = _pseudo_pools(config, usable=0.)
  assert pools['mixed']['rgb'].shape == pools['real']['rgb'].shape
  state = training.init_state(config, jax.random.PRNGKey(0))
  cam = training.Camera.of(load_scene(config))
  state, stats = training.train_step(config, cam, True, state, pools, jax.random.PRNGKey(2))
  assert float(stats['pseudo_rays']) == 0 and np.isfinite(float(stats['loss']))


def test_training_log_times_the_steps_only_and_writes_records_in_order(tmp_path,
                                                                      monkeypatch):
  """rundir.TrainingLog, the logging edge of both training loops: training time stops at
  stop_clock (reading the state and evaluating are not training), records keep their
  key order, evaluated records join the curve, the last step is checkpointed."""
  import flax  # pylint: disable=g-import-not-at-top
  clock = [0.]
  monkeypatch.setattr(rundir.time, 'perf_counter', lambda: clock[0])

  @flax.struct.dataclass
  class State:
    step: np.ndarray
    params: np.ndarray

  class Bar:
    postfix = None

    def set_postfix(self, **kw):
      self.postfix = kw

  def eval_fn(params):
    clock[0] += 100.
    return float(params) + 20.
  cfg = tiny_config(max_steps=4, print_every=2, eval_every=4, checkpoint_every=100)
  bar, curve = Bar(), []
  log = rundir.TrainingLog(cfg, str(tmp_path), eval_fn, 5., curve, 1000., bar)
  for done in range(1, 5):
    clock[0] += 1.  # one training step
    if log.due(done):
      log.stop_clock()
      clock[0] += 50.  # reading the state: not training
      log.record(done, State(step=np.asarray(done), params=np.asarray(0.5)),
                 {'loss': 0.25, 'psnr': 10., 'x': done}, postfix={'n': done})
  assert [log.due(d) for d in range(1, 5)] == [False, True, False, True]
  recs = rundir.read_jsonl(rundir.training_paths(str(tmp_path))[1])
  assert [list(r) for r in recs] == [
      ['step', 'train_seconds', 'time', 'loss', 'psnr', 'x'],
      ['step', 'train_seconds', 'time', 'loss', 'psnr', 'x', 'eval_psnr']]
  assert [(r['train_seconds'], r['time']) for r in recs] == [(7., 1007.), (9., 1009.)]
  assert recs[1]['eval_psnr'] == 20.5 and curve == [recs[1]] and log.train_seconds == 9.
  assert bar.postfix == {'loss': '0.2500', 'psnr': '10.00', 'n': 4, 'test': '20.50'}
  assert [s for s, _ in rundir.list_checkpoints(rundir.training_paths(str(tmp_path))[0])] == [4]


def test_fit_loop_keys_window_hook_and_resume(tmp_path):
  """fit.fit, the loop of both backbones: the fresh state from init_and_step_keys' k_init,
  step s gets fold_in(base_key, s) and pseudo_on inside the window, the hook runs after
  each step with its 1-based index and key, logged records hold log_fields' fields; a
  run stopped after its step-3 checkpoint resumes there and ends as the whole run."""
  import flax  # pylint: disable=g-import-not-at-top

  @flax.struct.dataclass
  class State:
    step: jnp.ndarray
    params: jnp.ndarray

  cfg = tiny_config(max_steps=6, print_every=2, eval_every=0, checkpoint_every=3, seed=4)
  k_init, base_key = fit.init_and_step_keys(cfg)
  calls, hooks = [], []

  def init_state(key):
    np.testing.assert_array_equal(key, k_init)
    return State(step=jnp.zeros((), jnp.int32), params=jnp.zeros((), jnp.float32))

  def step_fn(state, pseudo_on, key):
    s = int(state.step)
    calls.append((s, pseudo_on))
    if s == stop_at[0]:
      raise KeyboardInterrupt
    np.testing.assert_array_equal(key, jax.random.fold_in(base_key, s))
    draw = jax.random.uniform(key)
    return state.replace(step=state.step + 1, params=state.params + draw), {'d': draw}

  def after_step(state, done, key):
    hooks.append(done)
    np.testing.assert_array_equal(key, jax.random.fold_in(base_key, done - 1))
    return state.replace(params=state.params * 0.5)

  def run(out):
    return fit.fit(cfg, out, init_state, step_fn,
                   lambda st, stats: ({'loss': float(stats['d']), 'psnr': 0.}, None),
                   window=(1, 3), after_step=after_step, show_progress=False)

  stop_at = [None]
  full = run(str(tmp_path / 'a'))
  assert calls == [(0, False), (1, True), (2, True), (3, False), (4, False), (5, False)]
  assert hooks == [1, 2, 3, 4, 5, 6] and int(full.state.step) == 6
  recs = rundir.read_jsonl(str(tmp_path / 'a' / 'log.jsonl'))
  assert [r['step'] for r in recs] == [2, 3, 4, 6] and full.curve == []
  calls.clear()
  stop_at[0] = 4
  with pytest.raises(KeyboardInterrupt):
    run(str(tmp_path / 'b'))
  calls.clear()
  stop_at[0] = None
  resumed = run(str(tmp_path / 'b'))
  assert [s for s, _ in calls] == [3, 4, 5]
  assert float(resumed.state.params) == float(full.state.params)
  assert rundir.read_jsonl(str(tmp_path / 'b' / 'log.jsonl'))[-1]['loss'] == recs[-1]['loss']
