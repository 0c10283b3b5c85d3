"""Adaptive density control of 3DGS (clone, split, prune, opacity reset) at static shapes.

The scene keeps its fixed capacity: a Gaussian never moves to another slot, pruned ones
become inactive, and new ones (clones, the second half of a split) go into free
(inactive) slots, allocated by an argsort of the candidates by decreasing gradient and a
stable argsort of the free slots by index. When the free slots run out, only the
highest-gradient candidates are densified and the rest are counted as dropped. Every
function here is jittable and keeps every shape and dtype.

Rules of the reference 3DGS (Kerbl et al. 2023, `gaussian_model.py`):
  * stats: for every Gaussian visible in a step (radius > 0), the norm of its view-space
    positional gradient is accumulated and its view count incremented; the mean over the
    views is the densification score. The reference's gradient is with respect to the
    NDC position (pixels / (W / 2), pixels / (H / 2)): `accumulate` rescales the pixel
    gradient the same way, so the reference's thresholds apply.
  * clone: score >= threshold and max scale <= percent_dense * extent: an exact copy.
  * split: score >= threshold and max scale > percent_dense * extent: replaced by two
    samples drawn from the Gaussian, with scales / 1.6 (the original slot holds the
    first sample, a free slot the second).
  * prune (after densifying, over all active slots): opacity < min_opacity, and once
    `prune_big` (after the first opacity reset) max screen radius over the views > 20 px
    or max world scale > 0.1 * extent. (The reference zeroes its max screen radii
    before it prunes, so its screen-size test never fires; here the radii accumulated
    since the last densification are used, as the paper describes.)
  * opacity reset: opacities clamped to <= 0.01 (logit), with the opacity's Adam moments
    zeroed, as the reference replaces the tensor in its optimiser.
New and changed slots start with zero Adam moments (`reset_adam_moments`).
When each of these runs is the densification strategy's (strategy.py).
"""
import flax
import jax
import jax.numpy as jnp
import numpy as np
import optax

from renerf_jax.gaussians import params as params_lib

SPLIT_SCALE = 1.6  # Split children have the scales / (0.8 * 2).
MAX_SCREEN_RADIUS = 20.  # Pixels; prune_big prunes Gaussians larger on screen than this.
MAX_WORLD_SCALE_FRAC = 0.1  # prune_big prunes max scale > this * extent.
RESET_OPACITY = 0.01  # reset_opacity clamps opacities to at most this.


@flax.struct.dataclass
class DensityStats:
  """Per-slot statistics since the last densification; every field is [N] float32."""
  grad_accum: jnp.ndarray  # Sum over visible views of ||d loss / d means2d|| (NDC).
  count: jnp.ndarray  # Views in which the Gaussian was visible (radius > 0).
  max_radii: jnp.ndarray  # Largest screen radius (pixels) over those views.


def init_stats(n):
  """Zero statistics for n slots."""
  return DensityStats(grad_accum=jnp.zeros((n,), jnp.float32),
                      count=jnp.zeros((n,), jnp.float32),
                      max_radii=jnp.zeros((n,), jnp.float32))


def accumulate(stats, grad2d, radius, height, width, on=True):
  """Adds one view's screen-space gradients to the statistics.

  Args:
    stats: DensityStats.
    grad2d: [N, 2] d loss / d means2d in pixels (render's means2d_offset gradient).
    radius: [N] screen radii of the view (0 for culled Gaussians).
    height, width: image size; the gradient is rescaled to NDC units (x W/2, x H/2).
    on: bool (may be traced); False returns `stats` unchanged.

  Returns:
    DensityStats.
  """
  visible = (radius > 0.) & on
  g = grad2d * jnp.array([0.5 * width, 0.5 * height], grad2d.dtype)
  norm = jnp.sqrt(jnp.sum(g * g, axis=-1))
  return DensityStats(
      grad_accum=stats.grad_accum + jnp.where(visible, norm, 0.),
      count=stats.count + visible.astype(jnp.float32),
      max_radii=jnp.where(visible, jnp.maximum(stats.max_radii, radius), stats.max_radii))


def mean_grads(stats):
  """[N] mean gradient norm over the views each slot was visible in (0 if never)."""
  return jnp.where(stats.count > 0., stats.grad_accum / jnp.maximum(stats.count, 1.), 0.)


