"""The mip-NeRF MLP field: IPE of the sample Gaussians -> raw density and colour."""
from typing import Optional

import flax.linen as nn
import jax
import jax.numpy as jnp

from renerf_jax.nerf import mip


class MipMLP(nn.Module):
  """mip-NeRF MLP: net_depth x net_width ReLU layers, input re-injected after every
  skip_layer layers, a density head, and a view branch (bottleneck + encoded direction)."""
  net_depth: int = 8
  net_width: int = 256
  skip_layer: int = 4
  net_depth_viewdirs: int = 1
  net_width_viewdirs: int = 128
  min_deg_point: int = 0
  max_deg_point: int = 16
  deg_view: int = 4
  use_viewdirs: bool = True

  @nn.compact
  def __call__(self, means, covs, viewdirs, feature_mask: Optional[jnp.ndarray] = None):
    """Evaluates the field.

    Args:
      means, covs: [..., S, 3] sample Gaussians.
      viewdirs: [..., 3] unit viewing directions.
      feature_mask: optional [F] multiplier of the IPE features (FreeNeRF).

    Returns:
      (raw_rgb [..., S, 3], raw_density [..., S]).
    """
    dense = lambda n: nn.Dense(n, kernel_init=jax.nn.initializers.glorot_uniform())
    inputs = mip.integrated_pos_enc(means, covs, self.min_deg_point, self.max_deg_point)
    if feature_mask is not None:
      inputs = inputs * feature_mask
    x = inputs
    for i in range(self.net_depth):
      x = nn.relu(dense(self.net_width)(x))
      if i % self.skip_layer == 0 and i > 0:
        x = jnp.concatenate([x, inputs], axis=-1)
    raw_density = dense(1)(x)[..., 0]
    if self.use_viewdirs:
      enc = mip.pos_enc(viewdirs, 0, self.deg_view, append_identity=True)
      enc = jnp.broadcast_to(enc[..., None, :], x.shape[:-1] + enc.shape[-1:])
      x = jnp.concatenate([dense(self.net_width)(x), enc], axis=-1)
      for _ in range(self.net_depth_viewdirs):
        x = nn.relu(dense(self.net_width_viewdirs)(x))
    raw_rgb = dense(3)(x)
    return raw_rgb, raw_density
