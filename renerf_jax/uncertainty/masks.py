"""Rendered Laplace uncertainty of a trained NeRF and the pseudo-view masks of Re-Nerfing.

The per-vertex sigma of the Laplace approximation over a deformation grid
(uncertainty.laplace, on the vertex grid of uncertainty.deformation), interpolated in space
and volume-rendered along pseudo-view rays, is the per-pixel uncertainty U that
Re-Nerfing thresholds to mask unreliable pseudo-view pixels.

Conventions:
  * Rendered uncertainty: U = sum_i w_i U(x_i) + (1 - acc) U_bg with the fine level's
    weights, U(x) = trilinear(sigma, x), and U_bg = the prior sigma by default (the part
    of a ray that hits nothing is as uncertain as unseen space).
  * Threshold: mu = Config.mask_threshold when >= 0, else the mu that keeps
    Config.mask_keep_frac of the pixels (mask_threshold, the one rule every backbone's
    masks use).
  * Masks: 1 keeps a pixel (U <= mu), 0 masks it (U > mu).
"""
import functools
import time
from typing import Callable, NamedTuple, Optional, Tuple

import jax
import jax.numpy as jnp
import jaxopt
import numpy as np

from renerf_jax import distributed
from renerf_jax.nerf import mip
from renerf_jax.nerf.model import materialize, render_rays
from renerf_jax.progress import progress_bar
from renerf_jax.nerf.rendering import render_flat
from renerf_jax.uncertainty import laplace
from renerf_jax.uncertainty import signals as sig
from renerf_jax.uncertainty.deformation import trilinear


# --------------------------------------------------------------- uncertainty


@functools.partial(jax.jit, static_argnums=(0,))
def _uncertainty_chunk(config, params, sigma, rays, lo, hi, u_bg):
  """Fine-level volume rendering of trilinear(sigma) plus the background term.

  Args:
    config: static Config. params: field parameters. sigma: [V] per-vertex sigma.
    rays: Rays [B]. lo, hi: [3] box of the grid. u_bg: scalar background uncertainty.

  Returns:
    (u [B], rgb [B, 3] the fine colour).
  """
  fine = render_rays(config, params, rays, jax.random.PRNGKey(0), train=False)[-1]
  means, _ = mip.cast_rays(fine['t_vals'], rays.origins, rays.directions, rays.radii,
                           config.ray_shape)
  means = materialize(means)  # Computed once, not once per trilinear corner.
  u_points = trilinear(sigma[:, None], means, lo, hi)[..., 0]  # [B, S]
  u = jnp.sum(fine['weights'] * u_points, axis=-1)
  u = u + jnp.clip(1. - fine['acc'], 0., 1.) * u_bg
  return u, fine['rgb']


