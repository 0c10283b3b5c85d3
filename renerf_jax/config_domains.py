"""Each Config field's domain: the values it may take, declared once beside its backbone
tag (the second argument of config_fields' constructors, e.g. `nerf(4096, '>=1')`).

A field's type is its annotation in configs.Config; its domain spec says which values of
that type are allowed:
  '>=1', '>0', '[0,1)', '(0,1]', 'any'   numbers: an interval ('any': every finite
                                        number); '-1|>=0': a sentinel value or an interval
  'cone|cylinder', ('', 'l2', 'inf')     strings: one of these choices
  'text', 'name'                         strings: any string / a non-empty one
  Rule(check, 'text')                    a rule of its own: check(value) says what is
                                         wrong (None: nothing), 'text' is what docs show
  None                                   bool fields only: True or False
Every number must be finite; an int field takes integers only (not True / False, not
2.0) within +-2^31 (int32, what jax's arrays hold); a float field takes ints too. A tuple
field (Tuple[int, int], Tuple[str, ...]) takes a tuple or a list (made a tuple) of its
length whose every element lies in the domain. config_checks derives the checks from the
domains (domain_problem), docs/configs.md lists them (docs/make_configs.py: describe) and
tests/test_config_domains.py draws values outside and inside each. Imports no module of
the package.
"""
import dataclasses
import math
import numbers
import re
import typing
from typing import Callable, Optional, Tuple

INT_LIMIT = 2**31  # |int fields| < this: int32, what jax's arrays and seeds hold.
_ONE_SIDED = re.compile(r'^(>=|>|<=|<)(-?[\d.e+-]+)$')
_TWO_SIDED = re.compile(r'^([\[(])(-?[\d.e+-]+),(-?[\d.e+-]+)([\])])$')


@dataclasses.dataclass(frozen=True)
class Rule:
  """A domain that no interval or choice list says: check(value) is what is wrong with
  value (a phrase after 'must be', e.g. "(scene name, near > 0) pairs"), else None."""
  check: Callable[[object], Optional[str]]
  text: str


@dataclasses.dataclass(frozen=True)
class Interval:
  """lo .. hi, each end closed or open (a single value: lo = hi, both closed)."""
  lo: float
  hi: float
  lo_closed: bool = True
  hi_closed: bool = True

  def __contains__(self, v) -> bool:
    return ((self.lo < v or (self.lo_closed and v == self.lo))
            and (v < self.hi or (self.hi_closed and v == self.hi)))

  def __str__(self) -> str:
    fmt = lambda v: f'{v:g}'
    if self.lo == self.hi:
      return fmt(self.lo)
    if math.isinf(self.hi):
      return ('>= ' if self.lo_closed else '> ') + fmt(self.lo)
    if math.isinf(self.lo):
      return ('<= ' if self.hi_closed else '< ') + fmt(self.hi)
    return (f'in {"[" if self.lo_closed else "("}{fmt(self.lo)}, {fmt(self.hi)}'
            f'{"]" if self.hi_closed else ")"}')


@dataclasses.dataclass(frozen=True)
class Domain:
  """A parsed domain spec (module docstring): exactly one of its parts is set (none for
  a bool field)."""
  spec: object = None  # As declared.
  intervals: Tuple[Interval, ...] = ()  # Numbers: the union of these.
  choices: Tuple[str, ...] = ()  # Strings: one of these.
  text: str = ''  # Strings: 'text' (any) or 'name' (non-empty).
  rule: Optional[Rule] = None


def parse_domain(spec) -> Optional[Domain]:
  """The Domain of a spec (module docstring); None for None (a bool field, or a field
  whose domain is not declared: tests/test_config_domains.py refuses the latter).

  Raises:
    ValueError: a spec that is none of the forms.
  """
  if spec is None:
    return None
  if isinstance(spec, Rule):
    return Domain(spec, rule=spec)
  if isinstance(spec, tuple) and all(isinstance(c, str) for c in spec) and len(spec) > 1:
    return Domain(spec, choices=spec)
  if not isinstance(spec, str) or not spec.strip():
    raise ValueError(f'Config field domain {spec!r}: see renerf_jax/config_domains.py')
  if spec in ('text', 'name'):
    return Domain(spec, text=spec)
  parts = [p.strip() for p in spec.replace(' ', '').split('|')]
  intervals = [_interval(p) for p in parts]
  if all(intervals):
    return Domain(spec, intervals=tuple(intervals))
  if len(parts) > 1 and all(re.fullmatch(r'[\w.+-]*', p) for p in parts):
    return Domain(spec, choices=tuple(parts))
  raise ValueError(f"Config field domain {spec!r} is not understood (the constructors "
                   "take (default, domain, affects): see renerf_jax/config_domains.py)")


