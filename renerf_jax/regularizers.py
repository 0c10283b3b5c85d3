"""RegNeRF and FreeNeRF regularisers and their schedules (pure functions).

RegNeRF: depth smoothness (L2 total variation of the expected depth) on patches rendered
from random unobserved poses, with a log-linearly decaying weight, and sample-space
annealing of the [near, far] interval. FreeNeRF: frequency regularisation (see
mip.freq_band_mask) and occlusion regularisation. RegNeRF's colour-likelihood (flow) loss
is left out: it is off in llff3.gin and its flow model was never released.
"""
import jax.numpy as jnp


def log_lerp(step, start, end, max_steps):
  """exp((1 - t) log(start) + t log(end)), t = clip(step / max_steps, 0, 1)."""
  t = jnp.clip(step / max(max_steps, 1), 0., 1.)
  return jnp.exp(jnp.log(start) * (1. - t) + jnp.log(end) * t)


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
