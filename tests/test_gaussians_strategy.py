"""Density control of the Gaussians: density.py's clone / split / prune / statistics and
the densification strategy (strategy.py: its schedule, its jitted state updates)."""
import jax
import jax.numpy as jnp
import numpy as np

from conftest import tiny_config
from gaussian_helpers import random_gaussians
from renerf_jax.gaussians import density
from renerf_jax.gaussians import schedule as gschedule
from renerf_jax.gaussians import training as gtrain
from renerf_jax.gaussians.strategy import DensityStrategy

_CFG = tiny_config()  # 3DGS's thresholds: gradient 5e-4, percent dense 0.01, opacity
# 0.005 (those of the hand-built scene's expectations).


# ----------------------------------------------------------------------------- density


def _hand_built():
  """8 slots, 5 active: 0 small + high grad (clone), 1 large + higher grad (split),
  2 low grad, 3 transparent (pruned), 4 low grad but 25 px on screen; 5..7 free."""
  n = 8
  g = random_gaussians(5, n)
  log_s = np.full((n, 3), np.log(0.05), np.float32)
  log_s[0] = np.log(0.005)
  logits = np.zeros(n, np.float32)
  logits[3] = -8.  # opacity 3e-4 < 0.005
  g = g.replace(log_scales=jnp.asarray(log_s), opacity_logits=jnp.asarray(logits))
  stats = density.DensityStats(
      grad_accum=jnp.asarray([3e-3, 8e-3, 1e-5, 0., 0., 9., 9., 9.], jnp.float32),
      count=jnp.asarray([3., 2., 1., 1., 1., 0., 0., 0.], jnp.float32),
      max_radii=jnp.asarray([3., 9., 9., 2., 25., 0., 0., 0.], jnp.float32))
  return g, stats


def test_clone_split_prune_select_the_expected_slots():
  g, stats = _hand_built()
  key = jax.random.PRNGKey(3)
  fn = jax.jit(density.densify_and_prune)
  new, reset, info = fn(g, stats, key, 5e-4, 0.01, 1., 0.005, False)
  assert {k: int(v) for k, v in info.items()} == {
      'clone': 1, 'split': 1, 'pruned': 1, 'dropped': 0, 'active': 6}
  np.testing.assert_array_equal(new.active, [1, 1, 1, 0, 1, 1, 1, 0])
  np.testing.assert_array_equal(reset, [0, 1, 0, 1, 0, 1, 1, 0])
  # Slot 5 (first free) holds the higher-gradient candidate's second split sample,
  # slot 6 an exact copy of slot 0.
  for k in ('means', 'log_scales', 'quats', 'opacity_logits', 'sh'):
    np.testing.assert_array_equal(getattr(new, k)[6], getattr(g, k)[0])
    for s in (0, 2, 4):
      np.testing.assert_array_equal(getattr(new, k)[s], getattr(g, k)[s])
  small = np.log(0.05) - np.log(1.6)
  np.testing.assert_allclose(new.log_scales[1], small, rtol=1e-6)
  np.testing.assert_allclose(new.log_scales[5], small, rtol=1e-6)
  for k in ('quats', 'opacity_logits', 'sh'):
    np.testing.assert_array_equal(getattr(new, k)[5], getattr(g, k)[1])
  # The two samples are distinct draws from the parent (std 0.05 per axis).
  d1, d5 = np.asarray(new.means[1] - g.means[1]), np.asarray(new.means[5] - g.means[1])
  assert 0. < np.abs(d1).max() < 0.3 and 0. < np.abs(d5).max() < 0.3
  assert not np.allclose(d1, d5)
  # After the first opacity reset, slot 4 (25 px > 20 px on screen) goes too.
  new_b, reset_b, info_b = fn(g, stats, key, 5e-4, 0.01, 1., 0.005, True)
  assert int(info_b['pruned']) == 2 and not bool(new_b.active[4]) and bool(reset_b[4])
  # ... and with a small extent every Gaussian larger than 0.1 extent is pruned.
  new_c, _, _ = fn(g, stats, key, 5e-4, 0.01, 0.3, 0.005, True)
  assert np.flatnonzero(new_c.active).tolist() == [0, 6]


def test_densify_keeps_shapes_and_dtypes():
  g, stats = _hand_built()
  new, reset, info = jax.jit(density.densify_and_prune)(
      g, stats, jax.random.PRNGKey(0), 5e-4, 0.01, 1., 0.005, True)
  for a, b in zip(jax.tree_util.tree_leaves(g), jax.tree_util.tree_leaves(new)):
    assert a.shape == b.shape and a.dtype == b.dtype
  assert reset.shape == (8,) and reset.dtype == bool
  assert all(v.shape == () and v.dtype == jnp.int32 for v in info.values())


def test_full_capacity_takes_the_highest_gradients_and_reports_the_rest():
  n = 6
  g = random_gaussians(4, n).replace(
      log_scales=jnp.full((n, 3), np.log(0.005), jnp.float32),
      opacity_logits=jnp.zeros((n,), jnp.float32))
  grads = jnp.asarray([1e-3, 4e-3, 2e-3, 3e-3, 0., 0.], jnp.float32)
  stats = density.DensityStats(grad_accum=grads, count=jnp.ones((n,), jnp.float32),
                               max_radii=jnp.zeros((n,), jnp.float32))
  new, reset, info = density.densify_and_prune(g, stats, jax.random.PRNGKey(0), 5e-4,
                                               0.01, 1., 0.005)
  assert int(info['dropped']) == 2 and int(info['clone']) == 2
  assert bool(new.active.all())
  # Slot 4 <- slot 1 (4e-3), slot 5 <- slot 3 (3e-3); slots 0 and 2 are not cloned.
  np.testing.assert_array_equal(new.means[4], g.means[1])
  np.testing.assert_array_equal(new.means[5], g.means[3])
  np.testing.assert_array_equal(reset, [0, 0, 0, 0, 1, 1])


