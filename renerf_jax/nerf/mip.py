"""mip-NeRF geometry: Gaussians of cones and cylinders, IPE, sampling, volume rendering.

Pure jax.numpy functions; shapes are written [rays..., samples, dims]. `t_vals` are the
S + 1 interval edges of S samples along each ray, in units of the ray's (unnormalised)
direction.
"""
import jax
import jax.numpy as jnp
import numpy as np

from renerf_jax.nerf import contraction

_TINY = 1e-10


def lift_gaussian(d, t_mean, t_var, r_var):
  """Lifts a Gaussian along a ray (mean/var in t, var across) into 3D, diagonal covariance.

  Args:
    d: [..., 3] ray directions.
    t_mean, t_var, r_var: [..., S] mean and variance along the ray, variance across it.

  Returns:
    (mean [..., S, 3], cov_diag [..., S, 3]).
  """
  mean = d[..., None, :] * t_mean[..., None]
  d_mag_sq = jnp.maximum(_TINY, jnp.sum(d**2, axis=-1, keepdims=True))
  d_outer_diag = d**2
  null_outer_diag = 1. - d_outer_diag / d_mag_sq
  cov_diag = (t_var[..., None] * d_outer_diag[..., None, :] +
              r_var[..., None] * null_outer_diag[..., None, :])
  return mean, cov_diag


def conical_frustum_to_gaussian(d, t0, t1, base_radius):
  """Gaussian approximation of a conical frustum, in the numerically stable form.

  With mu = (t0 + t1) / 2 and h = (t1 - t0) / 2 the moments are
  t_mean = mu + 2 mu h^2 / (3 mu^2 + h^2),
  t_var = h^2 / 3 - 4/15 h^4 (12 mu^2 - h^2) / (3 mu^2 + h^2)^2,
  r_var = r^2 (mu^2 / 4 + 5/12 h^2 - 4/15 h^4 / (3 mu^2 + h^2)).
  The denominator is floored, so t0 == t1 == 0 (near == far == 0) stays finite, and the
  h^4 terms are evaluated through the ratio h^2 / (3 mu^2 + h^2) in [0, 1], so nothing
  overflows float32 before mu^2 itself does (h^4 (12 mu^2 - h^2) overflowed from h ~ 2e6
  on, giving t_var = 0 and, from h ~ 3e9 on, NaN).

  Args:
    d: [..., 3] directions. t0, t1: [..., S] interval ends. base_radius: [..., 1].

  Returns:
    (mean, cov_diag), each [..., S, 3].
  """
  mu = (t0 + t1) / 2.
  hw = (t1 - t0) / 2.
  denom = jnp.maximum(3. * mu**2 + hw**2, _TINY)
  ratio = hw**2 / denom
  t_mean = mu + 2. * mu * ratio
  t_var = hw**2 / 3. - (4. / 15.) * ratio**2 * (12. * mu**2 - hw**2)
  t_var = jnp.maximum(t_var, 0.)
  r_var = base_radius**2 * (mu**2 / 4. + (5. / 12.) * hw**2 - (4. / 15.) * hw**2 * ratio)
  return lift_gaussian(d, t_mean, t_var, r_var)


def cylinder_to_gaussian(d, t0, t1, radius):
  """Gaussian of a cylinder segment: uniform along the ray, disk of `radius` across."""
  t_mean = (t0 + t1) / 2.
  r_var = radius**2 / 4.
  t_var = (t1 - t0)**2 / 12.
  return lift_gaussian(d, t_mean, t_var, jnp.broadcast_to(r_var, t_mean.shape))


def cast_rays(t_vals, origins, directions, radii, ray_shape):
  """Gaussians of the S segments of each ray.

  Args:
    t_vals: [..., S + 1] interval edges. origins, directions: [..., 3]. radii: [..., 1].
    ray_shape: 'cone' or 'cylinder'.

  Returns:
    (means [..., S, 3], cov_diags [..., S, 3]).
  """
  t0, t1 = t_vals[..., :-1], t_vals[..., 1:]
  gaussian_fn = conical_frustum_to_gaussian if ray_shape == 'cone' else cylinder_to_gaussian
  means, covs = gaussian_fn(directions, t0, t1, radii)
  return means + origins[..., None, :], covs


def pos_enc(x, min_deg, max_deg, append_identity=True):
  """Sinusoidal encoding [x, sin(2^k x), sin(2^k x + pi/2)] for k in [min_deg, max_deg)."""
  scales = 2.**jnp.arange(min_deg, max_deg)
  xb = jnp.reshape(x[..., None, :] * scales[:, None], x.shape[:-1] + (-1,))
  four_feat = jnp.sin(jnp.concatenate([xb, xb + 0.5 * jnp.pi], axis=-1))
  return jnp.concatenate([x, four_feat], axis=-1) if append_identity else four_feat


