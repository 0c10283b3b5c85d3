"""3D Gaussian Splatting core: projection, tiles and rasteriser against dense oracles."""
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from renerf_jax import cameras
from renerf_jax.gaussians import params
from renerf_jax.gaussians import projection
from renerf_jax.gaussians import rasterize
from renerf_jax.gaussians import reference
from renerf_jax.gaussians import render
from renerf_jax.gaussians import tiles

H, W, FOCAL = 24, 32, 30.
BG = np.array([0.2, 0.3, 0.4], np.float32)


def _pose(eye=(0.3, -0.2, 4.), target=(0., 0., 0.)):
  """OpenGL camera-to-world looking from eye at target, +y roughly up."""
  eye = np.asarray(eye, np.float64)
  return cameras.view_matrix(eye - np.asarray(target), np.array([0., 1., 0.]), eye)


def _scene(seed, n, spread=1., log_scale=(-2.5, -1.), sh_scale=0.1, capacity=None):
  """n random anisotropic, rotated, coloured Gaussians around the origin."""
  rng = np.random.default_rng(seed)
  capacity = capacity or n
  f = lambda x: jnp.asarray(x, jnp.float32)
  sh = sh_scale * rng.normal(size=(capacity, 16, 3))
  sh[:, 0] = rng.uniform(-1.5, 1.5, size=(capacity, 3))
  return params.Gaussians(
      means=f(rng.uniform(-spread, spread, (capacity, 3))),
      log_scales=f(rng.uniform(*log_scale, (capacity, 3))),
      quats=f(rng.normal(size=(capacity, 4))),
      opacity_logits=f(rng.uniform(-1., 3., capacity)),
      sh=f(sh), active=jnp.arange(capacity) < n)


def _screen(g, c2w, height=H, width=W, sh_degree=3):
  proj = projection.project(g.means, g.log_scales, g.quats, g.active, jnp.asarray(c2w,
                            jnp.float32), FOCAL, height, width)
  colours = params.eval_sh(sh_degree, g.sh, g.means - jnp.asarray(c2w[:, 3], jnp.float32))
  return proj, colours, jax.nn.sigmoid(g.opacity_logits)


# ----------------------------------------------------------------------------- rasteriser


@pytest.mark.parametrize('cap_mode', ['loose', 'binding'])
def test_tiled_rasteriser_matches_dense_reference(cap_mode):
  g = _scene(0, 150)
  proj, colours, opac = _screen(g, _pose())
  assert int(proj.valid.sum()) > 100
  ref = reference.dense_reference(proj.means2d, proj.conics, colours, opac, proj.depths,
                                  proj.valid, H, W, BG, radius=proj.radius, tile=16)
  _, count = tiles.tile_intersect(proj.means2d, proj.radius, proj.depths, proj.valid, H,
                                  W, cap=256)
  count = np.asarray(count)
  cap = 256 if cap_mode == 'loose' else int(count.min())
  ids, count2 = tiles.tile_intersect(proj.means2d, proj.radius, proj.depths, proj.valid, H,
                                     W, cap=cap)
  np.testing.assert_array_equal(count, count2)
  out = rasterize.rasterize(ids, proj.means2d, proj.conics, colours, opac, proj.depths,
                            H, W, BG)
  # Pixels of tiles where the cap does not bind.
  free = (count <= cap).reshape(2, 2).repeat(16, 0).repeat(16, 1)[:H, :W]
  if cap_mode == 'binding':
    assert count.max() > cap and free.any() and not free.all()
  for got, want in zip(out, ref):
    np.testing.assert_allclose(np.asarray(got)[free], np.asarray(want)[free], atol=1e-5)
  if cap_mode == 'binding':  # Dropping Gaussians is visible where the cap binds.
    assert np.abs(np.asarray(out[2]) - np.asarray(ref[2]))[~free].max() > 1e-3
  # The untiled oracle (no box culling) differs only by the faint tails beyond 3 sigma.
  full = reference.dense_reference(proj.means2d, proj.conics, colours, opac, proj.depths,
                                   proj.valid, H, W, BG)
  np.testing.assert_allclose(np.asarray(full[0])[free], np.asarray(ref[0])[free],
                             atol=0.05)


