"""EWA projection of 3D Gaussians into a pinhole camera (the 3DGS forward projection).

Camera conventions are those of `renerf_jax.cameras`: `c2w` is a [3, 4] OpenGL
camera-to-world matrix (camera looks along -z, +y up, +x right), the principal point is
the image centre and pixel (i, j) (column, row) has its centre at (i + 0.5, j + 0.5).
A camera-space point (x, y, z) lands at

  u = focal * x / -z + width / 2,   v = focal * y / z + height / 2,

the same place `cameras.pixel_directions(u - 0.5, v - 0.5, ...)` shoots its ray through.
Internally the math uses the OpenCV-style frame (x right, y down, z forward) of the
reference 3DGS, where the depth is the positive z.

Culled Gaussians never produce NaN, forward or backward: the culling mask is computed on
a stop-gradient pass, and culled (or inactive, or non-finite) Gaussians are replaced by a
harmless canonical Gaussian before the differentiable pass (the double-where trick).
"""
import functools

import flax
import jax
import jax.numpy as jnp

from renerf_jax.gaussians import params

DILATION = 0.3  # Pixels^2 added to the diagonal of the 2D covariance (3DGS low-pass).
FOV_CLAMP = 1.3  # The Jacobian's x/z, y/z are clamped to 1.3 tan(half fov).


@flax.struct.dataclass
class Projection:
  """Screen-space Gaussians; every field has leading shape [N].

  Fields of culled Gaussians (valid == False) are zero.
  """
  means2d: jnp.ndarray  # [N, 2] (u, v) in pixels; pixel centres at integer + 0.5.
  depths: jnp.ndarray  # [N] distance along the viewing axis (-z in OpenGL camera space).
  cov2d: jnp.ndarray  # [N, 2, 2] screen covariance, dilation included.
  conics: jnp.ndarray  # [N, 3] (a, b, c) of the inverse covariance [[a, b], [b, c]].
  radius: jnp.ndarray  # [N] float, integer-valued: ceil(3 sqrt(largest eigenvalue)).
  valid: jnp.ndarray  # [N] bool.


def _splat(means, log_scales, quats, c2w, focal, height, width):
  """Unmasked projection of (assumed finite) Gaussians; returns a dict of [N, ...].

  Every matrix product in float32 (a GPU's default TF32 would move the means by ~1e-3
  relative: half a pixel at 500 px).
  """
  with jax.default_matmul_precision('highest'):
    return _splat_products(means, log_scales, quats, c2w, focal, height, width)


def _splat_products(means, log_scales, quats, c2w, focal, height, width):
  rot, centre = c2w[:3, :3], c2w[:3, 3]
  # World -> OpenCV camera: R^T, then flip y and z.
  w2c = rot.T * jnp.array([1., -1., -1.], rot.dtype)[:, None]
  t = (means - centre) @ w2c.T
  x, y, z = t[:, 0], t[:, 1], t[:, 2]
  u = focal * x / z + 0.5 * width
  v = focal * y / z + 0.5 * height
  lim_x = FOV_CLAMP * 0.5 * width / focal
  lim_y = FOV_CLAMP * 0.5 * height / focal
  tx = jnp.clip(x / z, -lim_x, lim_x)
  ty = jnp.clip(y / z, -lim_y, lim_y)
  zeros = jnp.zeros_like(z)
  jac = jnp.stack([
      jnp.stack([focal / z, zeros, -focal * tx / z], axis=-1),
      jnp.stack([zeros, focal / z, -focal * ty / z], axis=-1)], axis=-2)  # [N, 2, 3]
  cov_cam = w2c @ params.covariance_3d(log_scales, quats) @ w2c.T
  cov2d = jac @ cov_cam @ jnp.swapaxes(jac, -1, -2)
  cov2d = cov2d + DILATION * jnp.eye(2, dtype=cov2d.dtype)
  a, b, c = cov2d[:, 0, 0], cov2d[:, 0, 1], cov2d[:, 1, 1]
  # Inverse through the scaled matrix, so det = a c - b^2 never overflows.
  s = jnp.maximum(a, c)
  an, bn, cn = a / s, b / s, c / s
  det_n = an * cn - bn * bn
  sdet = s * det_n  # det / s
  conics = jnp.stack([cn / sdet, -bn / sdet, an / sdet], axis=-1)
  # Largest eigenvalue: mid + sqrt(max(0.1, mid^2 - det)), with mid^2 - det written as
  # ((a - c) / 2)^2 + b^2 (no cancellation, no overflow).
  lam = 0.5 * (a + c) + jnp.maximum(jnp.sqrt(0.1), jnp.hypot(0.5 * (a - c), b))
  radius = jnp.ceil(3. * jnp.sqrt(lam))
  means2d = jnp.stack([u, v], axis=-1)
  finite = (jnp.all(jnp.isfinite(means2d), -1) & jnp.all(jnp.isfinite(cov2d), (-1, -2)) &
            jnp.all(jnp.isfinite(conics), -1) & jnp.isfinite(radius) & jnp.isfinite(z))
  return dict(means2d=means2d, depths=z, cov2d=cov2d, conics=conics, radius=radius,
              good=finite & (det_n > 0.) & (s > 0.))


@functools.partial(jax.jit, static_argnames=('height', 'width'))
def project(means, log_scales, quats, active, c2w, focal, height, width, near=0.01):
  """Projects 3D Gaussians to screen-space 2D Gaussians (EWA, plain 3DGS).

  cov2d = J W Sigma W^T J^T + 0.3 I, with W the world-to-camera rotation and J the
  Jacobian of the perspective map at the (fov-clamped) mean. A Gaussian is valid when it
  is active, has finite parameters, lies strictly beyond the near plane (depth > near),
  all its outputs are finite, its radius is > 0 and its box centre +- radius overlaps the
  image.

  Args:
    means: [N, 3]. log_scales: [N, 3]. quats: [N, 4] (w, x, y, z), any norm.
    active: [N] bool.
    c2w: [3, 4] OpenGL camera-to-world.
    focal: focal length in pixels.
    height, width: static image size.
    near: near-plane depth.

  Returns:
    Projection.
  """
  ok = (active & jnp.all(jnp.isfinite(means), -1) & jnp.all(jnp.isfinite(log_scales), -1)
        & jnp.all(jnp.isfinite(quats), -1))
  # A harmless stand-in for culled Gaussians: unit, on the axis, beyond the near plane.
  safe_mean = c2w[:3, 3] - (2. * near + 1.) * c2w[:3, 2]

  def sanitise(mask):
    m = mask[:, None]
    return (jnp.where(m, means, safe_mean), jnp.where(m, log_scales, 0.),
            jnp.where(m, quats, jnp.array([1., 0., 0., 0.], quats.dtype)))

  probe = jax.lax.stop_gradient(
      _splat(*sanitise(ok), c2w, focal, height, width))
  ok = ok & probe['good'] & (probe['depths'] > near)
  out = _splat(*sanitise(ok), c2w, focal, height, width)
  radius = jax.lax.stop_gradient(out['radius'])
  u, v = jax.lax.stop_gradient(out['means2d']).T
  on_screen = ((u + radius > 0.) & (u - radius < width) &
               (v + radius > 0.) & (v - radius < height))
  valid = ok & out['good'] & (radius > 0.) & on_screen

  def mask(x):
    return jnp.where(valid.reshape((-1,) + (1,) * (x.ndim - 1)), x, 0.)

  return Projection(means2d=mask(out['means2d']), depths=mask(out['depths']),
                    cov2d=mask(out['cov2d']), conics=mask(out['conics']),
                    radius=mask(radius), valid=valid)
