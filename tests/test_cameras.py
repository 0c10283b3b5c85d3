import jax.numpy as jnp
import numpy as np

from renerf_jax import cameras


def _identity():
  return np.concatenate([np.eye(3), np.zeros((3, 1))], 1).astype(np.float32)


def test_pixel_directions_closed_form():
  h, w, f = 6, 8, 5.
  d = np.asarray(cameras.pixel_directions(jnp.array(3.), jnp.array(1.), f, h, w))
  np.testing.assert_allclose(d, [(3.5 - 4.) / f, -(1.5 - 3.) / f, -1.], rtol=1e-6)


def test_image_rays_world_space():
  h, w, f = 6, 8, 5.
  c2w = _identity()
  c2w[:, 3] = [1., 2., 3.]
  rays = cameras.image_rays(c2w, h, w, f, use_ndc=False, near=2., far=6.)
  assert rays.origins.shape == (h, w, 3)
  np.testing.assert_allclose(rays.origins, np.broadcast_to([1., 2., 3.], (h, w, 3)))
  ys, xs = np.mgrid[:h, :w]
  expected = np.stack([(xs + .5 - w / 2) / f, -(ys + .5 - h / 2) / f, -np.ones((h, w))], -1)
  np.testing.assert_allclose(rays.directions, expected, rtol=1e-6, atol=1e-7)
  np.testing.assert_allclose(np.linalg.norm(rays.viewdirs, axis=-1), 1., rtol=1e-6)
  # Neighbouring directions differ by 1/f: radius = (1/f) * 2/sqrt(12).
  np.testing.assert_allclose(rays.radii, 2. / np.sqrt(12.) / f, rtol=1e-5)
  np.testing.assert_allclose(rays.near, 2.)
  np.testing.assert_allclose(rays.far, 6.)


def _project_ndc(p, focal, h, w, near=1.):
  return np.array([-2. * focal / w * p[0] / p[2], -2. * focal / h * p[1] / p[2],
                   1. + 2. * near / p[2]])


def test_ndc_matches_projection_of_world_points():
  h, w, f = 40., 60., 50.
  origin = np.array([0.1, -0.2, 0.3])
  direction = np.array([0.2, 0.1, -1.])
  o_ndc, d_ndc = cameras.convert_to_ndc(jnp.array(origin), jnp.array(direction), f, h, w)
  o_ndc, d_ndc = np.asarray(o_ndc), np.asarray(d_ndc)
  # The NDC origin is the projection of the ray's point on the near plane z = -1.
  t_near = (-1. - origin[2]) / direction[2]
  np.testing.assert_allclose(o_ndc, _project_ndc(origin + t_near * direction, f, h, w),
                             rtol=1e-5)
  for depth in (1.5, 3., 10., 1000.):
    p = origin + (-depth - origin[2]) / direction[2] * direction
    q = _project_ndc(p, f, h, w)
    t = (q[2] - o_ndc[2]) / d_ndc[2]
    assert 0. <= t <= 1.
    np.testing.assert_allclose(o_ndc + t * d_ndc, q, rtol=1e-4, atol=1e-5)
  # Infinity maps to t = 1 (NDC z = 1).
  np.testing.assert_allclose(o_ndc[2] + d_ndc[2], 1., atol=1e-6)


def test_ndc_rays_nearly_parallel_to_image_plane_stay_finite():
  o = jnp.zeros((3, 3))
  d = jnp.array([[1., 0., -1e-12], [1., 0., 0.], [0., 1., 1e-9]])
  o_ndc, d_ndc = cameras.convert_to_ndc(o, d, 10., 20., 20.)
  assert np.all(np.isfinite(o_ndc)) and np.all(np.isfinite(d_ndc))


def test_ndc_image_rays_cover_unit_interval():
  rays = cameras.image_rays(_identity(), 4, 6, 5., use_ndc=True, near=0., far=1.)
  # Central NDC rays of an identity camera start at z = -1 and end at z = 1.
  z0 = np.asarray(rays.origins[..., 2])
  z1 = np.asarray(rays.origins[..., 2] + rays.directions[..., 2])
  np.testing.assert_allclose(z0, -1., atol=1e-6)
  np.testing.assert_allclose(z1, 1., atol=1e-6)
  assert np.all(np.asarray(rays.radii) > 0)


def test_llff_axes_and_recentering():
  rng = np.random.default_rng(0)
  poses = np.tile(np.eye(3, 4)[None], (5, 1, 1))
  poses[:, :, 3] = rng.normal(size=(5, 3))
  # LLFF [down, right, back] -> OpenGL [right, up, back].
  llff = np.stack([-poses[:, :, 1], poses[:, :, 0], poses[:, :, 2], poses[:, :, 3]], -1)
  np.testing.assert_allclose(cameras.llff_to_opengl(llff), poses)
  bounds = rng.uniform(2., 10., size=(5, 2))
  out, bds, scale = cameras.process_llff_poses(poses, bounds)
  np.testing.assert_allclose(scale, 1. / (bounds.min() * .75))
  np.testing.assert_allclose(bds.min(), 1. / .75)
  avg = cameras.average_pose(out)
  np.testing.assert_allclose(avg, np.eye(3, 4), atol=1e-9)
  np.testing.assert_allclose(np.linalg.det(out[:, :3, :3]), 1., atol=1e-9)
