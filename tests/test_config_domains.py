"""Every Config field has a declared domain (config_domains), and bad values of every
field are refused in one line before any work starts: a property-based test (hypothesis,
derandomised: the same draws every run) binds, through gin as a user would, values
outside each field's domain (wrong type, negative, zero, NaN, inf, huge, empty string,
unknown choice) and values inside it; train.main refuses one bad value per field with
exit 2 and one line, writing no run directory."""
import dataclasses
import importlib.util
import math
import os
import string
import subprocess
import sys

import gin
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

import train
from renerf_jax.config_domains import PSEUDO_TARGETS, Interval, parse_domain, shape_of
from renerf_jax.configs import Config, load_config
from renerf_jax.errors import ConfigError
from renerf_jax.poses import AUGMENTATION_PRESETS

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FIELDS = dataclasses.fields(Config)
# gin has no literal for NaN: a constant stands for it (gin.clear_config keeps constants).
NAN = '%test_config_domains.nan'
gin.constant(NAN[1:], float('nan'))
# Derandomised (the same draws every run), no shrinking: each example draws a value for
# every field, and a failure names the field and the value already.
SETTINGS = settings(derandomize=True, max_examples=12, deadline=None, database=None,
                    phases=(Phase.explicit, Phase.generate),
                    suppress_health_check=list(HealthCheck))
INT_MAX = 2**31 - 1
FLOAT_MAX = 1.7976931348623157e308

# Bindings under which a value inside one field's domain meets every rule between fields
# (config_checks.check_config): the rules are tested on their own in test_configs.py.
CONTEXT = {
    'near': {'far': FLOAT_MAX}, 'piecewise_spacing': {'far': 2.},
    'contraction': {'use_ndc': False}, 'near_camera_loss_mult': {'use_ndc': False},
    'gs_capacity': {'gs_init_points': 1}, 'gs_init_points': {'gs_capacity': INT_MAX},
    'gs_init_views': {'n_input_views': INT_MAX},
    'gs_densify_from_frac': {'gs_densify_until_frac': 1.},
    'gs_densify_until_frac': {'gs_densify_from_frac': 0.},
    'min_deg_point': {'max_deg_point': INT_MAX},
    'mask_threshold': {'mask_signal': 'depth_variance'},
}


def _gin(value) -> str:
  """value as a gin literal (NaN: the constant; inf: 1e999)."""
  if isinstance(value, float) and math.isnan(value):
    return NAN
  if isinstance(value, float) and math.isinf(value):
    return '1e999' if value > 0 else '-1e999'
  if isinstance(value, (tuple, list)):
    return '(' + ''.join(_gin(v) + ', ' for v in value) + ')'
  return repr(value)


def _bindings(f, value, context=()):
  own = {'backbone': 'gaussians'} if f.metadata['backbone'] == 'gaussians' else {}
  own.update(context)
  return [f'Config.{k} = {_gin(v)}' for k, v in own.items()] + [
      f'Config.{f.name} = {_gin(value)}']


# ------------------------------------------------- what lies inside and outside, per field


def _inside_number(kind, interval):
  lo, hi = interval.lo, interval.hi
  if kind is int:
    lo = -INT_MAX if math.isinf(lo) else int(lo) + (0 if interval.lo_closed else 1)
    hi = INT_MAX if math.isinf(hi) else int(hi) - (0 if interval.hi_closed else 1)
    return st.integers(max(lo, -INT_MAX), min(hi, INT_MAX))
  return st.floats(None if math.isinf(lo) else lo, None if math.isinf(hi) else hi,
                   exclude_min=not interval.lo_closed and not math.isinf(lo),
                   exclude_max=not interval.hi_closed and not math.isinf(hi),
                   allow_nan=False, allow_infinity=False)