@pytest.mark.parametrize('chunk', [8, 32])
def test_rasteriser_vjp_matches_autodiff_of_the_dense_reference(chunk):
  """The custom VJP (back to front from the final transmittance) against autodiff of the
  box-culled dense oracle, float64, with uncapped lists spanning many chunks and pixels
  that end early (T below 1e-4)."""
  g = _scene(0, 150, log_scale=(-2., -0.8))
  proj, colours, opac = _screen(g, _pose())
  with jax.enable_x64(True):
    f64 = lambda x: jnp.asarray(np.asarray(x), jnp.float64)
    args = [f64(x) for x in (proj.means2d, proj.conics, colours,
                             np.minimum(1.5 * np.asarray(opac), 1.), proj.depths)]
    bg = f64(BG)
    ids, count = tiles.tile_intersect(f64(proj.means2d), f64(proj.radius), args[4],
                                      proj.valid, H, W, cap=0)
    assert ids.shape == (4, 150) and int(count.max()) > 3 * chunk
    ended, walked, length = rasterize.walk(ids, *args, H, W, chunk=chunk)
    ended = np.asarray(ended)
    assert ended.any() and not ended.all()  # Some pixels end early, some do not.
    assert int(length.max()) > 2 * chunk and int(walked.max()) > 2  # Lists span chunks.
    rng = np.random.default_rng(1)
    wts = [jnp.asarray(rng.normal(size=s)) for s in [(H, W, 3), (H, W), (H, W)]]

    def weighted(out):
      return (jnp.sum(out[0] * wts[0]) + 0.1 * jnp.sum(out[1] * wts[1]) +
              jnp.sum(out[2] * wts[2]))

    def ours(*a):
      return weighted(rasterize.rasterize(ids, *a[:5], H, W, a[5], chunk=chunk))

    def ref(*a):
      return weighted(reference.dense_reference(*a[:5], proj.valid, H, W, a[5],
                                                radius=f64(proj.radius), tile=16))

    v0, g0 = jax.value_and_grad(ours, argnums=range(6))(*args, bg)
    v1, g1 = jax.value_and_grad(ref, argnums=range(6))(*args, bg)
    np.testing.assert_allclose(float(v0), float(v1), rtol=1e-10)
    names = ('means2d', 'conics', 'colours', 'opacities', 'depths', 'background')
    for name, a, b in zip(names, g0, g1):
      assert np.abs(np.asarray(b)).max() > 1e-3, name
      np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-8,
                                 atol=1e-10 * np.abs(np.asarray(b)).max(), err_msg=name)


def test_uncapped_lists_hold_every_overlap_and_match_the_reference():
  g = _scene(2, 300)
  proj, colours, opac = _screen(g, _pose())
  ids, count = tiles.tile_intersect(proj.means2d, proj.radius, proj.depths, proj.valid, H,
                                    W, cap=0)
  assert ids.shape == (4, 300) and int(count.max()) > 256
  out = render.render(g, jnp.asarray(_pose(), jnp.float32), FOCAL, H, W, 3, BG, 0)
  assert float(out['cap_bound']) == 0.
  ref = reference.dense_reference(proj.means2d, proj.conics, colours, opac, proj.depths,
                                  proj.valid, H, W, BG, radius=proj.radius, tile=16)
  for k, want in zip(('rgb', 'depth', 'acc'), ref):
    np.testing.assert_allclose(out[k], want, atol=2e-5, err_msg=k)
  # A cap of 8 keeps exactly the first 8 entries of each uncapped list.
  ids8, _ = tiles.tile_intersect(proj.means2d, proj.radius, proj.depths, proj.valid, H, W,
                                 cap=8)
  np.testing.assert_array_equal(ids8, np.asarray(ids)[:, :8])


