"""Per-pixel uncertainty signals of a trained NeRF B, all from one render along the rays.

The variants that uncertainty.quality compares (VARIANTS):
  * laplace: what masks.compute_masks renders with Config.mask_signal='laplace':
    per-vertex sigma (laplace.vertex_sigma) of the Hessian over config.hessian_rays
    training rays drawn with config.seed, U = sum_i w_i trilinear(sigma, x_i) + (1 - acc) prior_sigma(lambda).
  * laplace_all_rays: the same with the Hessian over all training rays.
  * bayes_rays: Bayes' Rays as released, over all training rays: one scalar per vertex,
    H_v = sum_axes mean_r diag(J_r^T J_r)_v + 1e-4 / (2^L)^3, variance 1 / H_v; at a
    sample the variance is interpolated with the squared normalised trilinear weights
    (w^2 / sum w^2) and its square root taken; U = sum_i w_i clip(log10 std_i, -3, 6) +
    (1 - acc) (-3) (empty space certain), normalised to [0, 1] by (U + 3) / 9 (and
    clipped there).
  * bayes_rays_subsample: bayes_rays with the Hessian of the config.hessian_rays subsample.
  * Hessian-free (HESSIAN_FREE): weight_entropy (entropy of the fine level's normalised
    weights), depth_variance (variance of the sample distances t under the normalised
    weights, around their mean, the rendered depth; NDC units for forward-facing scenes)
    and one_minus_acc.
Every U is larger where B is less certain.

Hessian conventions: laplace.hessian_diagonal's pass (coarse and fine levels both count,
fine positions fixed w.r.t. the coarse weights) run with lambda = 0, halved: mean_jtj =
(1 / R) sum_r sum_levels diag(J_r^T J_r) [V, 3], summed over the colour channels. Then
laplace's diag(H) = 2 mean_jtj + 2 lambda exactly as laplace.hessian_diagonal, and Bayes' Rays'
H_v = sum_axes mean_jtj (its "summed J^T J divided by the number of rays").
Normalised weights of a ray whose weights sum to 0 are uniform (nothing seen: the
entropy is log S, the depth variance that of the sample distances).
"""
import functools
import time
from typing import Dict, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from renerf_jax.nerf import mip
from renerf_jax.nerf.model import materialize, render_rays
from renerf_jax.nerf.rendering import render_flat
from renerf_jax.uncertainty import laplace
from renerf_jax.uncertainty.deformation import cells_of, trilinear, trilinear_corners

VARIANTS = ('laplace', 'laplace_all_rays', 'bayes_rays', 'bayes_rays_subsample',
            'weight_entropy', 'depth_variance', 'one_minus_acc')
HESSIAN_FREE = ('weight_entropy', 'depth_variance', 'one_minus_acc')
# The Hessian pass behind each Hessian variant: 'subsample' or 'all_rays'.
HESSIAN_OF = {'laplace': 'subsample', 'bayes_rays_subsample': 'subsample',
              'laplace_all_rays': 'all_rays', 'bayes_rays': 'all_rays'}
BR_PRIOR = 1e-4  # Bayes' Rays' prior precision, divided by (2^L)^3.
BR_LOG10_MIN, BR_LOG10_MAX = -3., 6.  # Its clip of log10 std.


# --------------------------------------------------------------- Hessian-free signals


def normalised_weights(weights):
  """Rendering weights as a distribution along each ray.

  Args:
    weights: [..., S] >= 0.

  Returns:
    [..., S] summing to 1 (uniform where the weights sum to <= 1e-10).
  """
  total = jnp.sum(weights, axis=-1, keepdims=True)
  ok = total > 1e-10
  uniform = jnp.full(weights.shape, 1. / weights.shape[-1], weights.dtype)
  return jnp.where(ok, jnp.maximum(weights, 0.) / jnp.where(ok, total, 1.), uniform)


def weight_entropy(weights):
  """Entropy of the normalised weights, in nats.

  Args:
    weights: [..., S] >= 0.

  Returns:
    [...] in [0, log S]: 0 for one-hot weights, log S for uniform (or all-zero) ones.
  """
  p = normalised_weights(weights)
  return -jnp.sum(jnp.where(p > 0., p * jnp.log(jnp.where(p > 0., p, 1.)), 0.), axis=-1)


def depth_variance(weights, t_vals):
  """Variance of the sample distances under the normalised weights.

  Args:
    weights: [..., S] >= 0. t_vals: [..., S + 1] interval edges (samples at the midpoints).

  Returns:
    [...] >= 0 (0 for one-hot weights).
  """
  p = normalised_weights(weights)
  t_mids = 0.5 * (t_vals[..., :-1] + t_vals[..., 1:])
  mean = jnp.sum(p * t_mids, axis=-1, keepdims=True)
  return jnp.sum(p * (t_mids - mean)**2, axis=-1)


