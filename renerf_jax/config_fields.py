"""What each Config field is for: its concern, the backbone reading it, what it changes.

Every field of configs.Config is declared with one of the constructors below (shared,
nerf, gaussians, renerf, report: its concern, `group`), which record in the field's
metadata
  group     the concern it belongs to (GROUPS; docs/configs.md lists the fields by it);
  backbone  who reads it: 'nerf', 'gaussians' or 'both' (BACKBONE_TAGS), found from the
            code (renerf_jax/gaussians is the Gaussians; the datasets, the pseudo-view
            poses, the round driver, evaluation and the run directory serve both);
  affects   what it can change (AFFECTS), read by every rule that decides what may be
            shared or resumed (configs.fields_where);
  domain    the values it may take (config_domains: the constructors' second argument,
            e.g. nerf(4096, '>=1'); a bool field needs none), checked by config_checks.
config_checks refuses a field that the chosen backbone ignores set away from its default;
config_differences (comparing runs) skips such fields. Imports no module of the package
that imports configs.
"""
import dataclasses
from typing import Dict, Tuple

from renerf_jax.config_domains import parse_domain
from renerf_jax.report import to_jsonable

# What a Config field can change, declared once per field (its `affects` category):
#   baseline   round 0: the baseline's parameters or its reported metrics;
#   pseudo     round r's pseudo-views or masks, given model B;
#   hessian    the Hessian pass of the masks, given B and its training rays;
#   render     the pixels of a pseudo-view rendered at a given pose, given B;
#   resumable  may change between invocations on one run directory.
# 'model' (data, model, optimisation, regularisers) changes everything. Round r >= 1
# depends on every field but 'io', 'report', 'rounds' and the chunk sizes' speed (D's
# training: 'd_training').
AFFECTS = {
    'model': ('baseline', 'pseudo', 'hessian', 'render'),
    'report': ('baseline', 'resumable'),  # what is logged and evaluated, not trained
    'io': ('resumable',),  # when checkpoints are written
    'rounds': ('resumable',),  # how many rounds run (each round is the same)
    'd_training': (),  # how D is trained from the pseudo-views
    'pseudo_poses': ('pseudo',),  # which pseudo-views are rendered
    'masks': ('pseudo',),  # whether and how pseudo-view pixels are masked
    'hessian': ('pseudo', 'hessian'),  # the Laplace approximation
    'hessian_chunk': ('pseudo', 'hessian', 'resumable'),  # its summation order
    'render_chunk': ('pseudo', 'render', 'resumable'),  # rendering's batch shapes
}

# The concerns, in the order docs/configs.md lists them: group -> its heading.
GROUPS = {
    'shared': 'Shared (data, split, seeds, steps, the backbone)',
    'nerf': 'NeRF (Config.backbone = \'nerf\')',
    'gaussians': 'Gaussians (Config.backbone = \'gaussians\')',
    'renerf': 'Re-Nerfing (rounds, pseudo-views, masks)',
    'report': 'Evaluation, logging, IO',
}
BACKBONE_TAGS = ('nerf', 'gaussians', 'both')
# How an error message names a backbone's settings.
BACKBONE_NAMES = {'nerf': 'NeRF', 'gaussians': 'Gaussians'}


def field(default, domain=None, affects: str = 'model', backbone: str = 'both',
          group: str = 'shared'):
  """A Config field with its metadata.

  Args:
    default: the default value (immutable: Config is frozen and hashable).
    domain: the values it may take (a spec of config_domains; None: a bool field).
    affects: what it can change (a key of AFFECTS).
    backbone: who reads it ('nerf', 'gaussians' or 'both').
    group: its concern (a key of GROUPS).

  Returns:
    A dataclasses.field.
  """
  assert affects in AFFECTS and backbone in BACKBONE_TAGS and group in GROUPS, (
      affects, backbone, group)
  return dataclasses.field(default=default, metadata={
      'affects': affects, 'backbone': backbone, 'group': group,
      'domain': parse_domain(domain)})


