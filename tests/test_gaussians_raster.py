"""The block lists of the rasteriser (issue 51): the pair sort against the tile lists,
alpha-reach culling against brute force, the capacity, and extreme scenes."""
import jax
import jax.numpy as jnp
import numpy as np

from renerf_jax import cameras
from renerf_jax.gaussians import blocks
from renerf_jax.gaussians import params
from renerf_jax.gaussians import projection
from renerf_jax.gaussians import rasterize
from renerf_jax.gaussians import reference
from renerf_jax.gaussians import render
from renerf_jax.gaussians import tiles

H, W, FOCAL = 40, 56, 40.
BG = np.array([0.2, 0.3, 0.4], np.float32)


def _pose(eye=(0.3, -0.2, 4.)):
  eye = np.asarray(eye, np.float64)
  return jnp.asarray(cameras.view_matrix(eye, np.array([0., 1., 0.]), eye), jnp.float32)


def _scene(seed, n, log_scale=(-2.5, -1.), spread=1., logits=(-4., 3.)):
  """n random coloured Gaussians around the origin, opacities from ~0.02 to ~0.95."""
  rng = np.random.default_rng(seed)
  f = lambda x: jnp.asarray(x, jnp.float32)
  sh = 0.1 * rng.normal(size=(n, 16, 3))
  sh[:, 0] = rng.uniform(-1.5, 1.5, size=(n, 3))
  return params.Gaussians(
      means=f(rng.uniform(-spread, spread, (n, 3))),
      log_scales=f(rng.uniform(*log_scale, (n, 3))), quats=f(rng.normal(size=(n, 4))),
      opacity_logits=f(rng.uniform(*logits, n)), sh=f(sh), active=jnp.ones(n, bool))


def _screen(g, c2w, height=H, width=W):
  proj = projection.project(g.means, g.log_scales, g.quats, g.active, c2w, FOCAL, height,
                            width)
  colours = params.eval_sh(3, g.sh, g.means - c2w[:, 3])
  return proj, colours, jax.nn.sigmoid(g.opacity_logits)


def _pairs(proj, opac, capacity, height=H, width=W):
  return blocks.pair_lists(proj.means2d, proj.radius, proj.conics, opac, proj.depths,
                           proj.valid, height, width, 16, 8, capacity)


def test_pair_lists_are_the_block_lists_of_the_uncapped_tile_lists():
  g = _scene(0, 400)
  proj, _, opac = _screen(g, _pose())
  tile_ids, count = tiles.tile_intersect(proj.means2d, proj.radius, proj.depths,
                                         proj.valid, H, W, cap=0)
  want, want_len = blocks.block_lists(tile_ids, proj.means2d, proj.conics, opac, H, W,
                                      16, 8)
  ids, length, count2, bound = _pairs(proj, opac, 512)
  np.testing.assert_array_equal(length, want_len)
  np.testing.assert_array_equal(count2, count)
  assert not np.asarray(bound).any()
  ids, want = np.asarray(ids), np.asarray(want)
  for k, n in enumerate(np.asarray(length)):
    np.testing.assert_array_equal(ids[k, :n], want[k, :n])
    assert np.all(ids[k, n:] == 400) and np.all(want[k, n:] == 400)
  # Alpha-reach culling leaves out most of the tile lists' pairs.
  assert int(length.sum()) < 0.6 * int(count.sum()) * 4


def test_pair_lists_sorting_a_prefix_of_the_buffer_changes_nothing(monkeypatch):
  """pair_lists sorts only the smallest prefix of its buffer that holds the pairs: the
  same lists, lengths and bindings as sorting the whole buffer, for pair totals from
  a tenth of the buffer to beyond it (the capacity binding)."""
  g = _scene(2, 400)
  proj, _, opac = _screen(g, _pose())
  num_blocks = np.prod(blocks.block_grid(H, W, 16, 8))
  total = int(_pairs(proj, opac, 512)[1].sum())
  assert total > 10 * num_blocks
  seen = set()
  for fill in (0.1, 0.45, 0.7, 0.95, 1., 2.):  # total / buffer size.
    capacity = max(int(total / (fill * num_blocks)), 1)
    got = _pairs(proj, opac, capacity)
    with monkeypatch.context() as m:
      m.setattr(blocks, 'SIZE_STEPS', 1)  # The whole buffer only.
      want = _pairs(proj, opac, capacity)
    for a, b in zip(got, want):
      np.testing.assert_array_equal(a, b)
    seen.add(bool(np.asarray(got[3]).any()))
  assert seen == {False, True}  # Some capacities bind, some do not.


