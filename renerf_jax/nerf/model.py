"""Coarse-to-fine mip-NeRF renderer over any field backbone: rays -> per-level outputs."""
from typing import Callable, List, Optional

import jax
import jax.numpy as jnp

from renerf_jax.nerf import contraction, mip
from renerf_jax.nerf.fields import make_field
from renerf_jax.nerf.fields.proposal import make_proposal

# Per-level sample offsets: (level, means [B, S, 3]) -> offsets [B, S, 3].
OffsetFn = Callable[[int, jnp.ndarray], jnp.ndarray]


@jax.custom_jvp
def trunc_exp(x):
  """exp(x) with the derivative exp(clip(x, -15, 15)) (Instant-NGP's density activation).

  The forward value is clipped at exp(30) so that float32 stays finite; the clipped
  derivative keeps one huge raw density from producing a huge gradient step.
  """
  return jnp.exp(jnp.minimum(x, 30.))


@trunc_exp.defjvp
def _trunc_exp_jvp(primals, tangents):
  (x,), (dx,) = primals, tangents
  return trunc_exp(x), jnp.exp(jnp.clip(x, -15., 15.)) * dx


def raw_to_outputs(raw_rgb, raw_density, rgb_padding, density_bias,
                   density_activation='softplus'):
  """Sigmoid colour with padding p (range [-p, 1 + p]); density act(raw + bias).

  density_activation: 'softplus' (mip-NeRF / RegNeRF) or 'exp' (trunc_exp, Instant-NGP:
  reaches the huge densities that a narrow annealed sampling interval needs in a few
  steps; with softplus a grid backbone's colours saturate before its density catches up).
  """
  rgb = jax.nn.sigmoid(raw_rgb) * (1. + 2. * rgb_padding) - rgb_padding
  if density_activation == 'exp':
    density = trunc_exp(raw_density + density_bias)
  else:
    density = jax.nn.softplus(raw_density + density_bias)
  return rgb, density


def materialize(tree):
  """Returns `tree` (arrays) unchanged, computed into memory once before its consumers.

  XLA:CPU fuses the computation of the sample positions (ray origin + t * direction, t
  from near / far) into each consumer, and the grid field's gather then recomputes it for
  every one of the L levels x 8 cell corners of every sample: rendering with the grid
  backbone ran 3x slower than the same field applied to stored positions
  (benchmarks/bench_throughput.py). A conditional is a fusion boundary that XLA keeps
  (its CPU pipeline drops optimization_barrier). The predicate is a tautology on the data
  (v is NaN or v is not NaN), so the zeros branch never runs, NaNs included.
  """
  leaves = jax.tree_util.tree_leaves(tree)
  if not leaves or leaves[0].size == 0:
    return tree
  v = leaves[0].reshape(-1)[0]
  pred = jnp.isnan(v) | ~jnp.isnan(v)
  return jax.lax.cond(pred, lambda t: t,
                      lambda t: jax.tree_util.tree_map(jnp.zeros_like, t), tree)