def shared(default, domain=None, affects='model', backbone='both'):
  """A field of the data, the split, the seeds, the steps: both backbones read it."""
  return field(default, domain, affects, backbone, 'shared')


def nerf(default, domain=None, affects='model'):
  """A field of the NeRF backbone (optimiser, sampling, field, regularisers, grid)."""
  return field(default, domain, affects, 'nerf', 'nerf')


def gaussians(default, domain=None, affects='model'):
  """A field of the Gaussians backbone (renerf_jax/gaussians)."""
  return field(default, domain, affects, 'gaussians', 'gaussians')


def renerf(default, domain=None, affects='model', backbone='both'):
  """A field of the Re-Nerfing rounds: pseudo-views, D's training, masks."""
  return field(default, domain, affects, backbone, 'renerf')


def report(default, domain=None, affects='report', backbone='both'):
  """A field of evaluation, logging or checkpoints."""
  return field(default, domain, affects, backbone, 'report')


def fields_with(cls, effect: str, present: bool = True) -> Tuple[str, ...]:
  """Names of the fields of `cls` whose `affects` category has (or, present=False, lacks)
  `effect`.

  Args:
    cls: a dataclass of such fields (configs.Config).
    effect: 'baseline', 'pseudo', 'hessian', 'render' or 'resumable'.
    present: select the fields with the effect (True) or without it (False).

  Returns:
    Field names in declaration order.
  """
  return tuple(f.name for f in dataclasses.fields(cls)
               if (effect in AFFECTS[f.metadata.get('affects', 'model')]) == present)


def field_backbone(cls, name: str) -> str:
  """Who reads field `name` of dataclass `cls`: 'nerf', 'gaussians' or 'both'."""
  return cls.__dataclass_fields__[name].metadata.get('backbone', 'both')


def ignored_by(cls, backbone: str) -> Tuple[str, ...]:
  """Names of the fields of `cls` that `backbone` never reads, in declaration order."""
  return tuple(f.name for f in dataclasses.fields(cls)
               if f.metadata.get('backbone', 'both') not in ('both', backbone))


def fields_by_group(cls) -> Dict[str, Dict[str, Tuple[str, ...]]]:
  """{group: {backbone tag: field names}} of `cls`, groups in GROUPS order."""
  out = {g: {} for g in GROUPS}
  for f in dataclasses.fields(cls):
    by_tag = out[f.metadata.get('group', 'shared')]
    tag = f.metadata.get('backbone', 'both')
    by_tag[tag] = by_tag.get(tag, ()) + (f.name,)
  return out


def _canonical(value):
  """Lists as tuples, recursively (gin's lists equal Config's tuple defaults)."""
  if isinstance(value, (list, tuple)):
    return tuple(_canonical(v) for v in value)
  return value


def ignored_settings(config):
  """[(name, value)] of the fields `config.backbone` ignores that are set away from their
  defaults, in declaration order (empty for an unknown backbone: checked elsewhere)."""
  if not isinstance(config.backbone, str) or config.backbone not in BACKBONE_NAMES:
    return []
  fields = type(config).__dataclass_fields__
  names = ignored_by(type(config), config.backbone)
  return [(name, getattr(config, name)) for name in names
          if _canonical(getattr(config, name)) != _canonical(fields[name].default)]


def config_differences(config, saved: dict, ignore=()) -> list:
  """Names of the fields outside `ignore` in which `config` and a saved config.json
  differ; a field missing from `saved` (added to Config later) counts as its default, and
  a field that config.backbone ignores never differs (it changes nothing of the run; a
  run saved before such settings were refused may hold one, e.g. a Gaussian run's
  anneal_nearfar = False)."""
  current = to_jsonable(dataclasses.asdict(config))
  defaults = to_jsonable(dataclasses.asdict(type(config)()))
  saved = dict({k: v for k, v in defaults.items() if k not in saved}, **saved)
  ignore = set(ignore) | set(ignored_by(type(config), config.backbone))
  return sorted(k for k in set(saved) | set(current)
                if k not in ignore and saved.get(k) != current.get(k))
