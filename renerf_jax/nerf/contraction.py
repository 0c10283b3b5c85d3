"""Unbounded scenes: mip-NeRF 360's scene contraction and disparity-spaced ray distances.

contract(x) maps all of R^3 into a ball (or cube) of radius 2: the identity inside the
unit ball, (2 - 1 / |x|) x / |x| outside (Barron et al. 2022, eq. 10). `order` picks
the norm: 2 (mip-NeRF 360) or inf (nerfacto's cube, which fills a grid's corners).
contract_gaussians carries mip-NeRF's Gaussians through it by linearisation (eq. 8:
mean f(mu), covariance J Sigma J^T with J the Jacobian at the mean).

Ray distances for unbounded scenes are spaced in disparity: s in [0, 1] maps to t in
[near, far] by s = (g(t) - g(near)) / (g(far) - g(near)) with g(t) = 1 / t (eq. 11), so
equal steps in s are equal steps in 1 / t and far content gets few samples. The
piecewise variant (mip-NeRF 360's and nerfacto's) spends half of s linearly on [near, 1]
and the other half in disparity on [1, far].
"""
import jax
import jax.numpy as jnp

_EPS = 1e-12
# Where contract() puts all of space (either order): the box of a grid or deformation
# field over contracted space.
CONTRACTED_BOX = ((-2., -2., -2.), (2., 2., 2.))


def _norm(x, order):
  if order == 2:
    return jnp.sqrt(jnp.maximum(jnp.sum(x * x, axis=-1, keepdims=True), _EPS))
  if order == 'inf':
    return jnp.maximum(jnp.max(jnp.abs(x), axis=-1, keepdims=True), _EPS)
  raise ValueError(f'contraction order {order!r} (2 or inf)')


def contract(x, order=2):
  """Scene contraction.

  Args:
    x: [..., 3] points.
    order: 2 (a ball of radius 2) or 'inf' (a cube of half-size 2).

  Returns:
    [..., 3] contracted points: x where |x| <= 1, (2 - 1 / |x|) x / |x| beyond.
  """
  r = _norm(x, order)
  # Evaluated where it is used only, so gradients stay finite inside the unit ball.
  r_out = jnp.maximum(r, 1.)
  return jnp.where(r <= 1., x, (2. - 1. / r_out) * x / r_out)


def contract_jacobian_l2(x):
  """The closed-form Jacobian of contract(., 2): I inside the unit ball, and outside
  (1 / r^2) xh xh^T + ((2 - 1 / r) / r) (I - xh xh^T), xh = x / r.

  Args:
    x: [..., 3]. Returns: [..., 3, 3].
  """
  r = _norm(x, 2)[..., None]
  xh = x[..., :, None] / r
  outer = xh * jnp.swapaxes(xh, -1, -2)
  eye = jnp.eye(3, dtype=x.dtype)
  outside = outer / r**2 + (2. - 1. / r) / r * (eye - outer)
  return jnp.where(r <= 1., jnp.broadcast_to(eye, outside.shape), outside)


def contract_gaussians(means, covs, order=2):
  """Gaussians through the contraction, linearised at their means.

  Args:
    means: [..., 3]. covs: [..., 3, 3] full covariances. order: as contract.

  Returns:
    (contracted means [..., 3], J covs J^T [..., 3, 3]).
  """
  flat = means.reshape(-1, 3)
  jac = jax.vmap(jax.jacfwd(lambda p: contract(p, order)))(flat).reshape(
      means.shape + (3,))
  return contract(means, order), jac @ covs @ jnp.swapaxes(jac, -1, -2)


def contract_samples(means, covs, kind):
  """Sample means and diagonal covariances of a renderer through the contraction.

  Args:
    means: [..., 3]. covs: [..., 3] diagonal covariances, or None (density-only
      samplers). kind: Config.contraction, 'l2' or 'inf'.

  Returns:
    (contracted means, diagonal of J diag(covs) J^T, i.e. (J * J) @ covs; None if
    covs is None).
  """
  order = {'l2': 2, 'inf': 'inf'}[kind]
  if covs is None:
    return contract(means, order), None
  flat = means.reshape(-1, 3)
  jac = jax.vmap(jax.jacfwd(lambda p: contract(p, order)))(flat).reshape(
      means.shape + (3,))
  return contract(means, order), jnp.einsum('...ij,...j->...i', jac * jac, covs)


def s_to_t(s, near, far, piecewise=False):
  """Ray distance t of normalised distance s in [0, 1], spaced in disparity.

  Args:
    s: [...] in [0, 1]. near, far: 0 < near < far (piecewise: near < 1 < far).
    piecewise: s in [0, 0.5] linear on [near, 1], s in [0.5, 1] in disparity on [1, far].

  Returns:
    [...] t, increasing in s, t(0) = near, t(1) = far.
  """
  if not piecewise:
    return 1. / (s / far + (1. - s) / near)
  lin = near + 2. * s * (1. - near)
  s2 = 2. * s - 1.
  disp = 1. / (s2 / far + (1. - s2))
  return jnp.where(s < 0.5, lin, disp)


def t_to_s(t, near, far, piecewise=False):
  """The inverse of s_to_t."""
  if not piecewise:
    return (1. / t - 1. / near) / (1. / far - 1. / near)
  lin = (t - near) / (1. - near) / 2.
  disp = 0.5 + 0.5 * (1. / t - 1.) / (1. / far - 1.)
  return jnp.where(t < 1., lin, disp)