def render_rays(config, params, rays, key, train: bool,
                feature_mask: Optional[jnp.ndarray] = None,
                offsets: Optional[OffsetFn] = None) -> List[dict]:
  """Renders rays with num_levels levels (coarse, then resampled fine).

  With Config.sampler = 'coarse_fine' (mip-NeRF) every level evaluates the one scene
  field; with 'proposal' level 0 evaluates the proposal field (density only) and level 1
  the scene field at the samples resampled from the proposal's weights.

  Args:
    config: static Config (sampling, field and output settings).
    params: field parameters (fields.init_field_params: {'params'}, plus 'proposal' with
      the proposal sampler).
    rays: cameras.Rays with leading shape [B].
    key: PRNG key (stratified jitter, density noise); unused at eval.
    train: training mode (randomised sampling if config.randomized, density noise).
    feature_mask: optional IPE feature mask (FreeNeRF frequency regularisation).
    offsets: optional per-level hook (level, means [B, S, 3]) -> offsets [B, S, 3],
      added to that level's sample means before the field (means + offsets(level,
      means): the Bayes' Rays deformation field, deformation.make_warp, or per-sample
      offsets per level; with Config.contraction, in contracted space as Bayes' Rays
      does); None costs nothing.

  Returns:
    One dict per level: rgb [B, 3], distance [B], acc [B], weights [B, S], t_vals [B, S+1],
    density [B, S]. With Config.sampler = 'proposal' level 0 is the proposal's (S =
    proposal_samples) and has no 'rgb' (colour_levels gives the levels that have it).
  """
  field = make_field(config)
  proposal = config.sampler == 'proposal'
  field_vars = {'params': params['params']} if proposal else params
  randomized = train and config.randomized
  results = []
  t_vals = weights = None
  for level in range(config.num_levels):
    key, k_sample, k_noise = jax.random.split(key, 3)
    if level == 0:
      n = config.proposal_samples if proposal else config.num_samples
      t_vals, (means, covs) = mip.sample_along_rays(
          k_sample, rays.origins, rays.directions, rays.radii, n,
          rays.near, rays.far, randomized, config.lindisp, config.ray_shape,
          config.piecewise_spacing)
    else:
      t_vals, (means, covs) = mip.resample_along_rays(
          k_sample, rays.origins, rays.directions, rays.radii, t_vals, weights, randomized,
          config.ray_shape, config.stop_level_grad, config.resample_padding,
          config.num_samples)
    density_only = proposal and level == 0  # Its covariances are never computed.
    if config.contraction:  # Unbounded scenes: fields and offsets in contracted space.
      means, contracted_covs = contraction.contract_samples(
          means, None if density_only else covs, config.contraction)
      covs = covs if density_only else contracted_covs
    if offsets is not None:
      means = means + offsets(level, means)
    if density_only:
      means = materialize(means)
      raw_density = make_proposal(config).apply({'params': params['proposal']}, means)
      raw_rgb = None
    else:
      means, covs = materialize((means, covs))
      raw_rgb, raw_density = field.apply(field_vars, means, covs, rays.viewdirs,
                                         feature_mask)
    if train and config.density_noise > 0 and raw_rgb is not None:
      raw_density = raw_density + config.density_noise * jax.random.normal(
          k_noise, raw_density.shape)
    if raw_rgb is None:
      _, density = raw_to_outputs(0., raw_density, config.rgb_padding,
                                  config.density_bias, config.density_activation)
      density = empty_outside_box(config, means, density)
      out = mip.volumetric_weights(density, t_vals, rays.directions)
    else:
      rgb, density = raw_to_outputs(raw_rgb, raw_density, config.rgb_padding,
                                    config.density_bias, config.density_activation)
      density = empty_outside_box(config, means, density)
      out = mip.volumetric_rendering(rgb, density, t_vals, rays.directions,
                                     config.white_bkgd)
    out.update(t_vals=t_vals, density=density)
    weights = out['weights']
    results.append(out)
  return results


def empty_outside_box(config, means, density):
  """Density with samples outside Config.grid_box set to 0 (Config.outside_box = 'empty').

  The grid fields clamp a point outside their box onto the box's faces, so with 'clamp'
  (the default) a sample outside gets the density of the nearest face cell: on a bounded
  scene whose cameras lie outside the box (Blender), that copies the faces' density along
  every ray to the camera, and floaters appear there (experiments/results/
  seed_matched_fox_lego). 'empty' makes the scene empty outside its box, as Instant-NGP
  does by sampling only inside its aabb. Left alone with Config.contraction (every
  contracted point is inside the box).

  Args:
    config: static Config. means: [..., S, 3] sample positions as the fields see them.
    density: [..., S] densities.

  Returns:
    density, zeroed outside the box when Config.outside_box = 'empty'.
  """
  if config.outside_box != 'empty' or config.contraction:
    return density
  lo, hi = (jnp.asarray(b, density.dtype) for b in config.grid_box)
  inside = jnp.all((means >= lo) & (means <= hi), axis=-1)
  return jnp.where(inside, density, 0.)


def level_samples(config):
  """Samples per ray of each of render_rays' levels (the proposal level first)."""
  return tuple(config.proposal_samples if config.sampler == 'proposal' and level == 0
               else config.num_samples for level in range(config.num_levels))


def samples_label(config) -> str:
  """Samples per ray as a table label: '2x48' (coarse-to-fine) or '64p+48' (proposal)."""
  if config.sampler == 'proposal':
    return f'{config.proposal_samples}p+{config.num_samples}'
  return f'{config.num_levels}x{config.num_samples}'


def colour_levels(config) -> int:
  """How many of render_rays' levels (the last ones) render colour: all of them with
  the coarse-to-fine sampler, only the last with the proposal sampler."""
  return 1 if config.sampler == 'proposal' else config.num_levels
