"""Proposal sampler field (mip-NeRF 360 / nerfacto): a tiny density-only grid.

With Config.sampler = 'proposal' the first sampling level of model.render_rays asks this
field, not the scene field, where the density is: a few coarse levels of the
multi-resolution grid and one hidden layer of `mlp_width` units, no colour and no view
direction. It is trained only by proposal.interlevel_loss (its weights must bound the
scene field's weights from above), and the scene field is evaluated at the fine samples
only, so the coarse pass costs a fraction of a scene-field pass.
"""
from typing import Tuple

import flax.linen as nn
import jax
import jax.numpy as jnp

from renerf_jax.nerf.fields.grid import grid_features, grid_layout


class ProposalGrid(nn.Module):
  """Grid encoding (levels `base_res` .. `max_res`) -> ReLU layer -> raw density.

  Attributes:
    num_levels, base_res, max_res, num_features, log2_hashmap_size: the grid (as in
      GridField).
    mlp_width: hidden width of the density MLP.
    init_scale: the table is initialised uniform in [-init_scale, init_scale].
    bbox_lo, bbox_hi: the box mapped onto the grid; points outside are clamped.
  """
  num_levels: int = 5
  base_res: int = 16
  max_res: int = 128
  num_features: int = 2
  log2_hashmap_size: int = 17
  mlp_width: int = 16
  init_scale: float = 1e-4
  bbox_lo: Tuple[float, float, float] = (-1., -1., -1.)
  bbox_hi: Tuple[float, float, float] = (1., 1., 1.)

  @nn.compact
  def __call__(self, means):
    """Raw density (before the activation and bias of model.raw_to_outputs).

    Args:
      means: [..., S, 3] sample positions.

    Returns:
      [..., S] raw density.
    """
    layout = grid_layout(self.num_levels, self.base_res, self.max_res,
                         self.log2_hashmap_size)
    scale = self.init_scale
    table = self.param(
        'table', lambda k, s: jax.random.uniform(k, s, jnp.float32, -scale, scale),
        (layout.total, self.num_features))
    feats = grid_features(table, layout, self.log2_hashmap_size, means, self.bbox_lo,
                          self.bbox_hi)
    feats = feats.reshape(feats.shape[:-2] + (-1,))
    dense = lambda n, name: nn.Dense(n, kernel_init=jax.nn.initializers.glorot_uniform(),
                                     name=name)
    hidden = nn.relu(dense(self.mlp_width, 'hidden')(feats))
    return dense(1, 'out')(hidden)[..., 0]


def make_proposal(config) -> ProposalGrid:
  """The proposal field of `config` (its box is the scene grid's, Config.grid_box)."""
  return ProposalGrid(num_levels=config.proposal_levels, base_res=config.grid_base_res,
                      max_res=config.proposal_max_res,
                      num_features=config.grid_features,
                      log2_hashmap_size=config.proposal_log2_hashmap_size,
                      mlp_width=config.proposal_mlp_width,
                      init_scale=config.grid_init_scale,
                      bbox_lo=tuple(config.grid_box[0]), bbox_hi=tuple(config.grid_box[1]))


def outer_weights(t, t_env, w_env):
  """The largest weight the histogram (t_env, w_env) puts on each interval of t.

  For interval [t_i, t_{i+1}] it is the sum of w_env over every env interval that
  overlaps it (mip-NeRF 360's `outer` measure): a histogram that bounds the scene
  field's weights from above has outer_weights(t, t_env, w_env) >= w on every interval.

  Args:
    t: [..., N + 1] sorted edges. t_env: [..., M + 1] sorted edges. w_env: [..., M] >= 0.

  Returns:
    [..., N] outer weights.
  """
  cum = jnp.concatenate([jnp.zeros_like(w_env[..., :1]), jnp.cumsum(w_env, axis=-1)],
                        axis=-1)
  m = t_env.shape[-1]
  flat_env = t_env.reshape(-1, m)
  flat_t = t.reshape(-1, t.shape[-1])
  # lo: the last env edge <= t_i; hi: the first env edge > t_{i+1}. hi(t_{i+1}) >
  # lo(t_i) for sorted t, so the outer weights are >= 0 even with repeated edges.
  hi = jax.vmap(lambda e, v: jnp.searchsorted(e, v, side='right'))(flat_env, flat_t)
  lo = jnp.clip(hi - 1, 0, m - 1).reshape(t.shape)
  hi = jnp.clip(hi, 0, m - 1).reshape(t.shape)
  cum_lo = jnp.take_along_axis(cum, lo, axis=-1)
  cum_hi = jnp.take_along_axis(cum, hi, axis=-1)
  return cum_hi[..., 1:] - cum_lo[..., :-1]


def interlevel_loss(t, w, t_env, w_env, eps=1e-7):
  """mip-NeRF 360's proposal loss: mean over rays of sum_i max(0, w_i - outer_i)^2 / w_i.

  The sum over the N scene-field intervals makes it N times mip-NeRF 360's mean over
  rays and intervals; the proposal gets no other gradient and the optimiser's clipping
  leaves it out (training.make_optimizer), so with Adam the scale hardly matters.
  Gradients flow only into the proposal's weights w_env (t, w are the scene field's
  histogram and are treated as constants; t_env does not depend on parameters).

  Args:
    t: [..., N + 1] scene-field edges. w: [..., N] its weights.
    t_env: [..., M + 1] proposal edges. w_env: [..., M] proposal weights.
    eps: keeps the division finite where w = 0 (those terms are 0).

  Returns:
    scalar loss (0 when the proposal bounds the scene field everywhere).
  """
  t, w = jax.lax.stop_gradient(t), jax.lax.stop_gradient(w)
  outer = outer_weights(t, t_env, w_env)
  excess = jnp.maximum(0., w - outer)
  return jnp.mean(jnp.sum(excess**2 / (w + eps), axis=-1))