def test_accumulate_uses_ndc_units_and_visible_views_only():
  stats = density.init_stats(3)
  grad2d = jnp.asarray([[1., 0.], [0., 2.], [5., 5.]], jnp.float32)
  radius = jnp.asarray([3., 4., 0.], jnp.float32)
  s = density.accumulate(stats, grad2d, radius, 24, 32)
  s = density.accumulate(s, grad2d * 0., radius, 24, 32)
  np.testing.assert_allclose(s.grad_accum, [16., 24., 0.])
  np.testing.assert_array_equal(s.count, [2., 2., 0.])
  np.testing.assert_array_equal(s.max_radii, [3., 4., 0.])
  np.testing.assert_allclose(density.mean_grads(s), [8., 12., 0.])
  off = density.accumulate(s, grad2d, radius, 24, 32, on=False)
  np.testing.assert_array_equal(off.count, s.count)


def test_adam_moments_reset_for_changed_slots_and_opacity_reset():
  g, stats = _hand_built()
  state = gtrain.init_state(_CFG, g, 1.)
  ones = jax.tree_util.tree_map(
      lambda x: jnp.ones_like(x) if x.ndim and x.shape[0] == 8 else x, state.opt_state)
  state = state.replace(opt_state=ones, stats=stats)
  out, info = DensityStrategy.of(_CFG).densify(state, jnp.float32(1.),
                                              jax.random.PRNGKey(0), jnp.asarray(False))
  assert int(info['clone']) == 1 and int(info['split']) == 1
  reset = np.array([0, 1, 0, 1, 0, 1, 1, 0], bool)
  moments = [s for s in jax.tree_util.tree_leaves(
      out.opt_state, is_leaf=lambda s: hasattr(s, 'mu')) if hasattr(s, 'mu')]
  assert len(moments) == len(gschedule.FIELDS)
  for s in moments:
    assert int(s.count) == 0  # Adam's step count is kept.
    for x in jax.tree_util.tree_leaves((s.mu, s.nu)):
      x = np.asarray(x).reshape(8, -1)
      assert np.all(x[reset] == 0.) and np.all(x[~reset] == 1.)
  assert float(out.stats.count.sum()) == 0. and int(out.dropped) == 0
  # Opacity reset: clamped to 0.01, the opacity moments zeroed, the others kept.
  g, _ = _hand_built()  # (densify donated the first one.)
  st = gtrain.init_state(_CFG, g.replace(opacity_logits=jnp.linspace(-6., 3., 8)), 1.)
  st = st.replace(opt_state=jax.tree_util.tree_map(
      lambda x: jnp.ones_like(x) if x.ndim and x.shape[0] == 8 else x, st.opt_state))
  before = np.asarray(st.params.opacity_logits)
  st = DensityStrategy.of(_CFG).reset_opacity(st)
  op = np.asarray(jax.nn.sigmoid(st.params.opacity_logits))
  assert np.all(op <= 0.01 + 1e-7)
  keep = jax.nn.sigmoid(before) < 0.01
  np.testing.assert_array_equal(np.asarray(st.params.opacity_logits)[keep], before[keep])
  inner = st.opt_state.inner_states
  for name in gschedule.FIELDS:
    adam = inner[name].inner_state.inner_state[0]
    want = 0. if name == 'opacity_logits' else 1.
    assert np.all(np.asarray(adam.mu[name]) == want), name
    assert np.all(np.asarray(adam.nu[name]) == want), name


# ----------------------------------------------------------------------------- strategy


def test_strategy_densifies_and_resets_when_its_schedule_says(monkeypatch):
  """step_post_backward: densify at refine_start < done < refine_stop, every
  refine_every, with prune_big after the first reset and the second half of the step's
  key; reset the opacities every reset_every before refine_stop; nothing else."""
  s = DensityStrategy(grad_threshold=2e-4, percent_dense=0.01, min_opacity=0.005,
                      refine_start=4, refine_stop=20, refine_every=2, reset_every=6)
  calls = []
  monkeypatch.setattr(DensityStrategy, 'densify', lambda self, st, ext, key, big: (
      calls.append(('densify', st, np.asarray(key), bool(big))) or (st + 1, {})))
  monkeypatch.setattr(DensityStrategy, 'reset_opacity', lambda self, st: (
      calls.append(('reset', st)) or st + 100))
  key = jax.random.PRNGKey(5)
  state = 0
  for done in range(1, 30):
    state = s.step_post_backward(state, done, jnp.float32(1.), key)
  densified = [c for c in calls if c[0] == 'densify']
  assert [c[1] for c in calls] == sorted(c[1] for c in calls)  # The state is threaded.
  resets = [i for i, c in enumerate(calls) if c[0] == 'reset']
  assert len(densified) == 7 and len(resets) == 3  # done 6, 8, ..., 18; 6, 12, 18.
  assert [c[3] for c in densified] == [False, True, True, True, True, True, True]
  np.testing.assert_array_equal(densified[0][2], np.asarray(jax.random.split(key)[1]))
  assert [calls[i - 1][0] for i in resets] == ['densify'] * 3  # Densify, then reset.
  assert state == 7 + 300