def test_tile_lists_are_depth_sorted_and_padded():
  g = _scene(1, 60)
  proj, _, _ = _screen(g, _pose())
  ids, count = tiles.tile_intersect(proj.means2d, proj.radius, proj.depths, proj.valid, H,
                                    W, cap=64)
  ids, count = np.asarray(ids), np.asarray(count)
  overlap = np.asarray(tiles.tile_overlap(proj.means2d, proj.radius, proj.valid, H, W))
  depths = np.asarray(proj.depths)
  for t in range(ids.shape[0]):
    assert count[t] <= 60
    real = ids[t, :count[t]]
    assert set(real) == set(np.flatnonzero(overlap[t]))
    assert np.all(np.diff(depths[real]) >= 0.)
    assert np.all(ids[t, count[t]:] == 60)


def test_single_gaussian_matches_closed_form():
  c2w = _pose(eye=(0.1, 0.2, 3.))
  colour = np.array([0.9, 0.1, 0.5], np.float32)
  g = params.Gaussians(
      means=jnp.array([[0.13, -0.07, 0.2]]), log_scales=jnp.log(jnp.array([[0.3, 0.12,
                                                                           0.2]])),
      quats=jnp.array([[0.9, 0.2, -0.3, 0.4]]), opacity_logits=jnp.array([1.4]),
      sh=jnp.zeros((1, 16, 3)).at[0, 0].set((colour - 0.5) / params.SH_C0),
      active=jnp.array([True]))
  out = render.render(g, jnp.asarray(c2w, jnp.float32), FOCAL, H, W, 0, BG, 8)
  proj, _, _ = _screen(g, c2w)
  assert bool(proj.valid[0]) and np.all(np.asarray(out['count']) == 1)  # In all tiles.
  ys, xs = np.mgrid[:H, :W] + 0.5
  d = np.stack([xs, ys], -1) - np.asarray(proj.means2d[0])
  inv = np.linalg.inv(np.asarray(proj.cov2d[0], np.float64))
  alpha = 1. / (1. + np.exp(-1.4)) * np.exp(-0.5 * np.einsum('hwi,ij,hwj->hw', d, inv, d))
  alpha = np.where(alpha >= 1. / 255., np.minimum(alpha, 0.99), 0.)
  assert (alpha == 0).any() and alpha.max() > 0.5
  np.testing.assert_allclose(out['rgb'], alpha[..., None] * colour +
                             (1. - alpha[..., None]) * BG, atol=1e-5)
  np.testing.assert_allclose(out['acc'], alpha, atol=1e-5)
  np.testing.assert_allclose(out['depth'], alpha * float(proj.depths[0]), atol=1e-5)
  assert float(out['cap_bound']) == 0.


def test_early_termination_drops_the_saturating_gaussian():
  """Three layers of alpha ~0.98: the third would push T below 1e-4 (to 8e-6), so it is
  not composited and only two are."""
  means2d = jnp.tile(jnp.array([[16., 12.]]), (3, 1))
  conics = jnp.tile(jnp.array([[1e-4, 0., 1e-4]]), (3, 1))
  colours = jnp.eye(3)
  opac = jnp.full((3,), 0.98)
  depths = jnp.array([1., 2., 3.])
  ids = jnp.tile(jnp.array([[0, 1, 2]]), (4, 1))
  rgb, _, acc = rasterize.rasterize(ids, means2d, conics, colours, opac, depths, H, W,
                                    jnp.zeros(3))
  a = 0.98 * np.exp(-0.5 * 1e-4 * 0.5)  # pixel (16.5, 12.5) -> d = (0.5, 0.5)
  np.testing.assert_allclose(rgb[12, 16], [a, (1 - a) * a, 0.], rtol=1e-5)
  np.testing.assert_allclose(acc[12, 16], 1 - (1 - a)**2, rtol=1e-5)
  # Padding ids (>= N) are skipped wherever they stand in a list, even mid-list.
  gappy = jnp.tile(jnp.array([[0, 3, 3, 1, 2]]), (4, 1))
  rgb2, _, acc2 = rasterize.rasterize(gappy, means2d, conics, colours, opac, depths, H, W,
                                      jnp.zeros(3), chunk=2)
  np.testing.assert_allclose(rgb2, rgb, atol=1e-7)
  np.testing.assert_allclose(acc2, acc, atol=1e-7)


# ----------------------------------------------------------------------------- projection


