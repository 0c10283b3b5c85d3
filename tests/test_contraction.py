"""Scene contraction and disparity spacing (renerf_jax/nerf/contraction.py)."""
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from renerf_jax.nerf import contraction
from renerf_jax.nerf import synthesis


def _dirs(n, seed=0):
  d = np.random.default_rng(seed).normal(size=(n, 3))
  return d / np.linalg.norm(d, axis=-1, keepdims=True)


@pytest.mark.parametrize('order', [2, 'inf'])
def test_contraction_is_identity_inside_continuous_at_the_boundary_and_bounded(order):
  d = _dirs(200)
  if order == 'inf':
    d = d / np.max(np.abs(d), axis=-1, keepdims=True)  # unit L-inf norm
  d = jnp.asarray(d, jnp.float32)
  inside = 0.7 * d
  np.testing.assert_array_equal(contraction.contract(inside, order), inside)
  # Continuous across |x| = 1: points just inside and just outside map 2 eps apart.
  eps = 1e-4
  a = contraction.contract((1. - eps) * d, order)
  b = contraction.contract((1. + eps) * d, order)
  assert float(jnp.max(jnp.abs(a - b))) < 3. * eps
  # Everything lands within radius 2 (to float32 rounding); distant points approach it.
  norm = (lambda x: jnp.linalg.norm(x, axis=-1)) if order == 2 else (
      lambda x: jnp.max(jnp.abs(x), axis=-1))
  for scale in (1.5, 10., 1e3, 1e8):
    assert float(jnp.max(norm(contraction.contract(scale * d, order)))) <= 2. + 1e-6
  np.testing.assert_allclose(norm(contraction.contract(1e6 * d, order)), 2., atol=1e-5)
  # Zero and huge inputs stay finite, with finite gradients.
  x = jnp.asarray([[0., 0., 0.], [1e30, -1e30, 3.]], jnp.float32)
  assert np.all(np.isfinite(contraction.contract(x, order)))
  g = jax.grad(lambda y: jnp.sum(contraction.contract(y, order)))(x)
  assert np.all(np.isfinite(g))


def test_l2_jacobian_closed_form_equals_autodiff_and_is_identity_at_the_boundary():
  rng = np.random.default_rng(1)
  x = jnp.asarray(_dirs(50) * rng.uniform(0.2, 20., (50, 1)), jnp.float32)
  auto = jax.vmap(jax.jacfwd(contraction.contract))(x)
  np.testing.assert_allclose(contraction.contract_jacobian_l2(x), auto, atol=1e-5)
  on = jnp.asarray(_dirs(20) * (1. + 1e-6), jnp.float32)
  np.testing.assert_allclose(contraction.contract_jacobian_l2(on),
                             np.broadcast_to(np.eye(3), (20, 3, 3)), atol=1e-5)


def test_contracted_gaussians_match_monte_carlo_for_small_covariances():
  """The linearised covariance equals the sample covariance of contracted samples when
  the Gaussian is small against its distance."""
  mean = jnp.asarray([3., -2., 1.5], jnp.float32)
  a = np.asarray([[0.05, 0.01, 0.], [0., 0.03, 0.01], [0.02, 0., 0.04]])
  cov = jnp.asarray(a @ a.T, jnp.float32)
  m, c = contraction.contract_gaussians(mean[None], cov[None])
  samples = np.random.default_rng(2).multivariate_normal(np.asarray(mean), np.asarray(cov),
                                                         200000)
  y = np.asarray(contraction.contract(jnp.asarray(samples, jnp.float32)))
  np.testing.assert_allclose(m[0], y.mean(0), atol=2e-3)
  np.testing.assert_allclose(c[0], np.cov(y.T), rtol=0.05, atol=2e-6)
  # Inside the unit ball nothing changes.
  m_in, c_in = contraction.contract_gaussians(0.1 * mean[None], cov[None])
  np.testing.assert_allclose(c_in[0], cov, atol=1e-7)
  np.testing.assert_allclose(m_in[0], 0.1 * mean, atol=1e-7)


