"""Tests of model.py helpers (render_rays itself is covered by test_training / test_grid)."""
import jax
import jax.numpy as jnp
import numpy as np

from renerf_jax.nerf.model import materialize


def test_materialize_is_the_identity_on_extreme_values():
  x = jnp.array([[jnp.nan, 1.], [jnp.inf, -jnp.inf], [0., -0.], [3e38, 1e-45]])
  y = jax.jit(materialize)(x)
  np.testing.assert_array_equal(np.asarray(y), np.asarray(x))  # NaN in the first entry too
  tree = (jnp.ones((2, 3)), jnp.arange(4.))
  out = jax.jit(materialize)(tree)
  for a, b in zip(out, tree):
    np.testing.assert_array_equal(a, b)
  empty = jnp.zeros((0, 3))
  assert materialize(empty).shape == (0, 3)


def test_materialize_passes_gradients_and_vmaps():
  x = jnp.array([1., -2., 3.])
  g = jax.grad(lambda v: jnp.sum(materialize(v)**2))(x)
  np.testing.assert_allclose(g, 2. * x)
  batched = jax.vmap(materialize)(jnp.array([[jnp.nan, 1.], [2., 3.]]))
  np.testing.assert_array_equal(batched, np.array([[np.nan, 1.], [2., 3.]]))


def test_materialize_changes_no_compiled_result(monkeypatch):
  """Inside a compiled step the helper only moves a fusion boundary: same values."""
  # pylint: disable=g-import-not-at-top
  from conftest import tiny_config
  from renerf_jax.nerf import model
  from renerf_jax.datasets import load_scene, ray_pool
  from renerf_jax.nerf.fields import init_field_params
  # pylint: enable=g-import-not-at-top
  with_it = jax.jit(lambda v: materialize(v * 2.) + 1.)
  without = jax.jit(lambda v: v * 2. + 1.)
  for x in (jnp.arange(24.).reshape(8, 3),
            jnp.array([[jnp.nan, 1., 2.], [jnp.inf, -jnp.inf, 0.]]),  # NaN first: the predicate
            jnp.array([[1., jnp.nan, -jnp.inf], [-0., 3e38, 1e-45]]),
            jnp.zeros((0, 3))):
    y = with_it(x)
    assert y.shape == x.shape and y.dtype == x.dtype
    np.testing.assert_array_equal(np.asarray(y), np.asarray(without(x)))
  # Rendering with it equals rendering with it replaced by the identity (training mode:
  # stratified jitter and density noise from the same key). Bitwise equal on CPU; the
  # tolerance leaves room for another backend's fusion (0.7 if the zeros branch ran).
  config = tiny_config()
  scene = load_scene(config)
  rays = jax.tree_util.tree_map(lambda a: a[:64], ray_pool(scene, scene.train_idx)['rays'])
  params = init_field_params(config, jax.random.PRNGKey(0))

  def render():
    fn = jax.jit(lambda p, r, k: model.render_rays(config, p, r, k, True))
    return jax.device_get(fn(params, rays, jax.random.PRNGKey(1)))

  expected = render()
  monkeypatch.setattr(model, 'materialize', lambda tree: tree)
  got = render()
  assert len(got) == len(expected) == config.num_levels
  for level, ref in zip(got, expected):
    assert level.keys() == ref.keys()
    for k in ref:
      assert np.all(np.isfinite(ref[k])), k
      np.testing.assert_allclose(level[k], ref[k], rtol=1e-5, atol=1e-5, err_msg=k)


def test_outside_box_empty_leaves_no_weight_outside_the_box():
  """Config.outside_box = 'empty': samples outside grid_box have density 0 (so no weight)
  while 'clamp' (the default) gives them the faces' density; inside, the two agree."""
  # pylint: disable=g-import-not-at-top
  from conftest import tiny_config
  from renerf_jax import cameras
  from renerf_jax.nerf import model
  from renerf_jax.nerf.fields import init_field_params
  # pylint: enable=g-import-not-at-top
  box = ((-0.5, -0.5, -0.5), (0.5, 0.5, 0.5))
  kw = dict(field='grid', grid_levels=2, grid_max_res=8, grid_base_res=4, use_ndc=False,
            near=0.5, far=4., grid_box=box, density_bias=3.)
  origins = jnp.tile(jnp.array([[0., 0., -2.]]), (4, 1))
  dirs = jnp.array([[0., 0., 1.], [0.3, 0., 1.], [0., -0.2, 1.], [1., 1., 0.2]])
  dirs = dirs / jnp.linalg.norm(dirs, axis=-1, keepdims=True)
  ones = jnp.ones((4, 1))
  rays = cameras.Rays(origins=origins, directions=dirs, viewdirs=dirs, radii=ones * 1e-3,
                      near=ones * 0.5, far=ones * 4.)
  out = {}
  for mode in ('clamp', 'empty'):
    config = tiny_config(outside_box=mode, **kw)
    params = init_field_params(config, jax.random.PRNGKey(0))
    fine = model.render_rays(config, params, rays, jax.random.PRNGKey(1), train=False)[-1]
    t = fine['t_vals']
    mid = 0.5 * (t[:, 1:] + t[:, :-1])
    pts = np.asarray(origins[:, None] + mid[..., None] * dirs[:, None])
    outside = np.any((pts < -0.5) | (pts > 0.5), axis=-1)
    out[mode] = (np.asarray(fine['density']), outside)
  dens, outside = out['empty']
  assert outside.any() and (~outside).any()
  assert np.all(dens[outside] == 0.) and np.all(np.isfinite(dens))
  assert np.all(out['clamp'][0][out['clamp'][1]] > 0.)  # the faces' density leaks out
  # The ray that misses the box entirely renders nothing with 'empty'.
  assert outside[3].all() and np.all(dens[3] == 0.)