def test_block_lists_keep_every_gaussian_that_reaches_a_pixel_of_the_block():
  g = _scene(1, 300)
  proj, _, opac = _screen(g, _pose())
  tile_ids, _ = tiles.tile_intersect(proj.means2d, proj.radius, proj.depths, proj.valid,
                                     H, W, cap=0)
  ids, length = blocks.block_lists(tile_ids, proj.means2d, proj.conics, opac, H, W, 16, 8)
  ids, length, tile_ids = np.asarray(ids), np.asarray(length), np.asarray(tile_ids)
  m2, cn, op = (np.asarray(x, np.float64) for x in (proj.means2d, proj.conics, opac))
  blocks_y, blocks_x = blocks.block_grid(H, W, 16, 8)
  dropped = 0
  for k in range(blocks_y * blocks_x):
    by, bx = divmod(k, blocks_x)
    tile = (by // 2) * (-(-W // 16)) + bx // 2
    ys, xs = np.mgrid[by * 8:by * 8 + 8, bx * 8:bx * 8 + 8] + 0.5
    full = [i for i in tile_ids[tile] if i < 300]
    kept = list(ids[k, :length[k]])
    assert kept == [i for i in full if i in set(kept)]  # A sub-list, same order.
    for i in set(full) - set(kept):
      dx, dy = m2[i, 0] - xs, m2[i, 1] - ys
      sigma = 0.5 * (cn[i, 0] * dx**2 + cn[i, 2] * dy**2) + cn[i, 1] * dx * dy
      alpha = np.minimum(0.99, op[i] * np.exp(-np.maximum(sigma, 0.)))
      assert not np.any((sigma >= 0.) & (alpha >= 1. / 255. * (1. - 1e-4))), (k, i)
      dropped += 1
  assert dropped > 1000


def test_alpha_reach_bounds_the_ellipse_and_gives_up_on_elongated_conics():
  cov = np.array([[9., 2.], [2., 4.]])
  inv = np.linalg.inv(cov)
  conics = jnp.asarray([[inv[0, 0], inv[0, 1], inv[1, 1]]] * 4, jnp.float32)
  opac = jnp.asarray([0.5, 1. / 255., 0.9 / 255., 0.5], jnp.float32)
  conics = conics.at[3].set(jnp.asarray([1., 0.99999, 1.]))  # Elongation ~1e5.
  rx, ry = (np.asarray(r) for r in blocks.alpha_reach(conics, opac))
  s = np.log(255. * 0.5)
  np.testing.assert_allclose([rx[0], ry[0]], np.sqrt(2. * s * np.diag(cov)), rtol=2e-3)
  assert 0. < rx[1] < 0.2 and rx[2] == ry[2] == -1.  # Below 1/255: no pixel.
  assert rx[3] == ry[3] == np.inf
  # The reach is tight: the ellipse sigma = s touches the box.
  t = np.linspace(0., 2. * np.pi, 2001)
  ring = np.linalg.cholesky(cov) @ np.stack([np.cos(t), np.sin(t)]) * np.sqrt(2. * s)
  np.testing.assert_allclose(np.abs(ring).max(1), [rx[0], ry[0]], rtol=2e-3)


def test_capacity_keeps_the_nearest_and_reports_every_tile_it_binds():
  """Forty Gaussians covering a 16x16 image: a capacity of 2 (8 pairs in the 4 blocks,
  4 per block) keeps the 2 nearest in every block, as a tile cap of 2 does."""
  rng = np.random.default_rng(3)
  n = 40
  g = params.Gaussians(
      means=jnp.asarray(np.c_[rng.uniform(-0.05, 0.05, (n, 2)), rng.uniform(-1., 1., n)],
                        jnp.float32),
      log_scales=jnp.full((n, 3), 0.5), quats=jnp.tile(jnp.array([[1., 0., 0., 0.]]), (n, 1)),
      opacity_logits=jnp.full((n,), -1.), sh=jnp.asarray(rng.normal(size=(n, 16, 3)),
                                                         jnp.float32),
      active=jnp.ones(n, bool))
  c2w = _pose((0., 0., 4.))
  proj, _, opac = _screen(g, c2w, 16, 16)
  ids, length, count, bound = _pairs(proj, opac, 2, 16, 16)
  assert ids.shape == (4, 4) and np.all(np.asarray(length) == 2)
  assert int(count[0]) == n and bool(bound.all())
  nearest = np.argsort(np.asarray(proj.depths), kind='stable')[:2]
  assert np.all(np.asarray(ids)[:, :2] == nearest)
  out = render.render(g, c2w, FOCAL, 16, 16, 3, BG, 0, capacity=2)
  capped = render.render(g, c2w, FOCAL, 16, 16, 3, BG, 2)
  full = render.render(g, c2w, FOCAL, 16, 16, 3, BG, 0)
  assert float(out['cap_bound']) == 1. and float(full['cap_bound']) == 0.
  for k in ('rgb', 'depth', 'acc'):
    np.testing.assert_allclose(out[k], capped[k], atol=1e-6)
  assert np.abs(np.asarray(out['acc'] - full['acc'])).max() > 0.05


def _grads(g, c2w, cap, capacity=512, near=0.01):
  def loss(means, log_scales, opacity_logits, sh):
    out = render.render(g.replace(means=means, log_scales=log_scales,
                                  opacity_logits=opacity_logits, sh=sh),
                        c2w, FOCAL, H, W, 3, BG, cap, near, capacity=capacity)
    return jnp.sum(out['rgb']**2) + 0.1 * jnp.sum(out['depth']) + jnp.sum(out['acc']), out
  return jax.jit(jax.value_and_grad(loss, argnums=range(4), has_aux=True))(
      g.means, g.log_scales, g.opacity_logits, g.sh)


def test_block_path_matches_the_dense_reference_and_the_tile_path_gradients():
  g = _scene(4, 250)
  c2w = _pose()
  proj, colours, opac = _screen(g, c2w)
  (_, out), grads = _grads(g, c2w, 0)
  (_, out_t), grads_t = _grads(g, c2w, 250)  # A cap that never binds: the tile path.
  ref = reference.dense_reference(proj.means2d, proj.conics, colours, opac, proj.depths,
                                  proj.valid, H, W, BG, radius=proj.radius, tile=16)
  assert float(out['cap_bound']) == 0. and float(out['acc'].max()) > 0.9
  for k, want in zip(('rgb', 'depth', 'acc'), ref):
    np.testing.assert_allclose(out[k], want, atol=2e-5, err_msg=k)
  for a, b in zip(grads, grads_t):
    b = np.asarray(b)
    assert np.abs(b).max() > 0.
    np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-5 * np.abs(b).max())