@pytest.mark.parametrize('piecewise', [False, True])
def test_disparity_spacing_is_monotone_reaches_far_and_inverts(piecewise):
  near, far = 0.2, 1e4
  s = jnp.linspace(0., 1., 257)
  t = contraction.s_to_t(s, near, far, piecewise)
  assert float(t[0]) == pytest.approx(near) and float(t[-1]) == pytest.approx(far, rel=1e-4)
  assert np.all(np.diff(np.asarray(t)) > 0.)  # monotone
  # Sample spacing grows with distance: far content gets few samples.
  gaps = np.diff(np.asarray(t))
  assert gaps[-1] > 100. * gaps[len(gaps) // 4]
  np.testing.assert_allclose(contraction.t_to_s(t, near, far, piecewise), s, atol=1e-5)
  if piecewise:  # The first half of s is linear on [near, 1].
    half = np.asarray(t[:129])
    np.testing.assert_allclose(np.diff(half), (1. - near) / 128., rtol=1e-4)
    assert float(t[128]) == pytest.approx(1.)
  # A ray with these distances reaches the contracted space's far shell.
  pts = jnp.asarray([0., 0., -1.]) * t[:, None]
  r = jnp.linalg.norm(contraction.contract(pts), axis=-1)
  assert float(r[-1]) > 1.999 and np.all(np.diff(np.asarray(r)) >= 0.)


def test_renderer_gives_the_fields_contracted_samples_out_to_the_far_shell():
  """Config.contraction: every level's sample means reach the field (and the offsets
  hook, Bayes' Rays' deformation) inside radius 2, a ray to 1000 units reaches the far
  shell, and the render stays finite; with NDC the setting is refused in one line."""
  from conftest import tiny_config  # pylint: disable=g-import-not-at-top
  from renerf_jax import cameras  # pylint: disable=g-import-not-at-top
  from renerf_jax.nerf import training  # pylint: disable=g-import-not-at-top
  from renerf_jax.errors import ConfigError  # pylint: disable=g-import-not-at-top
  from renerf_jax.nerf.model import render_rays  # pylint: disable=g-import-not-at-top
  for kind, norm, extra in (
      ('l2', lambda m: jnp.linalg.norm(m, axis=-1), dict(lindisp=True)),
      ('inf', lambda m: jnp.max(jnp.abs(m), axis=-1),  # the density-only proposal level
       dict(piecewise_spacing=True, sampler='proposal', proposal_samples=32,
            field='grid'))):
    cfg = tiny_config(use_ndc=False, contraction=kind, num_samples=32,
                      grid_box=((-2., -2., -2.), (2., 2., 2.)), near=0.2, far=1e3, **extra)
    params = training.init_state(cfg, jax.random.PRNGKey(0)).params
    d = jnp.asarray(_dirs(16, seed=3), jnp.float32)
    ones = jnp.ones((16, 1), jnp.float32)
    rays = cameras.Rays(origins=0.1 * d, directions=d, viewdirs=d, radii=1e-3 * ones,
                        near=0.2 * ones, far=1e3 * ones)
    seen = []

    def offsets(level, means, seen=seen):
      seen.append((level, float(jnp.max(norm(means))), float(jnp.min(norm(means)))))
      return jnp.zeros_like(means)
    outs = render_rays(cfg, params, rays, jax.random.PRNGKey(1), train=False,
                       offsets=offsets)
    assert [s[0] for s in seen] == list(range(cfg.num_levels))
    assert all(hi <= 2. + 1e-5 and hi > 1.99 for _, hi, _ in seen), seen
    assert all(lo < 1. for _, _, lo in seen), seen  # the near samples stay uncontracted
    for out in outs:
      for k in ('distance', 'acc', 'weights') + (('rgb',) if 'rgb' in out else ()):
        assert np.all(np.isfinite(np.asarray(out[k]))), k
  with pytest.raises(ConfigError, match='not NDC'):
    tiny_config(use_ndc=True, contraction='l2')
  with pytest.raises(ConfigError, match='near < 1 < far'):
    tiny_config(use_ndc=False, piecewise_spacing=True, near=2., far=10.)


def test_laplace_deformation_grid_spans_the_space_the_fields_see(monkeypatch):
  """With Config.contraction the Bayes' Rays deformation grid covers the contracted
  cube (where the offsets act), else the scene's box."""
  from conftest import tiny_config  # pylint: disable=g-import-not-at-top
  from renerf_jax.uncertainty import masks as uncertainty_masks  # pylint: disable=g-import-not-at-top
  from renerf_jax.datasets import load_scene  # pylint: disable=g-import-not-at-top
  seen = []

  def fake_masks(config, params, train_rays, rays, lo, hi, **kw):
    seen.append((tuple(np.asarray(lo).tolist()), tuple(np.asarray(hi).tolist())))
    raise StopIteration
  monkeypatch.setattr(uncertainty_masks, 'compute_masks', fake_masks)
  for kind in ('l2', ''):
    cfg = tiny_config(use_ndc=False, contraction=kind)
    scene = load_scene(cfg)
    with pytest.raises(StopIteration):
      synthesis.masked_pseudo_views(cfg, scene, None, scene.poses[:1])
  assert seen[0] == contraction.CONTRACTED_BOX
  assert seen[1] == tuple(tuple(float(v) for v in b) for b in scene.bbox)
  assert seen[1] != seen[0]