def test_projection_matches_monte_carlo_and_nerf_rays():
  rng = np.random.default_rng(2)
  size, focal = 200, 200.
  c2w = _pose(eye=(1., 0.5, 4.5), target=(0.2, 0., 0.))
  mean = np.array([0.25, 0.1, 0.05])
  scales = np.array([0.25, 0.08, 0.15])
  quat = np.array([0.8, -0.3, 0.4, 0.2])
  proj = projection.project(jnp.asarray(mean[None], jnp.float32),
                            jnp.log(jnp.asarray(scales[None], jnp.float32)),
                            jnp.asarray(quat[None], jnp.float32), jnp.array([True]),
                            jnp.asarray(c2w, jnp.float32), focal, size, size)
  assert bool(proj.valid[0])
  # Monte Carlo: perspective-project 3D samples with the OpenGL pinhole directly.
  rot = np.asarray(params.quat_to_rotmat(jnp.asarray(quat)), np.float64)
  x = mean + (rng.normal(size=(400000, 3)) * scales) @ rot.T
  cam = (x - c2w[:, 3]) @ c2w[:, :3]
  uv = np.stack([focal * cam[:, 0] / -cam[:, 2] + size / 2,
                 focal * cam[:, 1] / cam[:, 2] + size / 2], -1)
  emp = np.cov(uv.T)
  cov2d = np.asarray(proj.cov2d[0]) - projection.DILATION * np.eye(2)
  assert 5. < np.sqrt(np.linalg.eigvalsh(cov2d)).max() < 20.  # Well inside the image.
  np.testing.assert_allclose(cov2d, emp, atol=0.02 * np.abs(emp).max())
  np.testing.assert_allclose(proj.means2d[0], uv.mean(0), atol=0.5)
  inv = np.linalg.inv(np.asarray(proj.cov2d[0]))
  np.testing.assert_allclose(proj.conics[0], [inv[0, 0], inv[0, 1], inv[1, 1]],
                             rtol=1e-4)
  lam = np.linalg.eigvalsh(np.asarray(proj.cov2d[0])).max()
  assert float(proj.radius[0]) == np.ceil(3. * np.sqrt(lam))
  # The NeRF ray through the projected position hits the mean at t = depth.
  u, v = np.asarray(proj.means2d[0], np.float64)
  rays = cameras.pixel_rays(c2w, u - 0.5, v - 0.5, focal, size, size, False, 0., 1.)
  np.testing.assert_allclose(np.asarray(rays.origins) + float(proj.depths[0]) *
                             np.asarray(rays.directions), mean, atol=1e-4)


def test_projection_jacobian_is_clamped_outside_the_fov():
  """A Gaussian far off-screen but overlapping it gets the 1.3 tan(fov/2) Jacobian."""
  c2w = np.eye(4)[:3]
  c2w[2, 3] = 5.
  mean = jnp.array([[6., 0., 0.]])  # x/z = 1.2 > 1.3 * 16 / 30 = 0.693
  proj = projection.project(mean, jnp.full((1, 3), 1.), jnp.array([[1., 0., 0., 0.]]),
                            jnp.array([True]), jnp.asarray(c2w, jnp.float32), FOCAL, H, W)
  lim = 1.3 * 0.5 * W / FOCAL
  jac = FOCAL / 5. * np.array([[1., 0., -lim], [0., 1., 0.]])
  want = jac @ (np.e**2 * np.eye(3)) @ jac.T + 0.3 * np.eye(2)
  np.testing.assert_allclose(proj.cov2d[0], want, rtol=1e-5)
  assert bool(proj.valid[0])


# ----------------------------------------------------------------------------- gradients