NAMES = st.text(string.ascii_letters + string.digits + '_-. ', min_size=1, max_size=10)
TEXT = st.text(string.ascii_letters + string.digits + '_-./ ', max_size=10)
RULE_INSIDE = {
    'llff_min_near': st.lists(st.tuples(NAMES, st.floats(0., 1e6, exclude_min=True)),
                              max_size=3).map(tuple),
    'grid_box': st.tuples(st.tuples(*[st.floats(-1e3, 1e3)] * 3),
                          st.tuples(*[st.floats(1e-3, 1e3)] * 3)).map(
                              lambda b: (b[0], tuple(lo + d for lo, d in zip(*b)))),
    'interp_factors': st.one_of(
        st.sampled_from(sorted(AUGMENTATION_PRESETS)),
        st.lists(st.floats(1e-3, 0.999), min_size=1, max_size=4).map(
            lambda v: ','.join(repr(x) for x in v))),
    'pseudo_targets': st.permutations(PSEUDO_TARGETS).flatmap(
        lambda p: st.integers(1, len(p)).map(lambda n: '+'.join(p[:n]))),
    'num_rounds': st.one_of(st.just('auto'), st.integers(0, 2**31 - 1)),
}
RULE_OUTSIDE = {
    'llff_min_near': st.sampled_from([(('fern', -1.),), (('fern', 0.),), (('fern',),),
                                      ((3, 1.),), (('', 1.),), (('fern', float('nan')),),
                                      'fern', 1.5, None]),
    'grid_box': st.sampled_from([((0., 0., 0.), (1., 1., 0.)), ((1., 0., 0.), (0., 1., 1.)),
                                 ((0., 0.), (1., 1.)), ((0., 0., 0.),), 3, None,
                                 ((0., 0., float('nan')), (1., 1., 1.))]),
    'interp_factors': st.sampled_from(['', '0.5,2', '0', '1', 'x', '12x', 3, None]),
    'pseudo_targets': st.sampled_from(['', 'interp+interp', 'views', 'interp+', 'Test', 3,
                                       None]),
    'num_rounds': st.one_of(st.sampled_from(['Auto', 'auto ', '', '2', True, False, 1.0,
                                             None, ('auto',), float('nan')]),
                            st.integers(-2**62, -1), st.integers(2**31, 2**62)),
}


def inside(f):
  """A strategy of values inside field f's declared domain."""
  domain = f.metadata['domain']
  if domain is not None and domain.rule is not None:
    return RULE_INSIDE[f.name]
  kind, length = shape_of(f.type)
  one = _inside_one(kind, domain)
  if length is None:
    return one
  if length == -1:
    return st.lists(one, max_size=3).map(tuple)
  return st.tuples(*[one] * length)


def _inside_one(kind, domain):
  if kind is bool:
    return st.booleans()
  if kind is str:
    return (st.sampled_from(domain.choices) if domain.choices else
            TEXT if domain.text == 'text' else NAMES)
  return st.one_of(*[_inside_number(kind, i) for i in domain.intervals])


def _gaps(intervals):
  """The complement of a union of Intervals, as Intervals."""
  gaps, start, start_closed = [], -math.inf, False
  for i in sorted(intervals, key=lambda i: (i.lo, not i.lo_closed)):
    if start < i.lo or (start == i.lo and start_closed and not i.lo_closed):
      gaps.append(Interval(start, i.lo, start_closed, not i.lo_closed))
    start, start_closed = i.hi, not i.hi_closed
  if start < math.inf:
    gaps.append(Interval(start, math.inf, start_closed, False))
  return gaps