def integrated_pos_enc(means, cov_diags, min_deg, max_deg):
  """Integrated positional encoding: E[sin(2^k x)] and E[cos(2^k x)] under N(mean, cov).

  E[sin(y)] = exp(-var / 2) sin(mean) for y ~ N(mean, var), so huge variances give
  features that go to 0, never NaN.

  Args:
    means, cov_diags: [..., 3].
    min_deg, max_deg: frequency bands 2^k, k in [min_deg, max_deg).

  Returns:
    [..., 2 * 3 * (max_deg - min_deg)] features, laid out [sin bands..., cos bands...],
    each half ordered by band then by coordinate.
  """
  scales = 2.**jnp.arange(min_deg, max_deg)
  shape = means.shape[:-1] + (-1,)
  y = jnp.reshape(means[..., None, :] * scales[:, None], shape)
  y_var = jnp.reshape(cov_diags[..., None, :] * scales[:, None]**2, shape)
  y = jnp.concatenate([y, y + 0.5 * jnp.pi], axis=-1)
  y_var = jnp.concatenate([y_var, y_var], axis=-1)
  return jnp.exp(-0.5 * y_var) * jnp.sin(y)


def freq_band_mask(num_bands, fraction):
  """FreeNeRF frequency-regularisation mask over bands (1 open, 0 closed).

  Band k gets weight clip(fraction * num_bands + 1 - k, 0, 1): the lowest band is always
  open and the others open one after another, linearly in `fraction` (step / (0.9 *
  max_steps) in FreeNeRF), all open at fraction = 1.

  Args:
    num_bands: number of frequency bands L.
    fraction: scalar in [0, 1] (traced is fine).

  Returns:
    [L] weights.
  """
  k = jnp.arange(num_bands, dtype=jnp.float32)
  return jnp.clip(fraction * num_bands + 1. - k, 0., 1.)


def ipe_feature_mask(band_mask):
  """Expands a per-band mask [L] to the IPE feature layout [2 * 3 * L]."""
  per_half = jnp.repeat(band_mask, 3)
  return jnp.concatenate([per_half, per_half])


def sample_along_rays(key, origins, directions, radii, num_samples, near, far, randomized,
                      lindisp, ray_shape, piecewise=False):
  """Stratified samples between near and far.

  Args:
    key: PRNG key (used when randomized).
    origins, directions: [..., 3]. radii, near, far: [..., 1].
    num_samples: S. randomized: jitter within strata. lindisp: linear in disparity.
    ray_shape: 'cone' or 'cylinder'.
    piecewise: mip-NeRF 360's spacing (contraction.s_to_t: half the samples linear on
      [near, 1], half in disparity on [1, far]; needs near < 1 < far); overrides lindisp.

  Returns:
    (t_vals [..., S + 1], (means, cov_diags) each [..., S, 3]).
  """
  u = jnp.linspace(0., 1., num_samples + 1)
  if piecewise:
    t_vals = contraction.s_to_t(u, near, far, piecewise=True)
  elif lindisp:
    t_vals = 1. / (1. / jnp.maximum(near, _TINY) * (1. - u) + 1. / far * u)
  else:
    t_vals = near * (1. - u) + far * u
  if randomized:
    mids = 0.5 * (t_vals[..., 1:] + t_vals[..., :-1])
    upper = jnp.concatenate([mids, t_vals[..., -1:]], -1)
    lower = jnp.concatenate([t_vals[..., :1], mids], -1)
    t_rand = jax.random.uniform(key, t_vals.shape)
    t_vals = lower + (upper - lower) * t_rand
  return t_vals, cast_rays(t_vals, origins, directions, radii, ray_shape)


def sorted_piecewise_constant_pdf(key, bins, weights, num_samples, randomized):
  """Draws sorted samples from the piecewise-constant density `weights` over `bins`.

  Inverse-CDF sampling with a per-ray binary search. Weights summing to ~0 fall back to
  uniform sampling.

  Args:
    key: PRNG key. bins: [..., B + 1] edges. weights: [..., B] non-negative.
    num_samples: samples per ray. randomized: stratified jitter, else evenly spaced.

  Returns:
    [..., num_samples] sorted sample positions within [bins[0], bins[-1]].
  """
  eps = 1e-5
  weight_sum = jnp.sum(weights, axis=-1, keepdims=True)
  padding = jnp.maximum(0., eps - weight_sum)
  weights = weights + padding / weights.shape[-1]
  pdf = weights / (weight_sum + padding)
  cdf = jnp.minimum(1., jnp.cumsum(pdf[..., :-1], axis=-1))
  batch = cdf.shape[:-1]
  cdf = jnp.concatenate([jnp.zeros(batch + (1,)), cdf, jnp.ones(batch + (1,))], axis=-1)
  if randomized:
    step = 1. / num_samples
    u = jnp.arange(num_samples) * step
    u = u + jax.random.uniform(key, batch + (num_samples,), maxval=step - np.float32(eps))
    u = jnp.minimum(u, 1. - eps)
  else:
    u = jnp.broadcast_to(jnp.linspace(0., 1. - eps, num_samples), batch + (num_samples,))
  n_edges = cdf.shape[-1]
  flat_cdf = cdf.reshape(-1, n_edges)
  flat_u = u.reshape(-1, num_samples)
  idx = jax.vmap(lambda c, v: jnp.searchsorted(c, v, side='right'))(flat_cdf, flat_u)
  idx = jnp.clip(idx, 1, n_edges - 1).reshape(batch + (num_samples,))
  cdf0 = jnp.take_along_axis(cdf, idx - 1, axis=-1)
  cdf1 = jnp.take_along_axis(cdf, idx, axis=-1)
  bin0 = jnp.take_along_axis(bins, idx - 1, axis=-1)
  bin1 = jnp.take_along_axis(bins, idx, axis=-1)
  denom = cdf1 - cdf0
  frac = jnp.where(denom > 0, (u - cdf0) / jnp.where(denom > 0, denom, 1.), 0.)
  return bin0 + jnp.clip(frac, 0., 1.) * (bin1 - bin0)