def test_nothing_visible_renders_the_background_with_zero_gradients():
  g = _scene(5, 50)
  g = g.replace(means=g.means.at[:, 2].set(g.means[:, 2] + 10.))  # All behind the camera.
  (_, out), grads = _grads(g, _pose(), 0)
  assert not np.asarray(out['valid']).any() and np.all(np.asarray(out['count']) == 0)
  np.testing.assert_array_equal(out['rgb'], np.broadcast_to(BG, (H, W, 3)))
  np.testing.assert_array_equal(out['acc'], 0.)
  for x in grads:
    np.testing.assert_array_equal(x, 0.)


def test_one_block_holding_every_gaussian_and_huge_ones_stay_finite():
  """Many tiny Gaussians stacked in one 8x8 block, beyond the capacity, beside huge and
  needle-like ones (elongated conics keep their whole tile box)."""
  rng = np.random.default_rng(6)
  n = 600
  g = _scene(6, n, log_scale=(-6., -5.), spread=0.01, logits=(2., 4.))
  means = np.array(g.means)
  means[:, 2] = rng.uniform(-1., 1., n)
  log_scales = np.asarray(g.log_scales).copy()
  log_scales[:3] = [[3., 3., 3.], [2., -7., -7.], [-7., 3., -7.]]  # Huge, needles.
  g = g.replace(means=jnp.asarray(means), log_scales=jnp.asarray(log_scales))
  c2w = _pose((0., 0., 4.))
  proj, _, opac = _screen(g, c2w)
  rx, _ = blocks.alpha_reach(proj.conics, opac)
  assert np.isinf(np.asarray(rx)[1:3]).any()  # A needle takes the fallback.
  ids, length, count, bound = _pairs(proj, opac, 64)
  assert int(np.asarray(length).max()) == 128 and bool(bound.any())
  (_, out), grads = _grads(g, c2w, 0, capacity=64)
  (_, roomy), _ = _grads(g, c2w, 0, capacity=1024)
  assert 0. < float(out['cap_bound']) < 1. and float(roomy['cap_bound']) == 0.
  for k in ('rgb', 'depth', 'acc'):
    assert np.all(np.isfinite(np.asarray(out[k]))), k
  for x in grads:
    assert np.all(np.isfinite(np.asarray(x)))
  assert float(roomy['acc'].min()) > 0.05  # The huge one covers the image...
  # ...but not where the stack fills the capacity (it lies behind 128 of them); the
  # tiles where nothing binds are untouched.
  free = ~np.asarray(bound).reshape(3, 4).repeat(16, 0).repeat(16, 1)[:H, :W]
  np.testing.assert_allclose(np.asarray(out['rgb'])[free], np.asarray(roomy['rgb'])[free],
                             atol=1e-6)
  assert np.abs(np.asarray(out['acc'] - roomy['acc'])).max() > 0.5
