"""Dense jax.hessian reference of the Laplace diagonal (small grids and few rays only).

The reference for renerf_jax.laplace.hessian_diagonal: it builds the full Hessian of the
loss w.r.t. the flattened deformation grid theta [V * 3] with jax.hessian (O(V) passes)
and takes its diagonal.
"""
import dataclasses
import functools

import jax
import jax.numpy as jnp

from renerf_jax.deformation import grid_size, make_warp
from renerf_jax.model import colour_levels, render_rays


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


@functools.partial(jax.jit, static_argnums=(0, 1))
def _dense_hessian_diagonal(config, log2_res, params, rays, lo, hi, target):
  """diag of jax.hessian of 1/R sum ||rgb(theta) - target||^2 at theta = 0.

  Args:
    config: static Config. log2_res: static L. params: field parameters.
    rays: flat Rays [R]. lo, hi: [3] box. target: [levels, R, 3] colours.

  Returns:
    [V, 3] Hessian diagonal.
  """
  num = rays.origins.shape[0]
  loss = lambda th: jnp.sum((_level_rgbs(config, params, rays, lo, hi, th) - target)**2) / num
  theta0 = jnp.zeros((grid_size(log2_res) * 3,), jnp.float32)
  return jnp.diag(jax.hessian(loss)(theta0)).reshape(-1, 3)


def reference_hessian_diagonals(config, params, rays, lo, hi, log2_res: int,
                                gt_rgb=None):
  """Dense jax.hessian reference (small grids and few rays only: O(V) passes).

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
  out = {'gn': _dense_hessian_diagonal(cfg, log2_res, params, rays, lo, hi, rgb0)}
  if gt_rgb is not None:
    target = jnp.broadcast_to(jnp.asarray(gt_rgb, jnp.float32), rgb0.shape)
    out['true'] = _dense_hessian_diagonal(cfg, log2_res, params, rays, lo, hi, target)
  return out