def test_gradients_match_central_differences_in_float64():
  with jax.enable_x64(True):
    rng = np.random.default_rng(3)
    n = 3
    sh = 0.05 * rng.normal(size=(n, 16, 3))
    sh[:, 0] = rng.uniform(-0.5, 0.5, (n, 3))
    fields = dict(
        means=np.array([[0.05, 0.02, 0.1], [-0.1, 0.05, -0.2], [0.08, -0.06, 0.3]]),
        log_scales=np.log(rng.uniform(0.3, 0.5, (n, 3))),
        quats=rng.normal(size=(n, 4)), opacity_logits=rng.uniform(-0.5, 0.5, n), sh=sh)
    c2w = jnp.asarray(_pose(eye=(0.2, 0.1, 3.)))
    wts = [jnp.asarray(rng.normal(size=s)) for s in [(H, W, 3), (H, W), (H, W)]]

    def loss(f):
      g = params.Gaussians(active=jnp.ones(n, bool), **f)
      out = render.render(g, c2w, FOCAL, H, W, 3, jnp.asarray(BG, jnp.float64), 8)
      return (jnp.sum(out['rgb'] * wts[0]) + 0.1 * jnp.sum(out['depth'] * wts[1]) +
              jnp.sum(out['acc'] * wts[2]))

    f0 = {k: jnp.asarray(v, jnp.float64) for k, v in fields.items()}
    out = render.render(params.Gaussians(active=jnp.ones(n, bool), **f0), c2w, FOCAL, H,
                        W, 3, jnp.asarray(BG, jnp.float64), 8)
    assert out['rgb'].dtype == jnp.float64
    assert np.all(np.asarray(out['count']) == n)  # Every Gaussian covers every tile.
    grads = jax.grad(loss)(f0)
    # Central differences of every element of every field: all 2 x 177 perturbed copies
    # of the scene in one vmapped call.
    eps = 1e-6
    sizes = [f0[k].size for k in f0]
    total = sum(sizes)
    steps = np.split(eps * np.eye(total), np.cumsum(sizes)[:-1], axis=1)
    batch = {k: jnp.asarray(np.concatenate([np.asarray(v) + d.reshape((total,) + v.shape),
                                            np.asarray(v) - d.reshape((total,) + v.shape)]))
             for (k, v), d in zip(f0.items(), steps)}
    losses = np.asarray(jax.jit(jax.vmap(loss))(batch))
    fd_all = (losses[:total] - losses[total:]) / (2. * eps)
    for name, fd in zip(f0, np.split(fd_all, np.cumsum(sizes)[:-1])):
      g = np.asarray(grads[name]).ravel()
      assert np.abs(g).max() > 1e-3, name
      np.testing.assert_allclose(g, fd, atol=1e-6 * np.abs(fd).max(), err_msg=name)


def _float_fields(g):
  """The differentiable fields of Gaussians, as a dict."""
  return {k: getattr(g, k) for k in ('means', 'log_scales', 'quats', 'opacity_logits',
                                     'sh')}


@functools.partial(jax.jit, static_argnames=('cap',))
def _loss_and_grads_jit(g, c2w, near, cap):
  def loss(means, log_scales, quats, logits, sh):
    out = render.render(g.replace(means=means, log_scales=log_scales, quats=quats,
                                  opacity_logits=logits, sh=sh),
                        c2w, FOCAL, H, W, 3, BG, cap, near)
    return jnp.sum(out['rgb'] ** 2) + jnp.sum(out['depth']) + jnp.sum(out['acc']), out
  (_, out), grads = jax.value_and_grad(loss, argnums=range(5), has_aux=True)(
      g.means, g.log_scales, g.quats, g.opacity_logits, g.sh)
  return out, grads


def _loss_and_grads(g, c2w, cap=16, near=0.01):
  """Render dict and gradients (means, log_scales, quats, logits, sh) of a scalar loss."""
  return _loss_and_grads_jit(g, jnp.asarray(c2w, jnp.float32), near, cap)