def densify_and_prune(gaussians, stats, key, grad_threshold, percent_dense, extent,
                      min_opacity, prune_big=False):
  """One densification: clone, split, then prune; new Gaussians fill free slots.

  Args:
    gaussians: params.Gaussians with N slots.
    stats: DensityStats gathered since the last densification.
    key: PRNG key of the split samples.
    grad_threshold: densify slots whose mean NDC gradient is >= this.
    percent_dense: clone/split boundary as a fraction of `extent`.
    extent: scene extent (world units).
    min_opacity: prune opacities below this.
    prune_big: bool (may be traced): also prune by screen and world size.

  Returns:
    (gaussians, reset [N] bool: slots whose Adam moments must be zeroed (new, split
    and pruned slots), info dict of int32 scalars: clone, split, pruned, dropped
    (candidates that found no free slot), active (after)).
  """
  g = gaussians
  n = g.means.shape[0]
  grads = mean_grads(stats)
  max_scale = jnp.max(jnp.exp(g.log_scales), axis=-1)
  cand = g.active & (grads >= grad_threshold)
  small = max_scale <= percent_dense * extent
  free = ~g.active
  n_cand = jnp.sum(cand, dtype=jnp.int32)
  n_free = jnp.sum(free, dtype=jnp.int32)
  take = jnp.minimum(n_cand, n_free)
  # Candidates by decreasing gradient (ties: lower slot first), then everything else.
  order = jnp.argsort(jnp.where(cand, -grads, jnp.inf), stable=True)
  rank = jnp.zeros((n,), jnp.int32).at[order].set(jnp.arange(n, dtype=jnp.int32))
  accepted = cand & (rank < take)
  clone = accepted & small
  split = accepted & ~small
  # Free slots by index, then the active ones.
  free_order = jnp.argsort((~free).astype(jnp.int32), stable=True)
  slot_ok = jnp.arange(n) < take
  target = jnp.where(slot_ok, free_order, n)  # n: dropped by the scatter.
  # Split samples x = mean + R (scale * z), z ~ N(0, I); two per slot.
  rot = params_lib.quat_to_rotmat(g.quats)
  z = jax.random.normal(key, (2, n, 3), g.means.dtype) * jnp.exp(g.log_scales)
  samples = g.means + jnp.einsum('nij,knj->kni', rot, z)
  small_log = g.log_scales - np.log(SPLIT_SCALE).astype(np.float32)
  split_m = split[:, None]
  parent = g.replace(means=jnp.where(split_m, samples[0], g.means),
                     log_scales=jnp.where(split_m, small_log, g.log_scales))
  child = g.replace(means=jnp.where(split_m, samples[1], g.means),
                    log_scales=jnp.where(split_m, small_log, g.log_scales))
  src = order

  def place(p, c):
    return p.at[target].set(c[src], mode='drop')

  new = params_lib.Gaussians(
      means=place(parent.means, child.means),
      log_scales=place(parent.log_scales, child.log_scales),
      quats=place(parent.quats, child.quats),
      opacity_logits=place(parent.opacity_logits, child.opacity_logits),
      sh=place(parent.sh, child.sh),
      active=g.active.at[target].set(True, mode='drop'))
  born = jnp.zeros((n,), bool).at[target].set(True, mode='drop')
  # Prune over the densified set; children have not been seen yet (max radius 0).
  opacity = jax.nn.sigmoid(new.opacity_logits)
  prune = opacity < min_opacity
  radii = jnp.where(born | split, 0., stats.max_radii)  # Both halves of a split are new.
  big = ((radii > MAX_SCREEN_RADIUS) |
         (jnp.max(jnp.exp(new.log_scales), -1) > MAX_WORLD_SCALE_FRAC * extent))
  prune = new.active & (prune | (big & prune_big))
  new = new.replace(active=new.active & ~prune)
  reset = born | split | prune
  info = {'clone': jnp.sum(clone, dtype=jnp.int32),
          'split': jnp.sum(split, dtype=jnp.int32),
          'pruned': jnp.sum(prune, dtype=jnp.int32),
          'dropped': n_cand - take,
          'active': jnp.sum(new.active, dtype=jnp.int32)}
  return new, reset, info


def reset_opacity(gaussians, max_opacity=RESET_OPACITY):
  """Clamps every opacity to at most max_opacity (3DGS's periodic opacity reset)."""
  logit = float(np.log(max_opacity / (1. - max_opacity)))
  return gaussians.replace(opacity_logits=jnp.minimum(gaussians.opacity_logits, logit))


def reset_adam_moments(opt_state, reset, fields=None):
  """Zeroes the Adam moments of the slots in `reset` (new Gaussians start from zero).

  Surviving Gaussians never change slot, so applying a densification's slot mapping to
  an optimiser state is exactly this: keep the moments of unchanged slots, zero those of
  new, split and pruned ones. Works on any optax state that holds ScaleByAdamState
  (plain adam, chains, multi_transform); only arrays with leading dimension N are
  touched, and Adam's step count is kept.

  Args:
    opt_state: optax state whose Adam moments are pytrees of [N, ...] arrays.
    reset: [N] bool.
    fields: optional collection of top-level keys of the moment dicts to reset (e.g.
      {'opacity_logits'}); None resets every key.

  Returns:
    The optax state with the same structure.
  """
  n = reset.shape[0]

  def zero_rows(x):
    if not hasattr(x, 'shape') or x.ndim == 0 or x.shape[0] != n:
      return x
    return jnp.where(reset.reshape((n,) + (1,) * (x.ndim - 1)), jnp.zeros_like(x), x)

  def fix_moment(tree):
    if fields is not None and isinstance(tree, dict):
      return {k: jax.tree_util.tree_map(zero_rows, v) if k in fields else v
              for k, v in tree.items()}
    return jax.tree_util.tree_map(zero_rows, tree)

  def fix(s):
    if isinstance(s, optax.ScaleByAdamState):
      return s._replace(mu=fix_moment(s.mu), nu=fix_moment(s.nu))
    return s

  return jax.tree_util.tree_map(fix, opt_state,
                                is_leaf=lambda s: isinstance(s, optax.ScaleByAdamState))