def _outside_number(kind, domain):
  """Numbers of the right type outside the intervals: in each gap between them, its
  ends included (-1 for '>= 0', 0 for '> 0', 1.5 for '[0, 1]')."""
  out = []
  for gap in _gaps(domain.intervals):
    if kind is int:
      lo = -INT_MAX if math.isinf(gap.lo) else int(gap.lo) + (0 if gap.lo_closed else 1)
      hi = INT_MAX if math.isinf(gap.hi) else int(gap.hi) - (0 if gap.hi_closed else 1)
      if lo > hi:
        continue
      ends = [v for v in (lo, hi) if abs(v) < INT_MAX]
    else:
      ends = [v if closed else math.nextafter(v, toward)
              for v, closed, toward in ((gap.lo, gap.lo_closed, math.inf),
                                        (gap.hi, gap.hi_closed, -math.inf))
              if math.isfinite(v)]
    out += [st.sampled_from(ends)] if ends else []
    out.append(_inside_number(kind, gap))
  return st.one_of(*out) if out else st.nothing()


def outside(f):
  """A strategy of values outside field f's declared domain: the wrong type, NaN, inf,
  huge, out of range, empty, an unknown choice."""
  domain = f.metadata['domain']
  if domain is not None and domain.rule is not None:
    return RULE_OUTSIDE[f.name]
  kind, length = shape_of(f.type)
  special = [float('nan'), float('inf'), -float('inf')]
  if kind is bool:
    one = st.sampled_from([0, 1, 'True', '', None, 1.0])
  elif kind is str:
    bad = [0, 1.5, True, None, ('a',)]
    if domain.choices:
      one = st.one_of(st.sampled_from(bad + ['unknown', 'x' + domain.choices[-1]]),
                      NAMES.filter(lambda v: v not in domain.choices))
    else:
      one = st.sampled_from(bad + ([''] if domain.text == 'name' else []))
  else:
    wrong_type = [True, False, 'auto', '', None, ('a',)] + special
    if kind is int:
      wrong_type += [1.5, 2.0]
      huge = st.one_of(st.integers(2**31, 2**62), st.integers(-2**62, -2**31))
    else:
      huge = st.nothing()
    one = st.one_of(st.sampled_from(wrong_type), huge, _outside_number(kind, domain))
  if length is None:
    return one
  good = _inside_one(kind, domain)
  n = 2 if length == -1 else length
  one_bad = st.tuples(st.lists(good, min_size=n - 1, max_size=n - 1), one,
                      st.integers(0, n - 1)).map(lambda t: tuple(t[0][:t[2]]) + (t[1],)
                                                 + tuple(t[0][t[2]:]))
  if length == -1:
    return st.one_of(one_bad, st.sampled_from([3, None, 'x']))
  wrong_length = st.one_of(st.lists(good, min_size=n + 1, max_size=n + 1).map(tuple),
                           st.lists(good, max_size=n - 1).map(tuple))
  return st.one_of(one_bad, wrong_length, st.sampled_from([3, None, 'x']))

# ----------------------------------------------------------------------------- the tests


def test_every_field_declares_a_domain_its_default_lies_in():
  """A field added without a domain fails here (bool fields: their type is the domain)."""
  missing = [f.name for f in FIELDS
             if f.metadata.get('domain') is None and shape_of(f.type)[0] is not bool]
  assert not missing, f'Config fields without a domain (config_domains): {missing}'
  assert len(FIELDS) >= 145
  Config()  # Every default passes its own check.
  with pytest.raises(ValueError, match='not understood'):
    parse_domain('model')  # An `affects` category passed where the domain goes.


