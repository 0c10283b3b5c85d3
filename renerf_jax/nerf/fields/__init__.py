"""Field backbones with one interface: (means, covs, viewdirs, feature_mask) -> raw outputs."""
import jax
import jax.numpy as jnp

from renerf_jax.nerf import mip


def make_field(config):
  """The flax module selected by `config.field` (built from static config only)."""
  if config.field == 'mlp':
    from renerf_jax.nerf.fields.mlp import MipMLP  # pylint: disable=g-import-not-at-top
    return MipMLP(net_depth=config.net_depth, net_width=config.net_width,
                  skip_layer=config.skip_layer, net_depth_viewdirs=config.net_depth_viewdirs,
                  net_width_viewdirs=config.net_width_viewdirs,
                  min_deg_point=config.min_deg_point, max_deg_point=config.max_deg_point,
                  deg_view=config.deg_view, use_viewdirs=config.use_viewdirs)
  if config.field == 'grid':
    from renerf_jax.nerf.fields.grid import GridField  # pylint: disable=g-import-not-at-top
    return GridField(num_levels=config.grid_levels, base_res=config.grid_base_res,
                     max_res=config.grid_max_res, num_features=config.grid_features,
                     log2_hashmap_size=config.grid_log2_hashmap_size,
                     mlp_width=config.grid_mlp_width, init_scale=config.grid_init_scale,
                     deg_view=config.deg_view, use_viewdirs=config.use_viewdirs,
                     bbox_lo=tuple(config.grid_box[0]), bbox_hi=tuple(config.grid_box[1]))
  raise ValueError(f'unknown field backbone {config.field!r}')


def frequency_mask(config, fraction):
  """FreeNeRF's coarse-to-fine mask in the field's feature layout.

  MLP: over the IPE bands (expanded to the IPE features); grid: over the grid levels.
  """
  if config.field == 'grid':
    return mip.freq_band_mask(config.grid_levels, fraction)
  return mip.ipe_feature_mask(
      mip.freq_band_mask(config.max_deg_point - config.min_deg_point, fraction))


def init_field_params(config, key):
  """Initial parameters of the configured field.

  Returns:
    flax variables {'params': ...} (initialised with `key`); with Config.sampler =
    'proposal' also 'proposal' (the proposal field's parameters, fields/proposal.py),
    and the two are initialised with the two halves of jax.random.split(key).
  """
  field = make_field(config)
  means = jnp.zeros((1, 2, 3))
  init = lambda k: field.init(k, means, jnp.ones_like(means) * 1e-2,
                              jnp.zeros((1, 3)).at[:, 2].set(-1.))
  if config.sampler != 'proposal':
    return init(key)
  k_field, k_prop = jax.random.split(key)
  params = init(k_field)
  from renerf_jax.nerf.fields.proposal import make_proposal  # pylint: disable=g-import-not-at-top
  return {'params': params['params'],
          'proposal': make_proposal(config).init(k_prop, means)['params']}