def test_inactive_slots_change_nothing_and_get_zero_gradients():
  n, extra = 6, 5
  g = _scene(4, n + extra, capacity=n + extra)
  # The same active Gaussians; the inactive slots hold visible Gaussians in `clean`...
  clean = g.replace(active=jnp.arange(n + extra) < n)
  nan = jnp.full((extra,), jnp.nan)
  garbage = clean.replace(  # ...and NaN, inf and huge values in `garbage`.
      means=g.means.at[n:, 0].set(nan).at[n:, 1].set(0.),
      log_scales=g.log_scales.at[n:].set(50.), quats=g.quats.at[n:].set(jnp.inf),
      opacity_logits=g.opacity_logits.at[n:].set(jnp.nan), sh=g.sh.at[n:].set(1e30))
  out_all, _ = _loss_and_grads(g, _pose(), cap=16)
  out_c, grads_c = _loss_and_grads(clean, _pose(), cap=16)
  out_g, grads_g = _loss_and_grads(garbage, _pose(), cap=16)
  assert np.abs(np.asarray(out_all['rgb'] - out_c['rgb'])).max() > 0.05
  assert float(out_c['acc'].max()) > 0.5
  for k in ('rgb', 'depth', 'acc'):
    np.testing.assert_array_equal(out_g[k], out_c[k])
  for a, b in zip(grads_g, grads_c):  # (Equal on CPU; GPU scatter-adds vary in order.)
    np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7 * np.abs(np.asarray(b)).max())
    assert np.all(np.asarray(a[n:]) == 0.)
    assert np.abs(np.asarray(a[:n])).max() > 0.
  # A slot with a NaN field is not rendered even when marked active.
  out_n, grads_n = _loss_and_grads(garbage.replace(active=jnp.ones(n + extra, bool)),
                                   _pose(), cap=16)
  np.testing.assert_array_equal(out_n['rgb'], out_c['rgb'])
  assert all(np.all(np.isfinite(np.asarray(x))) for x in grads_n)


def test_extreme_gaussians_stay_finite():
  c2w = np.eye(4)[:3]  # Camera at the origin looking down -z.
  near = 0.5
  means = np.array([
      [0., 0., -3.],  # log_scale -30 (a point)
      [0.2, 0., -3.],  # log_scale +10 (fills the view)
      [0., 0., 2.],  # behind the camera
      [0.1, 0.1, -near],  # exactly on the near plane
      [0., 0., 0.],  # at the camera centre
      [0.3, 0.2, -2.],  # opacity logit +30
      [-0.3, 0.2, -2.],  # opacity logit -30
      [0.1, -0.2, -2.5],  # zero quaternion
      [-0.2, -0.1, -2.],  # unnormalised quaternion
      [0.1, 0.1, -0.5000001],  # just beyond the near plane
      [50., 0., -1.],  # far off screen
  ], np.float32)
  n = len(means)
  log_scales = np.full((n, 3), -2., np.float32)
  log_scales[0], log_scales[1] = -30., 10.
  logits = np.zeros(n, np.float32)
  logits[5], logits[6] = 30., -30.
  quats = np.tile(np.float32([1., 0., 0., 0.]), (n, 1))
  quats[7] = 0.
  quats[8] = [3e3, 1e3, -2e3, 5e2]
  g = params.Gaussians(jnp.asarray(means), jnp.asarray(log_scales), jnp.asarray(quats),
                       jnp.asarray(logits), jnp.full((n, 16, 3), 0.1, jnp.float32),
                       jnp.ones(n, bool))
  out, grads = _loss_and_grads(g, c2w, cap=16, near=near)
  for k in ('rgb', 'depth', 'acc'):
    assert np.all(np.isfinite(np.asarray(out[k]))), k
  for x in grads:
    assert np.all(np.isfinite(np.asarray(x)))
  valid = np.asarray(out['valid'])
  np.testing.assert_array_equal(valid, [1, 1, 0, 0, 0, 1, 1, 1, 1, 1, 0])
  assert float(out['acc'].min()) > 0.1  # The huge Gaussian covers everything.
  # Culled Gaussians get zero gradients, the point-like and huge ones do not.
  assert np.all(np.asarray(grads[0])[[2, 3, 4, 10]] == 0.)
  assert np.all(np.abs(np.asarray(grads[3])[[0, 1]]) > 0.)