def _interval(part: str) -> Optional[Interval]:
  """The Interval a spec part says ('>=1', '[0,1)', 'any', '-1'), or None."""
  if part == 'any':
    return Interval(-math.inf, math.inf, False, False)
  m = _ONE_SIDED.match(part)
  try:
    if m:
      op, v = m.group(1), float(m.group(2))
      return (Interval(v, math.inf, op == '>=', False) if op[0] == '>' else
              Interval(-math.inf, v, False, op == '<='))
    m = _TWO_SIDED.match(part)
    if m:
      return Interval(float(m.group(2)), float(m.group(3)), m.group(1) == '[',
                      m.group(4) == ']')
    v = float(part)
    return Interval(v, v)
  except ValueError:
    return None


def shape_of(annotation):
  """(element type, length) of a field's annotation: (int, None) for int, (int, 2) for
  Tuple[int, int], (str, -1) for Tuple[str, ...]; (None, None) for nested tuples (their
  domain is a Rule)."""
  if typing.get_origin(annotation) not in (tuple, typing.Tuple):
    return annotation, None
  args = typing.get_args(annotation)
  if len(args) == 2 and args[1] is Ellipsis:
    return (args[0], -1) if args[0] in (int, float, str, bool) else (None, None)
  if len(set(args)) == 1 and args[0] in (int, float, str, bool):
    return args[0], len(args)
  return None, None


def _range_text(intervals) -> str:
  text = ' or '.join(str(i) for i in intervals)
  return 'finite' if text == '> -inf' else text


def element_text(kind, domain: Optional[Domain]) -> str:
  """What one value of type `kind` in `domain` is, e.g. 'an integer >= 1'."""
  if kind is bool:
    return 'True or False'
  if domain is None:
    return {int: 'an integer', float: 'a number', str: 'a string'}.get(kind, 'a value')
  if domain.choices:
    return 'one of ' + ', '.join(repr(c) for c in domain.choices)
  if domain.text:
    return 'a string' if domain.text == 'text' else 'a non-empty string'
  if domain.rule is not None:
    return domain.rule.text
  noun = 'an integer' if kind is int else 'a finite number'
  rng = _range_text(domain.intervals)
  return noun if rng == 'finite' else f'{noun} {rng}'


def describe(annotation, domain: Optional[Domain]) -> str:
  """The domain as docs/configs.md and the error messages say it."""
  kind, length = shape_of(annotation)
  if length is None:
    return element_text(kind, domain)
  what = element_text(kind, domain)
  count = 'any number of' if length == -1 else f'{length}'
  return f'a tuple of {count} values, each {what}'


def values_text(domain: Optional[Domain], kind=None) -> str:
  """A domain in a few words for docs/configs.md: '>= 1', 'in [0, 1)', "'cone', 'cylinder'",
  'any', 'non-empty', a Rule's text, 'True, False' (bool, domain None)."""
  if domain is None:
    return 'True, False' if kind is bool else '(none declared)'
  if domain.choices:
    return ', '.join(repr(c) for c in domain.choices)
  if domain.text:
    return 'any' if domain.text == 'text' else 'non-empty'
  if domain.rule is not None:
    return domain.rule.text
  return _range_text(domain.intervals)


def _element_problem(kind, domain: Optional[Domain], v) -> Optional[str]:
  """Why v is not a value of type kind in domain (a phrase after 'must be'), or None."""
  if kind is bool:
    return None if isinstance(v, bool) else 'True or False'
  if kind in (int, float):
    want = numbers.Integral if kind is int else numbers.Real
    if isinstance(v, bool) or not isinstance(v, want):
      return element_text(kind, domain)
    if not math.isfinite(v):
      return element_text(kind, domain)
    if kind is int and not -INT_LIMIT < v < INT_LIMIT:
      return f'{element_text(kind, domain)}, |value| < 2^31 (int32)'
    if domain is not None and not any(v in i for i in domain.intervals):
      return _range_text(domain.intervals)
    return None
  if kind is str:
    if not isinstance(v, str):
      return element_text(kind, domain)
    if domain is None or domain.text == 'text':
      return None
    if domain.text == 'name':
      return None if v else 'a non-empty string'
    return None if v in domain.choices else element_text(kind, domain)
  return None