def one_minus_acc(acc):
  """1 - accumulated opacity, clipped to [0, 1].

  Args:
    acc: [...].

  Returns:
    [...].
  """
  return jnp.clip(1. - acc, 0., 1.)


def opacity(acc):
  """Accumulated opacity, clipped to [0, 1]: not an uncertainty but a region selector
  (Config.mask_signal 'acc', NeRF only: with mask_threshold 0.5 the masks keep the pixels
  B renders empty, e.g. lego's background; one_minus_acc at 0.5 keeps the opaque ones, the
  object; issue 49 item 5). As a mask's "uncertainty" map it reads inverted.

  Args:
    acc: [...].

  Returns:
    [...].
  """
  return jnp.clip(acc, 0., 1.)


# --------------------------------------------------------------- rendering of vertex values


def render_vertex_values(weights, acc, point_values, u_bg):
  """U = sum_i w_i u_i + (1 - acc) u_bg (masks.render_uncertainty's rendering).

  Args:
    weights: [..., S]. acc: [...]. point_values: [..., S] U at the samples.
    u_bg: scalar U of the part of the ray that hits nothing.

  Returns:
    [...].
  """
  return jnp.sum(weights * point_values, axis=-1) + one_minus_acc(acc) * u_bg


def squared_weight_interp(values, points, lo, hi):
  """Bayes' Rays' interpolation of a per-vertex variance: sum w^2 v / sum w^2.

  Args:
    values: [(n + 1)^3] per-vertex variance. points: [..., 3]. lo, hi: box corners.

  Returns:
    [...] (the vertices' common value when all 8 corners agree).
  """
  ids, w = trilinear_corners(points, lo, hi, cells_of(values.shape[0]))
  corner = jnp.take(values, ids, axis=0, mode='clip')
  w2 = w**2
  return jnp.sum(w2 * corner, axis=-1) / jnp.sum(w2, axis=-1)  # sum w2 >= 1 / 8.


def bayes_rays_normalise(x):
  """Maps Bayes' Rays' rendered log10 std from [-3, 6] to [0, 1].

  Args:
    x: [...].

  Returns:
    [...] (x + 3) / 9.
  """
  return (x - BR_LOG10_MIN) / (BR_LOG10_MAX - BR_LOG10_MIN)


def bayes_rays_render(weights, acc, point_var):
  """Bayes' Rays' rendered uncertainty, normalised to [0, 1].

  Args:
    weights: [..., S]. acc: [...]. point_var: [..., S] interpolated variance > 0.

  Returns:
    [...] normalise(sum_i w_i clip(log10 sqrt(var_i), -3, 6) + (1 - acc) (-3)), clipped
    to [0, 1] (float weights summing a little above 1 would leave it).
  """
  log_std = jnp.clip(0.5 * jnp.log10(jnp.maximum(point_var, 1e-30)), BR_LOG10_MIN,
                     BR_LOG10_MAX)
  u = jnp.sum(weights * log_std, axis=-1) + one_minus_acc(acc) * BR_LOG10_MIN
  return jnp.clip(bayes_rays_normalise(u), 0., 1.)


# --------------------------------------------------------------- Hessian tables


def mean_jtj(config, params, rays, lo, hi, chunk: int, show_progress: bool = False):
  """(1 / R) sum_r sum_levels diag(J_r^T J_r) over rays, by laplace's pass, timed.

  Args:
    config: Config (deform_log2_res). params: trained field parameters.
    rays: flat Rays [R]. lo, hi: [3] box of the grid. chunk: rays per jitted chunk.
    show_progress: draw a bar over the rays.

  Returns:
    ([V, 3] float32 on the device, wall seconds until it is ready).
  """
  t0 = time.perf_counter()
  h = laplace.hessian_diagonal(config, params, rays, lo, hi, config.deform_log2_res, 0.,
                               chunk=chunk, show_progress=show_progress)
  return jax.block_until_ready(0.5 * h), time.perf_counter() - t0


def laplace_sigma(jtj, lam: float):
  """laplace.vertex_sigma of diag(H) = 2 mean_jtj + 2 lambda.

  Args:
    jtj: [V, 3] from mean_jtj. lam: prior precision.

  Returns:
    [V] sigma.
  """
  return laplace.vertex_sigma(2. * jtj + 2. * lam)


def bayes_rays_variance(jtj, log2_res: int):
  """Bayes' Rays' per-vertex variance 1 / (sum_axes mean_jtj + 1e-4 / (2^L)^3).

  Args:
    jtj: [V, 3] from mean_jtj. log2_res: L.

  Returns:
    [V] variance.
  """
  return 1. / (jnp.sum(jtj, axis=-1) + BR_PRIOR / float(2**log2_res)**3)