def test_quaternion_norm_does_not_matter_and_zero_is_identity():
  g = _scene(5, 20)
  c2w = jnp.asarray(_pose(), jnp.float32)
  unit = g.quats / jnp.linalg.norm(g.quats, axis=-1, keepdims=True)
  img = lambda g: render.render(g, c2w, FOCAL, H, W, 3, BG, 32)['rgb']
  ref = img(g.replace(quats=unit))
  np.testing.assert_allclose(img(g.replace(quats=unit * 1e3)), ref, atol=1e-5)
  np.testing.assert_allclose(img(g.replace(quats=unit * 1e-3)), ref, atol=1e-5)
  ident = jnp.tile(jnp.array([[1., 0., 0., 0.]]), (20, 1))
  np.testing.assert_allclose(img(g.replace(quats=jnp.zeros((20, 4)))),
                             img(g.replace(quats=ident)), atol=1e-6)
  assert np.abs(np.asarray(img(g.replace(quats=ident)) - ref)).max() > 1e-3
  np.testing.assert_allclose(params.quat_to_rotmat(jnp.zeros(4)), np.eye(3))
  r = np.asarray(params.quat_to_rotmat(g.quats))
  np.testing.assert_allclose(r @ np.swapaxes(r, -1, -2), np.tile(np.eye(3), (20, 1, 1)),
                             atol=1e-5)
  np.testing.assert_allclose(np.linalg.det(r), 1., atol=1e-5)
  jac = jax.grad(lambda q: jnp.sum(params.quat_to_rotmat(q)))(jnp.zeros(4))
  assert np.all(np.isfinite(np.asarray(jac)))


def test_hundred_thousand_gaussians_in_one_tile():
  n = 100000
  rng = np.random.default_rng(6)
  g = params.random_init(jax.random.PRNGKey(0), n, [-0.5, -0.5, -0.5], [0.5, 0.5, 0.5])
  g = g.replace(sh=g.sh.at[:, 0].set(jnp.asarray(rng.normal(size=(n, 3)), jnp.float32)))
  c2w = jnp.asarray(_pose(eye=(0., 0., 3.)), jnp.float32)

  def loss(f):
    out = render.render(params.Gaussians(active=g.active, **f), c2w, 20., 16, 16, 0, BG, 8)
    return jnp.sum(out['rgb']) + jnp.sum(out['acc']), out

  (_, out), grads = jax.value_and_grad(loss, has_aux=True)(_float_fields(g))
  assert float(out['cap_bound']) == 1.
  assert int(out['count'][0]) > 0.9 * n
  for k in ('rgb', 'depth', 'acc'):
    assert np.all(np.isfinite(np.asarray(out[k]))), k
  assert float(out['acc'].max()) > 0.05
  for k in ('means', 'log_scales', 'quats', 'opacity_logits', 'sh'):
    x = np.asarray(grads[k])
    assert np.all(np.isfinite(x)), k
  # Only the 8 nearest valid Gaussians are blended and receive gradient.
  depth = np.where(np.asarray(out['valid']), 3. - np.asarray(g.means[:, 2]), np.inf)
  touched = np.flatnonzero(np.asarray(grads['opacity_logits']))
  assert 0 < len(touched) and set(touched) <= set(np.argsort(depth)[:8])


def test_random_init():
  g = params.random_init(jax.random.PRNGKey(1), 100, [-1., 0., 2.], [1., 2., 4.],
                         capacity=128)
  assert g.means.shape == (128, 3) and g.sh.shape == (128, 16, 3)
  assert int(g.active.sum()) == 100 and not bool(g.active[100:].any())
  m = np.asarray(g.means)
  assert np.all(m >= [-1., 0., 2.]) and np.all(m <= [1., 2., 4.])
  np.testing.assert_allclose(np.exp(g.log_scales), 2. / 100**(1. / 3.), rtol=1e-5)
  np.testing.assert_allclose(jax.nn.sigmoid(g.opacity_logits), 0.1, rtol=1e-5)
  np.testing.assert_allclose(params.eval_sh(3, g.sh, jnp.ones((128, 3))), 0.5)
  cov = np.asarray(params.covariance_3d(g.log_scales, g.quats))
  np.testing.assert_allclose(cov[0], np.eye(3) * np.exp(2. * float(g.log_scales[0, 0])),
                             rtol=1e-5)