def domain_problem(annotation, domain: Optional[Domain], value):
  """(problem, value): problem is None when value lies in the field's domain, else the
  phrase after 'must be' (after 'must lie' when it starts with 'in '); value is value
  normalised (lists from gin become tuples).

  Args:
    annotation: the field's type annotation. domain: its Domain (None: bool, or none
      declared). value: the field's value.
  """
  if domain is not None and domain.rule is not None:
    value = _as_tuples(value)
    return domain.rule.check(value), value
  kind, length = shape_of(annotation)
  if length is None:
    return _element_problem(kind, domain, value), value
  if not isinstance(value, (tuple, list)) or (length >= 0 and len(value) != length):
    return describe(annotation, domain), value
  value = tuple(value)
  bad = [v for v in value if _element_problem(kind, domain, v) is not None]
  return (describe(annotation, domain) if bad else None), value


def _as_tuples(value):
  """Lists as tuples, recursively (gin's lists; Config is hashable)."""
  if isinstance(value, (tuple, list)):
    return tuple(_as_tuples(v) for v in value)
  return value


def field_message(name: str, value, problem: str) -> str:
  """The one line of a value outside its domain."""
  verb = 'must lie' if problem.startswith('in ') else 'must be'
  return f'Config.{name}={value!r} {verb} {problem}'


# ------------------------------------------------ the fields that need rules of their own


def _is_number(v) -> bool:
  return (isinstance(v, numbers.Real) and not isinstance(v, bool)
          and math.isfinite(v))


def _min_near_problem(v):
  ok = isinstance(v, tuple) and all(
      isinstance(p, tuple) and len(p) == 2 and isinstance(p[0], str) and p[0]
      and _is_number(p[1]) and p[1] > 0 for p in v)
  return None if ok else '(scene name, near > 0) pairs'


def _box_problem(v):
  ok = (isinstance(v, tuple) and len(v) == 2
        and all(isinstance(c, tuple) and len(c) == 3 and all(map(_is_number, c)) for c in v)
        and all(lo < hi for lo, hi in zip(*v)))
  return None if ok else '((x, y, z) low, (x, y, z) high) corners with low < high'


def _factors_problem(v):
  from renerf_jax.poses import resolve_factors  # pylint: disable=g-import-not-at-top
  if not isinstance(v, str) or not v.strip():
    return "a preset name ('7x') or comma-separated factors in (0, 1)"
  try:
    resolve_factors(v)
  except ValueError as e:
    return f"a preset name ('7x') or comma-separated factors in (0, 1) ({e})"
  return None


PSEUDO_TARGETS = ('interp', 'test', 'random', 'unused')


def _targets_problem(v):
  parts = v.split('+') if isinstance(v, str) else None
  if parts and len(set(parts)) == len(parts) and set(parts) <= set(PSEUDO_TARGETS):
    return None
  return f"one of {', '.join(PSEUDO_TARGETS)} or a '+' combination of them, each once"


def _num_rounds_problem(v):
  ok = (v == 'auto' if isinstance(v, str) else
        isinstance(v, int) and not isinstance(v, bool) and 0 <= v < INT_LIMIT)
  return None if ok else "an integer >= 0 or 'auto'"


NUM_ROUNDS = Rule(_num_rounds_problem, "integer >= 0, or 'auto' (decided on validation "
                  'views)')
MIN_NEAR = Rule(_min_near_problem, '(scene name, near > 0) pairs')
BOX = Rule(_box_problem, '(low corner, high corner), low < high on each axis')
FACTORS = Rule(_factors_problem, "a preset ('2x' .. '11x') or factors in (0, 1), "
               "e.g. '0.25,0.5'")
TARGETS = Rule(_targets_problem, "'+' combination of interp, test, random, unused")