def render_uncertainty(config, params, sigma, rays, lo, hi, chunk: int = 4096,
                       u_bg: Optional[float] = None, log_scale: bool = False,
                       show_progress: bool = False, desc: str = 'uncertainty'):
  """Per-ray uncertainty U = sum_i w_i U(x_i) + (1 - acc) U_bg over the fine level.

  The colour comes out of the same pass, so pseudo-views with masks cost one render.

  Args:
    config: Config. params: field parameters.
    sigma: [V] per-vertex sigma (laplace.vertex_sigma).
    rays: flat Rays [N].
    lo, hi: box of the grid.
    chunk: rays per jitted chunk (last chunk padded).
    u_bg: uncertainty of the part of the ray that hits nothing (default: the largest
      vertex sigma, which is the prior sigma whenever some vertex is unseen; pass
      laplace.prior_sigma(lambda) to make it explicit).
    log_scale: return log U (Bayes' Rays visualises / thresholds log U; a keep-fraction
      threshold is the same either way, an absolute one is not).
    show_progress: draw a bar (rays, rate, ETA). desc: its label.

  Returns:
    (u [N], rgb [N, 3]) host numpy float32 arrays.
  """
  sigma = jnp.asarray(sigma, jnp.float32)
  if u_bg is None:
    u_bg = float(jnp.max(sigma))
  num = int(rays.origins.shape[0])
  chunk = max(1, min(chunk, num))
  lo = jnp.asarray(lo, jnp.float32) * jnp.ones(3, jnp.float32)
  hi = jnp.asarray(hi, jnp.float32) * jnp.ones(3, jnp.float32)
  params = distributed.local(params)  # Each process renders its share of the chunks.
  bar = progress_bar(total=num, desc=desc, disable=not show_progress, unit='ray')

  def one_chunk(k):
    idx, valid = laplace._chunk_indices(num, k * chunk, chunk)  # pylint: disable=protected-access
    part = jax.tree_util.tree_map(lambda x, idx=idx: jnp.take(x, idx, axis=0), rays)
    u, rgb = _uncertainty_chunk(config, params, sigma, part, lo, hi,
                                jnp.float32(u_bg))
    bar.update(int(valid.sum()))
    return np.asarray(u), np.asarray(rgb)
  outs = distributed.map_shares(one_chunk, -(-num // chunk))
  bar.close()
  sizes = [min(chunk, num - k * chunk) for k in range(len(outs))]
  u = np.concatenate([o[0][:m] for o, m in zip(outs, sizes)])
  rgbs = [o[1][:m] for o, m in zip(outs, sizes)]
  if log_scale:
    u = np.log(np.maximum(u, np.finfo(np.float32).tiny))
  return u, np.concatenate(rgbs)


# --------------------------------------------------------------- thresholds and masks


@jax.jit
def _bisect_threshold(u, k):
  """jaxopt.Bisection for the k-th smallest of u.

  Args:
    u: [N] float32 uncertainties. k: traced int32, 1 <= k <= N.

  Returns:
    The upper end of the final bracket (see threshold_for_keep_fraction).
  """
  num = u.shape[0]
  # (count(u <= mu) - k + 1/2) / N = mean(u <= mu) - (k - 1/2) / N; counted in int32 so
  # it is exact for any N, and never 0: a clean sign change at the k-th smallest u.
  fn = lambda mu: (jnp.sum(u <= mu, dtype=jnp.int32) - k + 0.5) / num
  lower = jnp.nextafter(jnp.min(u), -jnp.inf)  # f < 0: nothing kept.
  upper = jnp.max(u)  # f > 0: everything kept.
  solver = jaxopt.Bisection(optimality_fun=fn, lower=lower, upper=upper, maxiter=200,
                            tol=0., check_bracket=False, jit=True)
  return solver.run().state.high


def threshold_for_keep_fraction(u, keep_frac: float):
  """The threshold mu that keeps a target fraction of pixels (U <= mu kept).

  Solves f(mu) = mean(U <= mu) - keep_frac = 0 with jaxopt.Bisection on the bracket
  [min U, max U]. f is a monotone step function, so the target is shifted half a step,
  (k - 1/2) / N with k = ceil(keep_frac N), which puts the sign change exactly at the
  k-th smallest U; the upper end of the bracket is returned (it always keeps >= k pixels).
  Tolerance: tol = 0 and 200 halvings, i.e. the bracket shrinks until its ends are
  adjacent float32 numbers, so exactly k pixels are kept unless U has ties at u_(k) (the
  kept fraction is then within 1 / N of the target, or above it by the tie count).

  Args:
    u: [N] finite uncertainties (any leading shape; flattened).
    keep_frac: target fraction in [0, 1]; <= 0 masks everything (mu below min U),
      >= 1 keeps everything (mu = max U).

  Returns:
    float mu.
  """
  u = jnp.asarray(u, jnp.float32).reshape(-1)
  if keep_frac <= 0.:
    return float(jnp.nextafter(jnp.min(u), -jnp.inf))
  if keep_frac >= 1.:
    return float(jnp.max(u))
  k = min(max(int(np.ceil(keep_frac * u.shape[0] - 1e-9)), 1), u.shape[0])
  return float(_bisect_threshold(u, jnp.int32(k)))


def mask_threshold(config, u) -> float:
  """The threshold mu of the pseudo-view masks, the one rule of every backbone.

  Args:
    config: Config. config.mask_threshold >= 0 is an absolute mu on U; else mu keeps
      config.mask_keep_frac of the pixels (threshold_for_keep_fraction).
    u: [...] uncertainties of all the pseudo-view pixels (flattened).

  Returns:
    float mu.
  """
  if config.mask_threshold >= 0:
    return float(config.mask_threshold)
  return threshold_for_keep_fraction(u, config.mask_keep_frac)


def masks_from_uncertainty(u, mu):
  """Float masks: 1 keeps a pixel (U <= mu), 0 masks it (U > mu).

  mu = inf keeps everything; mu = 0 (or below min U; U > 0) masks everything.

  Args:
    u: [...] uncertainties. mu: scalar threshold.

  Returns:
    [...] float32 mask.
  """
  return (jnp.asarray(u) <= mu).astype(jnp.float32)


# --------------------------------------------------------------- Hessian-free signals


@functools.partial(jax.jit, static_argnums=(0,))
def _signal_chunk(config, params, rays):
  """Fine-level colour and config.mask_signal (a Hessian-free U) of rays [B]."""
  fine = render_rays(config, params, rays, jax.random.PRNGKey(0), train=False)[-1]
  u = {'one_minus_acc': lambda: sig.one_minus_acc(fine['acc']),
       'depth_variance': lambda: sig.depth_variance(fine['weights'], fine['t_vals']),
       'weight_entropy': lambda: sig.weight_entropy(fine['weights']),
       'acc': lambda: sig.opacity(fine['acc'])}[config.mask_signal]()
  return {'u': u, 'rgb': fine['rgb']}


def render_signal(config, params, rays, show_progress=False, desc='uncertainty'):
  """U = config.mask_signal (not 'laplace') and the colour of rays [N], in one render.

  Returns:
    (u [N], rgb [N, 3]) host numpy arrays.
  """
  out = render_flat(config, params, rays, show_progress=show_progress, desc=desc,
                    chunk_fn=lambda p, r: _signal_chunk(config, p, r))
  return out['u'], out['rgb']


# --------------------------------------------------------------- pseudo-view masks

# The Hessian pass of compute_masks: (config, params, train_rays, lo, hi, chunk,
# show_progress) -> (sigma [V], seconds the pass costs), as laplace.vertex_sigma_pass.
SigmaFn = Callable[..., Tuple[jnp.ndarray, float]]


class Masks(NamedTuple):
  """Result of compute_masks (host numpy arrays shaped like the pseudo rays)."""
  uncertainty: np.ndarray  # [...] rendered U.
  mask: np.ndarray  # [...] 1 keeps a pixel, 0 masks it.
  mu: float  # The threshold.
  rgb: np.ndarray  # [..., 3] the fine colour, rendered in the same pass as U.
  hessian_seconds: float  # The Hessian pass's seconds, as its sigma_fn reports them.
  render_seconds: float  # Wall time of everything else: the render, U and the threshold.


def compute_masks(config, params, train_rays, pseudo_rays, lo, hi,
                  hessian_chunk: Optional[int] = None, show_progress: bool = False,
                  sigma_fn: Optional[SigmaFn] = None) -> Masks:
  """Uncertainty masks of pseudo-view pixels (the Re-Nerfing + Bayes' Rays step).

  U is config.mask_signal: a Hessian-free signal of one render (the default
  'one_minus_acc'), or with 'laplace' the Laplace approximation, which uses
  config.deform_log2_res, config.hessian_rays (training rays drawn with
  config.seed), config.hessian_lambda, config.mask_threshold (>= 0: absolute mu) or else
  config.mask_keep_frac (mu by bisection), and config.render_chunk. U_bg is the prior
  sigma sqrt(3 / (2 lambda)). The pseudo-view colours come out of the uncertainty render,
  so masked pseudo-views cost the Hessian pass plus one render, not two renders.

  Args:
    config: Config. params: trained field parameters.
    train_rays: Rays of the training pool (any leading shape; flattened).
    pseudo_rays: Rays of the pseudo-view pixels, leading shape [...] (e.g. [M, H, W]).
    lo, hi: [3] box of the deformation grid.
    hessian_chunk: rays per chunk of the Hessian pass (default config.hessian_chunk).
    show_progress: draw bars over the Hessian rays and the pseudo rays.
    sigma_fn: the Hessian pass, (config, params, train_rays, lo, hi, chunk,
      show_progress) -> (sigma [V], the seconds it costs) (None:
      laplace.vertex_sigma_pass, which reports its wall time; another implementation
      reports what its result cost to compute, which Masks.hessian_seconds carries).

  Returns:
    Masks.
  """
  t0 = time.perf_counter()
  flat = lambda r: jax.tree_util.tree_map(lambda x: x.reshape((-1, x.shape[-1])), r)
  shape = pseudo_rays.origins.shape[:-1]
  pass_wall = 0.
  desc = f'pseudo-views + uncertainty ({shape[0]})' if len(shape) == 3 else 'uncertainty'
  if config.mask_signal != 'laplace':  # Hessian-free: no Hessian pass at all.
    u, rgb = render_signal(config, params, flat(pseudo_rays), show_progress, desc)
    hessian_seconds = 0.
  else:
    train = laplace.subsample_rays(flat(train_rays), config.hessian_rays, config.seed)
    t_pass = time.perf_counter()
    sigma, hessian_seconds = (sigma_fn or laplace.vertex_sigma_pass)(
        config, params, train, lo, hi, hessian_chunk or config.hessian_chunk, show_progress)
    pass_wall = time.perf_counter() - t_pass
    u, rgb = render_uncertainty(config, params, sigma, flat(pseudo_rays), lo, hi,
                                chunk=config.render_chunk,
                                u_bg=laplace.prior_sigma(config.hessian_lambda),
                                show_progress=show_progress, desc=desc)
  mu = mask_threshold(config, u)
  mask = np.asarray(masks_from_uncertainty(u, mu))
  return Masks(uncertainty=u.reshape(shape), mask=mask.reshape(shape), mu=float(mu),
               rgb=rgb.reshape(shape + (3,)), hessian_seconds=float(hessian_seconds),
               render_seconds=time.perf_counter() - t0 - pass_wall)