def test_knn_scales_match_brute_force_and_clamp_duplicates():
  rng = np.random.default_rng(7)
  pts = rng.uniform(-1., 1., (300, 3)).astype(np.float32)
  pts[5] = pts[6] = pts[7] = pts[8]  # Four copies: their 3 nearest are at distance 0.
  d2 = np.sum((pts[:, None].astype(np.float64) - pts[None]) ** 2, -1)
  np.fill_diagonal(d2, np.inf)
  want = np.sqrt(np.maximum(np.sort(d2, 1)[:, :3].mean(1), 1e-7))
  got = np.asarray(params.knn_scales(pts, block=128))  # Blocks that do not divide 300.
  np.testing.assert_allclose(got, want, rtol=1e-4)
  np.testing.assert_allclose(got[5:9], np.sqrt(1e-7), rtol=1e-5)
  np.testing.assert_allclose(params.knn_scales(pts[:2]), [np.sqrt(d2[0, 1])] * 2, rtol=1e-5)
  with pytest.raises(ValueError, match='at least 2 points'):
    params.knn_scales(pts[:1])
  g = params.random_init(jax.random.PRNGKey(1), 100, [-1., 0., 2.], [1., 2., 4.],
                         capacity=128, knn=True)
  np.testing.assert_allclose(np.exp(g.log_scales[:100, 0]),
                             params.knn_scales(g.means[:100]), rtol=1e-5)
  assert np.all(np.isfinite(np.asarray(g.log_scales)))


# ----------------------------------------------------------------------------- SH


def test_sh_degree_zero_is_the_dc_colour():
  rng = np.random.default_rng(7)
  sh = jnp.asarray(rng.normal(size=(50, 16, 3)), jnp.float32)
  dirs = jnp.asarray(rng.normal(size=(50, 3)), jnp.float32)
  want = np.maximum(params.SH_C0 * np.asarray(sh[:, 0]) + 0.5, 0.)
  np.testing.assert_allclose(params.eval_sh(0, sh, dirs), want, rtol=1e-6)
  np.testing.assert_allclose(params.eval_sh(0, sh, -dirs), want, rtol=1e-6)
  dc_only = sh.at[:, 1:].set(0.)
  np.testing.assert_allclose(params.eval_sh(3, dc_only, dirs), want, rtol=1e-6)
  assert np.abs(np.asarray(params.eval_sh(3, sh, dirs)) - want).max() > 0.1
  # Direction length does not matter.
  np.testing.assert_allclose(params.eval_sh(3, sh, 7. * dirs), params.eval_sh(3, sh, dirs),
                             rtol=1e-5, atol=1e-6)


def test_sh_basis_is_orthonormal_on_the_sphere():
  # Gauss-Legendre in cos(theta) x uniform phi integrates these polynomials exactly.
  mu, w_mu = np.polynomial.legendre.leggauss(8)
  phi = np.arange(16) * 2. * np.pi / 16
  st = np.sqrt(1. - mu**2)
  dirs = np.stack([st[:, None] * np.cos(phi), st[:, None] * np.sin(phi),
                   np.broadcast_to(mu[:, None], (8, 16))], -1).reshape(-1, 3)
  w = (w_mu[:, None] * np.full(16, 2. * np.pi / 16)).ravel()
  basis = np.asarray(params.sh_basis(3, jnp.asarray(dirs, jnp.float32)), np.float64)
  gram = np.einsum('n,na,nb->ab', w, basis, basis)
  np.testing.assert_allclose(gram, np.eye(16), atol=2e-6)
  # Closed forms: Y_00 = 1 / (2 sqrt(pi)), Y_10 ~ sqrt(3 / (4 pi)) z, and the 3DGS signs.
  np.testing.assert_allclose(basis[:, 0], 0.5 / np.sqrt(np.pi), rtol=1e-6)
  np.testing.assert_allclose(basis[:, 2], np.sqrt(3. / (4. * np.pi)) * dirs[:, 2],
                             atol=1e-6)
  np.testing.assert_allclose(basis[:, 3], -np.sqrt(3. / (4. * np.pi)) * dirs[:, 0],
                             atol=1e-6)
  np.testing.assert_allclose(basis[:, 6], np.sqrt(5. / (16. * np.pi)) *
                             (3. * dirs[:, 2]**2 - 1.), atol=1e-6)
  # Degree l only: lower-degree bases are prefixes.
  np.testing.assert_allclose(params.sh_basis(1, jnp.asarray(dirs, jnp.float32)),
                             basis[:, :4], atol=1e-7)
