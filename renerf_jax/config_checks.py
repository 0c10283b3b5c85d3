"""The checks every Config passes when it is made (Config.__post_init__ calls them).

One clear line per bad value (errors.ConfigError naming the field), raised before any
work starts: first each field's declared domain (config_domains, derived: check_domains),
then the rules between fields written out here (near <= far, a mask threshold within its
signal's range, K after the annealing, ...). A few fields are also normalised here
(lists from gin become tuples).
"""
import dataclasses
import math

from renerf_jax.config_domains import domain_problem, field_message
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


def check_domains(c):
  """Raises ConfigError for the first field of Config c (in declaration order) whose
  value lies outside its declared domain (config_domains); normalises c's tuple fields
  (gin's lists become tuples: Config is hashable).

  Args:
    c: a Config being made (frozen: normalised fields are set with object.__setattr__).
  """
  for f in dataclasses.fields(c):
    problem, value = domain_problem(f.type, f.metadata.get('domain'), getattr(c, f.name))
    if problem is not None:
      raise ConfigError(field_message(f.name, getattr(c, f.name), problem))
    if value is not getattr(c, f.name):
      object.__setattr__(c, f.name, value)


def signal_upper_bound(c) -> float:
  """The largest value Config c's mask_signal takes (Config.mask_threshold above it would
  mask nothing): 1 for one_minus_acc and acc, log(num_samples) nats for weight_entropy
  (uniform weights over the fine level's samples), the prior sigma sqrt(3 / (2 lambda))
  for laplace (a vertex no ray sees), unbounded for depth_variance."""
  return {'one_minus_acc': 1., 'acc': 1., 'weight_entropy': math.log(c.num_samples),
          'laplace': math.sqrt(3. / (2. * c.hessian_lambda))}.get(c.mask_signal, math.inf)


def check_config(c):
  """Raises ConfigError for the first bad field of Config c; normalises c in place.

  A setting the backbone ignores first (check_backbone_fields), then each field's own
  domain (check_domains), then the rules between fields.

  Args:
    c: a Config being made (frozen: normalised fields are set with object.__setattr__).
  """
  check_backbone_fields(c)
  check_domains(c)
  object.__setattr__(c, 'llff_min_near', tuple(
      (name, float(near)) for name, near in c.llff_min_near if name == c.scene))
  _check(not c.piecewise_spacing or c.near < 1. < c.far,
         f'Config.piecewise_spacing needs near < 1 < far, not near={c.near}, '
         f'far={c.far}')
  _check(not (c.contraction and c.use_ndc),
         f'Config.contraction={c.contraction!r} is for unbounded scenes, not NDC '
         '(Config.use_ndc=True)')
  _check(c.gs_capacity >= c.gs_init_points,
         f'Config.gs_capacity={c.gs_capacity} must be >= Config.gs_init_points='
         f'{c.gs_init_points} >= 1')
  _check(c.gs_init_views <= max(c.n_input_views, 1),
         f'Config.gs_init_views={c.gs_init_views} must lie in [0, Config.n_input_views='
         f'{c.n_input_views}]')
  _check(c.gs_densify_from_frac <= c.gs_densify_until_frac,
         f'Config.gs_densify_from_frac={c.gs_densify_from_frac} and '
         f'gs_densify_until_frac={c.gs_densify_until_frac} must satisfy '
         '0 <= from <= until <= 1')
  _check(c.min_deg_point <= c.max_deg_point,
         f'Config.min_deg_point={c.min_deg_point} must be <= Config.max_deg_point='
         f'{c.max_deg_point}')
  _check(c.sampler != 'proposal' or c.num_levels == 2,
         f'Config.sampler=\'proposal\' needs Config.num_levels = 2 (one proposal '
         f'level, then the scene field), got {c.num_levels}')
  _check(c.sampler != 'proposal' or c.stop_level_grad,
         'Config.sampler=\'proposal\' needs Config.stop_level_grad = True (the '
         'proposal is trained by the interlevel loss alone)')
  _check(c.outside_box == 'clamp' or not c.contraction,
         "Config.outside_box='empty' with Config.contraction: every contracted point is "
         'inside the box already (leave it at clamp)')
  _check(c.near_camera_loss_mult == 0. or not c.use_ndc,
         'Config.near_camera_loss_mult > 0 needs use_ndc = False (camera centres are in '
         'world space)')
  top = signal_upper_bound(c)
  _check(c.mask_threshold <= top,
         f'Config.mask_threshold={c.mask_threshold} is above the largest value of '
         f'Config.mask_signal={c.mask_signal!r}, {top:.6g}: it would mask nothing')
  k = pseudo_steps(c)
  # The NeRF's near/far annealing (the Gaussians have none).
  _check(c.backbone != 'nerf' or c.num_rounds == 0 or c.pseudo_schedule != 'early'
         or not c.anneal_nearfar or k >= min(c.anneal_nearfar_steps, c.max_steps),
         f'Config.pseudo_until_frac={c.pseudo_until_frac} puts K at step {k} of '
         f'{c.max_steps}, before the near/far annealing ends (step '
         f'{c.anneal_nearfar_steps}); raise it to at least '
         f'{min(c.anneal_nearfar_steps, c.max_steps) / c.max_steps:.4f}')
  _check(c.far >= c.near, f'Config.far={c.far} < Config.near={c.near}')
  _check(c.leave_out_view < 0 or c.val_views == 0,
         f'Config.leave_out_view={c.leave_out_view} makes the left-out training view the '
         f'only validation view; set Config.val_views = 0 (not {c.val_views})')