def test_the_issues_values_are_refused_in_one_line():
  """Issue 63's values, bound on gin_configs/demo.gin: each refused naming the field."""
  for binding, line in [
      ('Config.num_rounds = -1', "Config.num_rounds=-1 must be an integer >= 0 or 'auto'"),
      ("Config.num_rounds = 'always'",
       "Config.num_rounds='always' must be an integer >= 0 or 'auto'"),
      ('Config.lr_init = -1.0', 'Config.lr_init=-1.0 must be > 0'),
      ('Config.n_input_views = 0', 'Config.n_input_views=0 must be >= 1'),
      ('Config.image_downsample = 0', 'Config.image_downsample=0 must be >= 1'),
      ('Config.batch_size = 0', 'Config.batch_size=0 must be > 0'),
      ('Config.max_steps = 0', 'Config.max_steps=0 must be > 0'),
      ('Config.pseudo_until_frac = 1.5', 'Config.pseudo_until_frac=1.5 must lie in [0, 1]')]:
    with pytest.raises(ConfigError) as e:
      load_config(['demo.gin'], [binding])
    assert str(e.value) == line
  # A threshold above what the mask signal can take would mask nothing.
  samples = load_config(['demo.gin']).num_samples
  for signal, top in [('one_minus_acc', '1'), ('acc', '1'),
                      ('weight_entropy', f'{math.log(samples):.6g}')]:
    with pytest.raises(ConfigError, match=rf'^Config.mask_threshold=2000.0 is above the '
                                          rf"largest value of Config.mask_signal='{signal}', "
                                          rf'{top}: it would mask nothing$'):
      load_config(['demo.gin'], [f"Config.mask_signal = '{signal}'",
                                 'Config.mask_threshold = 2000.0'])
  # laplace's U is a rendered posterior sigma, at most the prior's sqrt(3 / (2 lambda)).
  assert load_config([], ["Config.mask_signal = 'laplace'", 'Config.mask_threshold = 2.0',
                          'Config.hessian_lambda = 1e-4'])
  with pytest.raises(ConfigError, match='122.474'):
    load_config([], ["Config.mask_signal = 'laplace'", 'Config.mask_threshold = 200.0'])
  # depth_variance is unbounded; weight_entropy is in nats, up to log(num_samples).
  assert load_config([], ["Config.mask_signal = 'depth_variance'",
                          'Config.mask_threshold = 1e6'])
  assert load_config([], ["Config.mask_signal = 'weight_entropy'", 'Config.num_samples = 64',
                          'Config.mask_threshold = 4.15'])


OUTSIDE = {f.name: outside(f) for f in FIELDS}
INSIDE = {f.name: inside(f) for f in FIELDS}


@SETTINGS
@given(st.data())
def test_every_field_refuses_values_outside_its_domain(data):
  """For every field (each example draws one value per field), a value outside its
  domain bound through gin is one ConfigError line naming the field."""
  for f in FIELDS:
    value = data.draw(OUTSIDE[f.name], label=f.name)
    with pytest.raises(ConfigError) as e:
      load_config([], _bindings(f, value))
    message = str(e.value)
    assert message.startswith(f'Config.{f.name}=') and '\n' not in message, (
        f.name, value, message)
    assert ' must ' in message, message


@SETTINGS
@given(st.data())
def test_every_field_accepts_values_inside_its_domain(data):
  """For every field, a value inside its domain (with the other fields set so that no
  rule between fields binds: CONTEXT) is taken as given (lists as tuples)."""
  for f in FIELDS:
    value = data.draw(INSIDE[f.name], label=f.name)
    config = load_config([], _bindings(f, value, CONTEXT.get(f.name, {})))
    got = getattr(config, f.name)
    if f.name == 'llff_min_near':  # Only the pair of Config.scene is kept.
      value = tuple((n, v) for n, v in value if n == config.scene)
    assert got == value and type(got) is type(value), (f.name, value, got)


def test_values_gin_cannot_write_are_refused_by_name_too():
  """Config(...) from code: an unhashable list or an arbitrary object in any field is a
  ConfigError naming it (not a TypeError from a comparison)."""
  for f in FIELDS:
    ctx = {'backbone': 'gaussians'} if f.metadata['backbone'] == 'gaussians' else {}
    for value in (object(), [object()]):
      with pytest.raises(ConfigError) as e:
        Config(**ctx, **{f.name: value})
      assert str(e.value).startswith(f'Config.{f.name}='), (f.name, str(e.value))


