"""Dense reference of the Laplace diagonal (small grids and few rays only).

The reference for renerf_jax.uncertainty.laplace.hessian_diagonal. It differentiates the whole
renderer w.r.t. the flattened deformation grid theta [V * 3] in forward mode only:

* the Gauss-Newton objective g(theta) = 1/R sum ||rgb(theta) - rgb(0)||^2 has, at theta =
  0 (zero residual), the Hessian 2/R J^T J exactly, so its diagonal is 2/R times the
  column sums of J^2, with J = jax.jacfwd(rgb) the dense [outputs, V * 3] Jacobian;
* the true loss f(theta) = 1/R sum ||rgb(theta) - gt||^2 has the Hessian diagonal
  d^2/dt^2 f(t e_k) at t = 0, a forward-over-forward directional second derivative per
  coordinate k (one jvp of a jvp).

Neither is jax.hessian (forward-over-reverse: jacfwd of jacrev): the transposed,
81-way-batched renderer that builds crashed XLA's CPU code on some machines (issue 38).
`gn_hessian_diagonal` and `true_hessian_diagonal` are checked against jax.hessian on a
small closed-form function in tests/test_laplace.py.
"""
import dataclasses
import functools

import jax
import jax.numpy as jnp

from renerf_jax.nerf.model import colour_levels, render_rays
from renerf_jax.uncertainty.deformation import grid_size, make_warp


def gn_hessian_diagonal(fn, theta0):
  """diag of the Hessian of 1/R sum ||fn(theta) - fn(theta0)||^2 at theta0 (= 2/R J^T J).

  Args:
    fn: theta [P] -> outputs [levels, R, ...]; R (the loss's normaliser) is axis 1.
    theta0: [P] the point.

  Returns:
    [P] the diagonal, from the dense forward-mode Jacobian.
  """
  jac = jax.jacfwd(fn)(theta0)  # [levels, R, ..., P]
  num = jac.shape[1]
  return 2. / num * jnp.sum(jac.reshape(-1, theta0.shape[0])**2, axis=0)


def true_hessian_diagonal(fn, theta0, target):
  """diag of the Hessian of 1/R sum ||fn(theta) - target||^2 at theta0.

  Args:
    fn: theta [P] -> outputs [levels, R, ...]; R (the loss's normaliser) is axis 1.
    theta0: [P] the point. target: outputs' shape.

  Returns:
    [P] d^2/dt^2 f(theta0 + t e_k) at t = 0 for every k, forward over forward.
  """
  def loss(theta):
    out = fn(theta)
    return jnp.sum((out - target)**2) / out.shape[1]

  def second(e):
    first = lambda th: jax.jvp(loss, (th,), (e,))[1]
    return jax.jvp(first, (theta0,), (e,))[1]
  return jax.lax.map(second, jnp.eye(theta0.shape[0], dtype=theta0.dtype))


def _level_rgbs(config, params, rays, lo, hi, theta):
  """The rgb of every level that renders colour, with a deformation applied to those
  levels' samples (the proposal level of Config.sampler = 'proposal' is not deformed).

  Args:
    config: Config. params: field parameters. rays: flat Rays [R].
    lo, hi: [3] box. theta: [V * 3] flattened vertex offsets.

  Returns:
    [levels, R, 3] rgb.
  """
  warp = make_warp(theta.reshape(-1, 3), lo, hi)
  first = config.num_levels - colour_levels(config)
  offsets = lambda level, means: warp(level, means) if level >= first else 0.
  levels = render_rays(config, params, rays, jax.random.PRNGKey(0), train=False,
                       offsets=offsets)[first:]
  return jnp.stack([lv['rgb'] for lv in levels])


@functools.partial(jax.jit, static_argnums=(0, 1, 2))
def _dense_diagonal(config, log2_res, true, params, rays, lo, hi, target):
  """The GN (true=False) or true (true=True) Hessian diagonal at theta = 0.

  Args:
    config: static Config. log2_res: static L. true: static bool.
    params: field parameters. rays: flat Rays [R]. lo, hi: [3] box.
    target: [levels, R, 3] colours (unused for GN: its target is rgb(0)).

  Returns:
    [V, 3] Hessian diagonal.
  """
  fn = lambda th: _level_rgbs(config, params, rays, lo, hi, th)
  theta0 = jnp.zeros((grid_size(log2_res) * 3,), jnp.float32)
  diag = true_hessian_diagonal(fn, theta0, target) if true else gn_hessian_diagonal(
      fn, theta0)
  return diag.reshape(-1, 3)


def reference_hessian_diagonals(config, params, rays, lo, hi, log2_res: int,
                                gt_rgb=None):
  """Dense forward-mode reference (small grids and few rays only: O(V) passes).

  GN objective g(theta) = 1/R sum_levels sum_r ||rgb_r(theta) - sg(rgb_r(0))||^2, whose
  Hessian at 0 is exactly 2/R sum_levels J^T J; optionally the true squared-error loss
  f(theta) = 1/R sum_levels sum_r ||rgb_r(theta) - gt_r||^2 (Hessian = GN + residual-
  weighted second derivatives of the renderer). Neither includes the prior 2 lambda.
  The fine sample positions are held fixed w.r.t. the coarse weights, as in
  hessian_diagonal.

  Args:
    config: Config. params: field parameters. rays: flat Rays [R].
    lo, hi: box. log2_res: L.
    gt_rgb: optional ground-truth colours, [R, 3] (the same target for every level) or
      [levels, R, 3], for the true Hessian.

  Returns:
    dict with 'gn' [V, 3] and, if gt_rgb is given, 'true' [V, 3] Hessian diagonals.
  """
  cfg = dataclasses.replace(config, stop_level_grad=True)
  lo = jnp.asarray(lo, jnp.float32) * jnp.ones(3, jnp.float32)
  hi = jnp.asarray(hi, jnp.float32) * jnp.ones(3, jnp.float32)
  theta0 = jnp.zeros((grid_size(log2_res) * 3,), jnp.float32)
  rgb0 = jax.jit(_level_rgbs, static_argnums=0)(cfg, params, rays, lo, hi, theta0)
  out = {'gn': _dense_diagonal(cfg, log2_res, False, params, rays, lo, hi, rgb0)}
  if gt_rgb is not None:
    target = jnp.broadcast_to(jnp.asarray(gt_rgb, jnp.float32), rgb0.shape)
    out['true'] = _dense_diagonal(cfg, log2_res, True, params, rays, lo, hi, target)
  return out
