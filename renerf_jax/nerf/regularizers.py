"""RegNeRF and FreeNeRF regularisers and their schedules (pure functions).

RegNeRF: depth smoothness (L2 total variation of the expected depth) on patches rendered
from random unobserved poses, with a log-linearly decaying weight, and sample-space
annealing of the [near, far] interval. FreeNeRF: frequency regularisation (see
mip.freq_band_mask) and occlusion regularisation. mip-NeRF 360: the distortion loss
(compact weights along each ray, against floaters). RegNeRF's colour-likelihood (flow)
loss is left out: it is off in llff3.gin and its flow model was never released.
"""
import jax.numpy as jnp

from renerf_jax.schedules import log_lerp


def depth_tv_weight(step, mult_start, mult_end, maxstep):
  """RegNeRF's depth-TV weight: log-linear from mult_start to mult_end over maxstep steps,
  then mult_end (llff3: 400 -> 0.1 over 512 steps)."""
  return log_lerp(step, mult_start, mult_end, maxstep)


def annealed_near_far(step, near, far, anneal_steps, start_perc, mid_perc):
  """RegNeRF's sample-space annealing.

  mid = near + mid_perc * (far - near); w = clip(max(step / anneal_steps, start_perc), 0, 1);
  the interval is [mid - w (mid - near), mid + w (far - mid)]. At step 0 it is
  [mid - p (mid - near), mid + p (far - mid)] (NDC with p = 1e-4, m = 1: [0.9999, 1]), and
  it widens linearly to [near, far] at step >= anneal_steps.

  Args:
    step: scalar step (traced is fine). near, far: [..., 1] bounds.
    anneal_steps: steps until the full interval. start_perc: p. mid_perc: m.

  Returns:
    (near, far) annealed, same shapes.
  """
  mid = near + mid_perc * (far - near)
  w = jnp.clip(jnp.maximum(step / max(anneal_steps, 1), start_perc), 0., 1.)
  return mid - w * (mid - near), mid + w * (far - mid)


def depth_tv(depth):
  """L2 total variation of depth patches, mean over patches and pixels.

  Args:
    depth: [P, ps, ps] expected depth of P patches.

  Returns:
    scalar: mean of (d[i, j] - d[i, j+1])^2 + (d[i, j] - d[i+1, j])^2 over the
    (ps - 1)^2 top-left pixels of each patch.
  """
  d00 = depth[:, :-1, :-1]
  return jnp.mean((d00 - depth[:, :-1, 1:])**2 + (d00 - depth[:, 1:, :-1])**2)


def occlusion_loss(density, num_front):
  """FreeNeRF occlusion regularisation: mean density of the first num_front samples.

  Args:
    density: [B, S] densities of one level.
    num_front: samples nearest to the camera that are penalised (FreeNeRF: 20).

  Returns:
    scalar loss.
  """
  return jnp.mean(density[:, :num_front])


def distortion_loss(s_vals, weights):
  """mip-NeRF 360's distortion loss of each ray, in O(S).

  L = sum_{i,j} w_i w_j |m_i - m_j| + 1/3 sum_i w_i^2 (s_{i+1} - s_i), with m_i the
  interval midpoints. The double sum is 2 sum_i w_i (m_i W_i - M_i) with W_i, M_i the
  sums of w_j and w_j m_j over the intervals j < i (the midpoints ascend).

  Args:
    s_vals: [..., S + 1] ascending interval edges, normalised to [0, 1] along the ray
      (mip-NeRF 360's s-distance: (t - near) / (far - near)).
    weights: [..., S] volume-rendering weights.

  Returns:
    [...] the loss of each ray (0 where all weights are 0).
  """
  mids = 0.5 * (s_vals[..., 1:] + s_vals[..., :-1])
  widths = s_vals[..., 1:] - s_vals[..., :-1]
  w_before = jnp.cumsum(weights, axis=-1) - weights
  wm_before = jnp.cumsum(weights * mids, axis=-1) - weights * mids
  inter = 2. * jnp.sum(weights * (mids * w_before - wm_before), axis=-1)
  intra = jnp.sum(weights**2 * widths, axis=-1) / 3.
  return inter + intra


def ray_distortion(t_vals, weights, near, far):
  """Mean distortion loss over rays, with t normalised by each ray's [near, far].

  Args:
    t_vals: [B, S + 1] interval edges. weights: [B, S]. near, far: [B] or [B, 1].

  Returns:
    scalar: mean over the B rays of distortion_loss((t - near) / (far - near), weights);
    a ray with far <= near is normalised by a tiny positive length instead.
  """
  near, far = near.reshape(-1, 1), far.reshape(-1, 1)
  s_vals = (t_vals - near) / jnp.maximum(far - near, 1e-10)
  return jnp.mean(distortion_loss(s_vals, weights))


def near_camera_ray_weight(origins, directions, t_vals, weights, centres, radius):
  """Per ray: the rendering weight within `radius` of any camera centre.

  The few training cameras of a sparse capture can each explain their own pixels with a
  floater just in front of them; a test camera beside one of them then looks through it
  (experiments/results/seed_matched_fox_lego: fox's worst test views).

  Args:
    origins, directions: [B, 3] rays (world space, unnormalised directions as the
      samples use them). t_vals: [B, S+1] interval ends. weights: [B, S].
    centres: [C, 3] camera centres. radius: distance (world units).

  Returns:
    [B]: sum_i w_i [min_c |x_i - c| < radius], x_i the interval midpoints.
  """
  mid = 0.5 * (t_vals[..., 1:] + t_vals[..., :-1])
  pts = origins[..., None, :] + mid[..., None] * directions[..., None, :]
  d2 = jnp.min(jnp.sum((pts[..., None, :] - centres)**2, axis=-1), axis=-1)
  return jnp.sum(weights * (d2 < radius * radius), axis=-1)


def near_camera_weight(origins, directions, t_vals, weights, centres, radius):
  """The near-camera density penalty: the mean over rays of near_camera_ray_weight (0
  when no sample is that near, or radius <= 0); the loss pushes that weight to 0."""
  return jnp.mean(near_camera_ray_weight(origins, directions, t_vals, weights, centres,
                                         radius))
