"""The checks every Config passes when it is made (Config.__post_init__ calls them).

One clear line per bad value (errors.ConfigError naming the field), raised before any
work starts; a few fields are also normalised here (lists from gin become tuples).
"""
import math

from renerf_jax.config_fields import BACKBONE_NAMES, field_backbone, ignored_settings
from renerf_jax.errors import ConfigError


def _check(cond: bool, msg: str):
  if not cond:
    raise ConfigError(msg)


def pseudo_steps(config) -> int:
  """K in steps: round(Config.pseudo_until_frac * Config.max_steps)."""
  return int(round(config.pseudo_until_frac * config.max_steps))


def check_backbone_fields(c):
  """Raises ConfigError for the first field that Config c's backbone ignores set away
  from its default (a setting that would silently change nothing).

  Args:
    c: a Config with a valid backbone.
  """
  for name, value in ignored_settings(c):
    owner = BACKBONE_NAMES[field_backbone(type(c), name)]
    raise ConfigError(f'Config.{name}={value!r} is a {owner} setting; '
                      f'Config.backbone={c.backbone!r} ignores it')


def check_config(c):
  """Raises ConfigError for the first bad field of Config c; normalises c in place.

  Args:
    c: a Config being made (frozen: normalised fields are set with object.__setattr__).
  """
  _check(isinstance(c.llff_min_near, (tuple, list)) and all(
      isinstance(p, (tuple, list)) and len(p) == 2 and isinstance(p[0], str)
      and isinstance(p[1], (int, float)) and not isinstance(p[1], bool)
      and math.isfinite(p[1]) and p[1] > 0 for p in c.llff_min_near),
         f'Config.llff_min_near={c.llff_min_near!r} must be (scene name, near > 0) '
         'pairs')
  object.__setattr__(c, 'llff_min_near', tuple(
      (name, float(near)) for name, near in c.llff_min_near if name == c.scene))
  _check(c.backbone in ('nerf', 'gaussians'),
         f'Config.backbone={c.backbone!r} (nerf or gaussians)')
  check_backbone_fields(c)
  _check(c.dataset_loader in ('llff', 'transforms', 'colmap', 'blender', 'procedural',
                              'orbit'),
         f'Config.dataset_loader={c.dataset_loader!r} (llff, transforms, colmap, blender, '
         'procedural or orbit)')
  _check(c.train_view_selection in ('linspace', 'coverage'),
         f'Config.train_view_selection={c.train_view_selection!r} (linspace or coverage)')
  _check(isinstance(c.val_views, int) and c.val_views >= 0,
         f'Config.val_views={c.val_views!r} must be an integer >= 0')
  _check(c.gs_init in ('random', 'sfm'), f'Config.gs_init={c.gs_init!r} (random or sfm)')
  _check(c.test_stride >= 1, f'Config.test_stride={c.test_stride} must be >= 1')
  _check(c.blender_split in ('standard', 'linspace'),
         f'Config.blender_split={c.blender_split!r} (standard or linspace)')
  _check(c.init_seed >= -1, f'Config.init_seed={c.init_seed} must be >= 0 (or -1: seed)')
  _check(c.outside_box in ('clamp', 'empty'),
         f'Config.outside_box={c.outside_box!r} (clamp or empty)')
  _check(c.d_seed in ('offset', 'same_init', 'same'),
         f'Config.d_seed={c.d_seed!r} (offset, same_init or same)')
  _check(not c.piecewise_spacing or c.near < 1. < c.far,
         f'Config.piecewise_spacing needs near < 1 < far, not near={c.near}, '
         f'far={c.far}')
  _check(c.contraction in ('', 'l2', 'inf'),
         f"Config.contraction={c.contraction!r} ('', 'l2' or 'inf')")
  _check(not (c.contraction and c.use_ndc),
         f'Config.contraction={c.contraction!r} is for unbounded scenes, not NDC '
         '(Config.use_ndc=True)')
  _check(c.ray_shape in ('cone', 'cylinder'),
         f'Config.ray_shape={c.ray_shape!r} (cone or cylinder)')
  _check(c.density_activation in ('softplus', 'exp'),
         f'Config.density_activation={c.density_activation!r} (softplus or exp)')
  _check(c.gs_init_points >= 1 and c.gs_capacity >= c.gs_init_points,
         f'Config.gs_capacity={c.gs_capacity} must be >= Config.gs_init_points='
         f'{c.gs_init_points} >= 1')
  _check(0 <= c.gs_init_views <= max(c.n_input_views, 1),
         f'Config.gs_init_views={c.gs_init_views} must lie in [0, Config.n_input_views='
         f'{c.n_input_views}]')
  _check(0. < c.gs_init_opacity < 1.,
         f'Config.gs_init_opacity={c.gs_init_opacity} must lie in (0, 1)')
  _check(c.gs_tile_cap >= 0,
         f'Config.gs_tile_cap={c.gs_tile_cap} must be >= 0 (0: no cap)')
  _check(c.gs_list_capacity >= 1,
         f'Config.gs_list_capacity={c.gs_list_capacity} must be >= 1')
  _check(c.gs_extent >= 0., f'Config.gs_extent={c.gs_extent} must be >= 0')
  for name in ('gs_sh_interval_frac', 'gs_densify_every_frac',
               'gs_opacity_reset_every_frac'):
    _check(getattr(c, name) > 0., f'Config.{name}={getattr(c, name)} must be > 0')
  _check(0. <= c.gs_densify_from_frac <= c.gs_densify_until_frac <= 1.,
         f'Config.gs_densify_from_frac={c.gs_densify_from_frac} and '
         f'gs_densify_until_frac={c.gs_densify_until_frac} must satisfy '
         '0 <= from <= until <= 1')
  for name in ('gs_grad_threshold', 'gs_percent_dense', 'gs_lr_means_init',
               'gs_lr_means_final', 'gs_lr_sh_dc', 'gs_lr_sh_rest', 'gs_lr_opacity',
               'gs_lr_scales', 'gs_lr_quats'):
    _check(getattr(c, name) > 0., f'Config.{name}={getattr(c, name)} must be > 0')
  _check(0. <= c.gs_min_opacity < 1.,
         f'Config.gs_min_opacity={c.gs_min_opacity} must lie in [0, 1)')
  _check(0. <= c.gs_lambda_dssim <= 1.,
         f'Config.gs_lambda_dssim={c.gs_lambda_dssim} must lie in [0, 1]')
  _check(0. <= c.gs_drop_rate < 1.,
         f'Config.gs_drop_rate={c.gs_drop_rate} must lie in [0, 1)')
  _check(len(c.gs_background) == 3,
         f'Config.gs_background={c.gs_background!r} must be an RGB triple')
  _check(c.field in ('mlp', 'grid'), f'Config.field={c.field!r} (mlp or grid)')
  _check(c.sampler in ('coarse_fine', 'proposal'),
         f'Config.sampler={c.sampler!r} (coarse_fine or proposal)')
  _check(c.sampler != 'proposal' or c.num_levels == 2,
         f'Config.sampler=\'proposal\' needs Config.num_levels = 2 (one proposal '
         f'level, then the scene field), got {c.num_levels}')
  _check(c.sampler != 'proposal' or c.stop_level_grad,
         'Config.sampler=\'proposal\' needs Config.stop_level_grad = True (the '
         'proposal is trained by the interlevel loss alone)')
  _check(c.near_camera_loss_mult >= 0. and c.near_camera_radius >= 0.,
         f'Config.near_camera_loss_mult={c.near_camera_loss_mult} and '
         f'near_camera_radius={c.near_camera_radius} must be >= 0')
  _check(c.outside_box == 'clamp' or not c.contraction,
         "Config.outside_box='empty' with Config.contraction: every contracted point is "
         'inside the box already (leave it at clamp)')
  _check(c.near_camera_loss_mult == 0. or not c.use_ndc,
         'Config.near_camera_loss_mult > 0 needs use_ndc = False (camera centres are in '
         'world space)')
  _check(c.distortion_loss_mult >= 0.,
         f'Config.distortion_loss_mult={c.distortion_loss_mult} must be >= 0')
  _check(c.proposal_samples >= 2,
         f'Config.proposal_samples={c.proposal_samples} must be >= 2')
  _check(c.pseudo_source in ('render', 'photo'),
         f'Config.pseudo_source={c.pseudo_source!r} (render or photo)')
  _check(c.pseudo_schedule in ('early', 'all', 'late'),
         f'Config.pseudo_schedule={c.pseudo_schedule!r} (early, all or late)')
  _check(c.renerf_init in ('reset', 'continue'),
         f'Config.renerf_init={c.renerf_init!r} (reset or continue)')
  _check(c.mask_signal in ('laplace', 'one_minus_acc', 'depth_variance',
                              'weight_entropy', 'acc'),
         f'Config.mask_signal={c.mask_signal!r} (laplace, one_minus_acc, '
         'depth_variance, weight_entropy or acc)')
  _check(c.pseudo_mix in ('pixels', 'fraction'),
         f'Config.pseudo_mix={c.pseudo_mix!r} (pixels or fraction)')
  _check(0. <= c.pseudo_frac <= 1.,
         f'Config.pseudo_frac={c.pseudo_frac} must lie in [0, 1]')
  _check(0. <= c.pseudo_until_frac <= 1.,
         f'Config.pseudo_until_frac={c.pseudo_until_frac} must lie in [0, 1] (K as '
         f'a fraction of Config.max_steps)')
  _check(c.max_steps > 0, f'Config.max_steps={c.max_steps} must be > 0')
  _check(0. <= c.lr_decay_start_frac < 1.,
         f'Config.lr_decay_start_frac={c.lr_decay_start_frac} must lie in [0, 1)')
  k = pseudo_steps(c)
  # The NeRF's near/far annealing (the Gaussians have none).
  _check(c.backbone != 'nerf' or c.num_rounds == 0 or c.pseudo_schedule != 'early'
         or not c.anneal_nearfar or k >= min(c.anneal_nearfar_steps, c.max_steps),
         f'Config.pseudo_until_frac={c.pseudo_until_frac} puts K at step {k} of '
         f'{c.max_steps}, before the near/far annealing ends (step '
         f'{c.anneal_nearfar_steps}); raise it to at least '
         f'{min(c.anneal_nearfar_steps, c.max_steps) / c.max_steps:.4f}')
  _check(c.batch_size > 0, f'Config.batch_size={c.batch_size} must be > 0')
  _check(c.num_samples >= 2, f'Config.num_samples={c.num_samples} must be >= 2')
  _check(c.num_levels >= 1, f'Config.num_levels={c.num_levels} must be >= 1')
  _check(c.n_input_views >= 1, f'Config.n_input_views={c.n_input_views} must be >= 1')
  _check(c.far >= c.near, f'Config.far={c.far} < Config.near={c.near}')
  _check(c.factor >= 1, f'Config.factor={c.factor} must be >= 1')
  _check(c.image_downsample >= 1,
         f'Config.image_downsample={c.image_downsample} must be >= 1')
  _check(c.hessian_chunk >= 1, f'Config.hessian_chunk={c.hessian_chunk} must be >= 1')
  _check(c.render_chunk >= 1, f'Config.render_chunk={c.render_chunk} must be >= 1')