def _one_bad_value(f):
  """A value outside field f's domain as a user might write it: below the range, an
  unknown choice, a word for a bool, a bare number for a tuple."""
  domain, (kind, length) = f.metadata['domain'], shape_of(f.type)
  if length is not None or (domain is not None and domain.rule is not None):
    return {'interp_factors': '0.5,2', 'num_rounds': 'always'}.get(f.name, 3)
  if kind is bool:
    return 'yes'
  if kind is str:
    return 'unknown' if domain.choices else 7
  lows = [i.lo for i in domain.intervals if math.isfinite(i.lo)]
  return (min(lows) - 1 if kind is int else min(lows) - 0.5) if lows else 'x'


def test_train_refuses_one_bad_value_per_field_in_one_line(tmp_path, capsys):
  """train.main in-process with one bad value per field (on demo.gin, a Gaussians field
  on gaussians_lego8.gin): exit 2, one `error:` line naming the field, no run directory
  made, an existing one unchanged."""
  existing = tmp_path / 'existing'
  existing.mkdir()
  (existing / 'config.json').write_text('{"seed": 0}')
  before = sorted((p.name, p.stat().st_mtime_ns, p.read_bytes()) for p in existing.iterdir())
  for f in FIELDS:
    for run_dir in (tmp_path / 'new', existing):
      base = 'gaussians_lego8' if f.metadata['backbone'] == 'gaussians' else 'demo'
      argv = [f'--gin_configs={base}.gin', f'--run_dir={run_dir}']
      argv += [f'--gin_bindings={b}' for b in _bindings(f, _one_bad_value(f))]
      with pytest.raises(SystemExit) as e:
        train.main(argv)
      err = capsys.readouterr().err
      assert e.value.code == 2, (f.name, err)
      assert err.startswith(f'error: Config.{f.name}=') and err.count('\n') == 1, err
    assert not (tmp_path / 'new').exists()
  assert sorted((p.name, p.stat().st_mtime_ns, p.read_bytes())
                for p in existing.iterdir()) == before


def test_train_py_refuses_auto_rounds_without_validation_views(tmp_path):
  """A real train.py: num_rounds = 'auto' decides on validation views, and demo.gin's
  scene has none: one line, exit 2, no run directory."""
  run_dir = tmp_path / 'run'
  res = subprocess.run([sys.executable, 'train.py', '--gin_configs=gin_configs/demo.gin',
                        "--gin_bindings=Config.num_rounds = 'auto'", f'--run_dir={run_dir}'],
                       cwd=REPO, capture_output=True, text=True, timeout=300, check=False)
  assert res.returncode == 2, res.stderr[-2000:]
  assert res.stderr == ("error: Config.num_rounds='auto' decides on validation views, and "
                        "scene 'orbit' has 0 (Config.val_views=0); set Config.val_views "
                        '>= 2 or an integer Config.num_rounds\n')
  assert res.stdout == '' and not run_dir.exists()


def test_docs_list_every_fields_domain_as_declared():
  """docs/configs.md's domain table is docs/make_configs.py's output (regenerate it with
  python docs/make_configs.py), one row per field."""
  spec = importlib.util.spec_from_file_location(
      'make_configs', os.path.join(REPO, 'docs', 'make_configs.py'))
  make_configs = importlib.util.module_from_spec(spec)
  spec.loader.exec_module(make_configs)
  with open(make_configs.PAGE, encoding='utf-8') as f:
    text = f.read()
  block = make_configs.generated()
  assert make_configs.page_with(text, block) == text, (
      'docs/configs.md is stale: run python docs/make_configs.py')
  rows = [line for line in block.splitlines() if line.startswith('| `')]
  assert [r.split('`')[1] for r in rows] == [f.name for f in FIELDS]
  assert ("| `num_rounds` | renerf | both | int or str | integer >= 0, or 'auto' (decided "
          'on validation views) |') in rows
  assert "| `mask_threshold` | renerf | both | float | -1 or >= 0 |" in rows