def resample_along_rays(key, origins, directions, radii, t_vals, weights, randomized,
                        ray_shape, stop_grad, resample_padding, num_samples=None):
  """mip-NeRF hierarchical resampling with the 2-tap max, 2-tap blur and padding.

  Args:
    key: PRNG key. origins, directions: [..., 3]. radii: [..., 1].
    t_vals: [..., S + 1] edges of the previous level. weights: [..., S] its weights.
    randomized: jitter. ray_shape: 'cone' or 'cylinder'.
    stop_grad: no gradient through the new t_vals.
    resample_padding: constant added to the blurred weights.
    num_samples: samples of the new level, N (default S, as many as the previous).

  Returns:
    (new t_vals [..., N + 1], (means, cov_diags) each [..., N, 3]).
  """
  weights_pad = jnp.concatenate([weights[..., :1], weights, weights[..., -1:]], axis=-1)
  weights_max = jnp.maximum(weights_pad[..., :-1], weights_pad[..., 1:])
  weights_blur = 0.5 * (weights_max[..., :-1] + weights_max[..., 1:])
  weights = weights_blur + resample_padding
  n_edges = t_vals.shape[-1] if num_samples is None else num_samples + 1
  new_t_vals = sorted_piecewise_constant_pdf(key, t_vals, weights, n_edges, randomized)
  if stop_grad:
    new_t_vals = jax.lax.stop_gradient(new_t_vals)
  return new_t_vals, cast_rays(new_t_vals, origins, directions, radii, ray_shape)


def volumetric_rendering(rgb, density, t_vals, directions, white_bkgd):
  """Alpha compositing along each ray.

  alpha_i = 1 - exp(-density_i * delta_i), T_i = exp(-sum_{j<i} density_j delta_j),
  w_i = alpha_i T_i. Works for density 0 (w = 0), huge densities (w saturates at the
  first sample) and zero-length intervals (alpha = 0).

  Args:
    rgb: [..., S, 3]. density: [..., S] >= 0. t_vals: [..., S + 1].
    directions: [..., 3] (delta is measured in units of |direction|).
    white_bkgd: composite the remaining transmittance on white.

  Returns:
    dict with rgb [..., 3], distance [..., ] (expected distance of the weights,
    normalised by acc; t_far for rays with acc ~ 0, clipped to [t_near, t_far]),
    acc [...] (opacity) and weights [..., S].
  """
  out = volumetric_weights(density, t_vals, directions)
  comp_rgb = jnp.sum(out['weights'][..., None] * rgb, axis=-2)
  if white_bkgd:
    comp_rgb = comp_rgb + (1. - out['acc'][..., None])
  return dict(rgb=comp_rgb, **out)


def volumetric_weights(density, t_vals, directions):
  """The colour-free part of volumetric_rendering: weights, opacity and distance.

  Args:
    density: [..., S] >= 0. t_vals: [..., S + 1]. directions: [..., 3].

  Returns:
    dict with distance [...], acc [...] and weights [..., S] (see volumetric_rendering).
  """
  t_mids = 0.5 * (t_vals[..., :-1] + t_vals[..., 1:])
  t_dists = t_vals[..., 1:] - t_vals[..., :-1]
  delta = t_dists * jnp.linalg.norm(directions[..., None, :], axis=-1)
  density_delta = density * delta
  alpha = 1. - jnp.exp(-density_delta)
  trans = jnp.exp(-jnp.concatenate(
      [jnp.zeros_like(density_delta[..., :1]),
       jnp.cumsum(density_delta[..., :-1], axis=-1)], axis=-1))
  weights = alpha * trans
  acc = jnp.sum(weights, axis=-1)
  ok = acc > 1e-6
  distance = jnp.where(ok, jnp.sum(weights * t_mids, axis=-1) / jnp.where(ok, acc, 1.),
                       t_vals[..., -1])
  distance = jnp.clip(distance, t_vals[..., 0], t_vals[..., -1])
  return dict(distance=distance, acc=acc, weights=weights)