class Tables(NamedTuple):
  """The per-vertex tables of the Hessian variants (device arrays)."""
  sigmas: Dict[str, jnp.ndarray]  # 'laplace', 'laplace_all_rays': [V] sigma.
  variances: Dict[str, jnp.ndarray]  # 'bayes_rays', 'bayes_rays_subsample': [V] variance.
  u_bg: float  # The Laplace variants' background U: laplace.prior_sigma(lambda).


def hessian_tables(config, params, train_rays, lo, hi, show_progress: bool = False):
  """Both Hessian passes (subsample and all rays) and every variant's table.

  Uses config.hessian_rays (subsample drawn with config.seed, as compute_masks),
  config.hessian_lambda, config.deform_log2_res and config.hessian_chunk. When the
  subsample is the whole pool, the all-rays pass is not run again.

  Args:
    config: Config. params: trained field parameters.
    train_rays: Rays of the training pool (any leading shape). lo, hi: [3] grid box.
    show_progress: draw bars over the Hessian rays.

  Returns:
    (Tables, info: {'hessian_seconds': {'subsample', 'all_rays'}, 'hessian_rays': the
    same keys}).
  """
  flat = jax.tree_util.tree_map(lambda x: x.reshape((-1, x.shape[-1])), train_rays)
  sub = laplace.subsample_rays(flat, config.hessian_rays, config.seed)
  n_all, n_sub = int(flat.origins.shape[0]), int(sub.origins.shape[0])
  jtj_sub, s_sub = mean_jtj(config, params, sub, lo, hi, config.hessian_chunk, show_progress)
  if n_sub == n_all:
    jtj_all, s_all = jtj_sub, s_sub
  else:
    jtj_all, s_all = mean_jtj(config, params, flat, lo, hi, config.hessian_chunk,
                              show_progress)
  lam, res = config.hessian_lambda, config.deform_log2_res
  tables = Tables(sigmas={'laplace': laplace_sigma(jtj_sub, lam),
                          'laplace_all_rays': laplace_sigma(jtj_all, lam)},
                  variances={'bayes_rays': bayes_rays_variance(jtj_all, res),
                             'bayes_rays_subsample': bayes_rays_variance(jtj_sub, res)},
                  u_bg=laplace.prior_sigma(lam))
  return tables, {'hessian_seconds': {'subsample': s_sub, 'all_rays': s_all},
                  'hessian_rays': {'subsample': n_sub, 'all_rays': n_all}}


# --------------------------------------------------------------- one render, every signal


@functools.partial(jax.jit, static_argnums=(0,))
def _signals_chunk(config, params, rays, lo, hi, sigmas, variances, u_bg):
  """Fine-level render of rays [B] and every signal ([B] each; rgb [B, 3])."""
  fine = render_rays(config, params, rays, jax.random.PRNGKey(0), train=False)[-1]
  means, _ = mip.cast_rays(fine['t_vals'], rays.origins, rays.directions, rays.radii,
                           config.ray_shape)
  means = materialize(means)
  w, acc = fine['weights'], fine['acc']
  out = {'rgb': fine['rgb'], 'distance': fine['distance'], 'acc': acc}
  for name, sigma in sigmas.items():
    points = trilinear(sigma[:, None], means, lo, hi)[..., 0]
    out[name] = render_vertex_values(w, acc, points, u_bg)
  for name, var in variances.items():
    out[name] = bayes_rays_render(w, acc, squared_weight_interp(var, means, lo, hi))
  out['weight_entropy'] = weight_entropy(w)
  out['depth_variance'] = depth_variance(w, fine['t_vals'])
  out['one_minus_acc'] = one_minus_acc(acc)
  return out


def render_signals(config, params, rays, lo, hi, tables: Tables, show_progress=False,
                   desc='signals'):
  """Renders rays once and returns every variant's U with the render itself.

  Args:
    config: Config (render_chunk). params: trained field parameters.
    rays: Rays with leading shape [...] (e.g. [views, H, W]).
    lo, hi: [3] box of the grid. tables: from hessian_tables.
    show_progress: draw a bar over the rays. desc: its label.

  Returns:
    dict of host numpy float32 arrays shaped [...]: each of VARIANTS, 'distance', 'acc',
    and 'rgb' [..., 3] (the fine colour, unclipped).
  """
  shape = rays.origins.shape[:-1]
  flat = jax.tree_util.tree_map(lambda x: jnp.reshape(x, (-1, x.shape[-1])), rays)
  lo = jnp.asarray(lo, jnp.float32) * jnp.ones(3, jnp.float32)
  hi = jnp.asarray(hi, jnp.float32) * jnp.ones(3, jnp.float32)
  fn = lambda p, r: _signals_chunk(config, p, r, lo, hi, tables.sigmas, tables.variances,
                                   jnp.float32(tables.u_bg))
  out = render_flat(config, params, flat, show_progress=show_progress, desc=desc,
                    chunk_fn=fn)
  return {k: np.asarray(v, np.float32).reshape(shape + v.shape[1:]) for k, v in out.items()}
