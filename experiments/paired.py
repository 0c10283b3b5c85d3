"""Paired statistics of a table row against a control (issue 49): is a gain shown?

A row (e.g. R1) and a control (e.g. "D's seed, no pseudo-views") are paired by
(scene, seed); the deltas d_i = row_i - control_i are summarised by their mean +- std,
the pairs the row wins, a two-sided paired t-test p-value (H0: mean delta 0) and a
paired bootstrap 95% interval of the mean delta (percentile method, a fixed seed so a
table is reproducible). A gain counts as shown only when that interval excludes 0 and
the t-test agrees (p < 0.05): with few pairs the percentile interval is too narrow (five
positive deltas exclude 0 from every resample, whatever their spread), so it alone would
call 1.58, 0.70, 0.11, 0.10, 0.23 dB a gain although p = 0.13.

A table compares many rows, so its p-values are Holm-adjusted over each family of
comparisons it makes (issue 62; holm_adjust, adjust_family): the rows compared with one
reference in one metric of one table. Then "shown" = the (unadjusted) interval excludes
0 and the Holm p < 0.05; a lone comparison is a family of one (Holm p = p). Intervals stay
unadjusted. A claim about spread (one config's runs agree better than another's) is a
two-sided F-test of the two variances (f_test).

Pure numpy, no scipy: Student's t tail is the regularised incomplete beta function,
evaluated with Lentz's continued fraction.
"""
import math

import numpy as np

BOOT_RESAMPLES = 10000
BOOT_SEED = 0
ALPHA = 0.05  # the t-test's level (and 1 - the interval's coverage)


def _beta_cf(a, b, x, max_iter=500, eps=1e-15):
  """Continued fraction of the incomplete beta function (modified Lentz)."""
  tiny = 1e-300
  qab, qap, qam = a + b, a + 1., a - 1.
  c, d = 1., 1. - qab * x / qap
  d = 1. / (d if abs(d) > tiny else tiny)
  h = d
  for m in range(1, max_iter + 1):
    m2 = 2 * m
    aa = m * (b - m) * x / ((qam + m2) * (a + m2))
    d = 1. + aa * d
    d = 1. / (d if abs(d) > tiny else tiny)
    c = 1. + aa / c
    c = c if abs(c) > tiny else tiny
    h *= d * c
    aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))
    d = 1. + aa * d
    d = 1. / (d if abs(d) > tiny else tiny)
    c = 1. + aa / c
    c = c if abs(c) > tiny else tiny
    delta = d * c
    h *= delta
    if abs(delta - 1.) < eps:
      break
  return h


def betainc(a: float, b: float, x: float) -> float:
  """The regularised incomplete beta function I_x(a, b), a, b > 0, 0 <= x <= 1."""
  if not (a > 0 and b > 0):
    raise ValueError(f'betainc needs a, b > 0 (got {a}, {b})')
  if not 0. <= x <= 1.:
    raise ValueError(f'betainc needs 0 <= x <= 1 (got {x})')
  if x in (0., 1.):
    return float(x)
  log_front = (math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b)
               + a * math.log(x) + b * math.log1p(-x))
  if x < (a + 1.) / (a + b + 2.):
    return math.exp(log_front) * _beta_cf(a, b, x) / a
  return 1. - math.exp(log_front) * _beta_cf(b, a, 1. - x) / b


def t_two_sided_p(t: float, df: float) -> float:
  """P(|T| >= |t|) for Student's t with df degrees of freedom."""
  if df <= 0:
    raise ValueError(f'df must be > 0 (got {df})')
  if math.isinf(t):
    return 0.
  return betainc(0.5 * df, 0.5, df / (df + t * t))


def f_cdf(x: float, d1: float, d2: float) -> float:
  """P(F <= x) for Fisher's F with (d1, d2) degrees of freedom."""
  if not (d1 > 0 and d2 > 0):
    raise ValueError(f'f_cdf needs d1, d2 > 0 (got {d1}, {d2})')
  if x <= 0.:
    return 0.
  if math.isinf(x):
    return 1.
  return betainc(0.5 * d1, 0.5 * d2, d1 * x / (d1 * x + d2))


def f_test(a, b) -> dict:
  """Two-sided F-test of equal variances of two independent samples (e.g. one config's
  runs over seeds against another's): is one spread shown to be smaller?

  Args:
    a, b: the two samples (at least 2 values each).

  Returns:
    {'std_a', 'std_b' (ddof 1), 'n_a', 'n_b', 'ratio' (var a / var b), 'p' (two-sided:
    2 min(P(F <= ratio), P(F >= ratio)), capped at 1), 'shown' (p < ALPHA)}.
  """
  a, b = (np.asarray(v, np.float64) for v in (a, b))
  if a.ndim != 1 or b.ndim != 1 or a.size < 2 or b.size < 2:
    raise ValueError(f'f_test needs two lists of at least 2 values (got {a.size}, {b.size})')
  va, vb = float(a.var(ddof=1)), float(b.var(ddof=1))
  if va == vb == 0.:
    ratio, p = 1., 1.
  else:
    ratio = va / vb if vb > 0. else math.inf
    cdf = f_cdf(ratio, a.size - 1, b.size - 1)
    p = min(1., 2. * min(cdf, 1. - cdf))
  return {'std_a': math.sqrt(va), 'std_b': math.sqrt(vb), 'n_a': int(a.size),
          'n_b': int(b.size), 'ratio': ratio, 'p': p, 'shown': bool(p < ALPHA)}


def holm_adjust(pvalues):
  """Holm's step-down adjustment of a family of p-values (None entries are skipped).

  The k-th smallest of the m p-values becomes max over j <= k of min(1, (m - j + 1) p_(j)):
  rejecting where the adjusted p < alpha keeps the chance of any false rejection in the
  family below alpha, whatever the dependence between the tests.

  Returns:
    The adjusted p-values in the order given (None where the input is None).
  """
  idx = [i for i, p in enumerate(pvalues) if p is not None]
  m = len(idx)
  out = [None] * len(pvalues)
  running = 0.
  for rank, i in enumerate(sorted(idx, key=lambda i: pvalues[i])):
    running = max(running, min(1., (m - rank) * float(pvalues[i])))
    out[i] = running
  return out


def adjust_family(summaries, better: float = 1.):
  """Holm-adjusts the p-values of one family of paired_summary results in place: each
  gets 'p_holm' and 'family' (m, the comparisons with a p-value), and its 'shown' /
  'loss_shown' are decided on p_holm. Summaries without a p-value (one pair) are left
  as they are.

  Args:
    summaries: the paired_summary dicts of the family (e.g. every row against B in PSNR).
    better: as in paired_summary.
  """
  summaries = [s for s in summaries if s and s.get('p') is not None]
  for s, p_holm in zip(summaries, holm_adjust([s['p'] for s in summaries])):
    s['p_holm'], s['family'] = p_holm, len(summaries)
    _decide(s, p_holm, better)
  return summaries


def _decide(s, p, better):
  """'shown' / 'loss_shown' of a summary with an interval, at p-value p."""
  lo, hi = s['ci']
  above, below = lo > 0., hi < 0.  # the interval excludes 0 on one side
  significant = p < ALPHA
  s['shown'] = bool(significant and (above if better > 0 else below))
  s['loss_shown'] = bool(significant and (below if better > 0 else above))


def bootstrap_interval(deltas, level=0.95, resamples=BOOT_RESAMPLES, seed=BOOT_SEED):
  """Percentile interval of the mean of `deltas` over paired bootstrap resamples.

  Args:
    deltas: [n] paired differences (n >= 1).
    level: the interval's coverage. resamples: bootstrap draws. seed: their rng seed.

  Returns:
    (low, high).
  """
  d = np.asarray(deltas, np.float64)
  rng = np.random.default_rng(seed)
  means = d[rng.integers(0, d.size, (resamples, d.size))].mean(axis=1)
  tail = 50. * (1. - level)
  return float(np.percentile(means, tail)), float(np.percentile(means, 100. - tail))


def paired_summary(deltas, better: float = 1.) -> dict:
  """Everything a table says of one row against one control.

  Args:
    deltas: [n] row minus control, one per (scene, seed) pair.
    better: +1 when a larger value is better (PSNR, SSIM), -1 when smaller is (LPIPS).

  Returns:
    {'mean', 'std' (ddof 1; 0 for one pair), 'wins' (pairs where the row is better),
    'n', 'p' (two-sided paired t-test; None for fewer than 2 pairs), 'ci' ([low, high]
    bootstrap 95% interval of the mean; None for fewer than 2 pairs), 'shown' (a gain
    is shown: the interval excludes 0 on the better side and p < ALPHA), 'loss_shown'
    (the same on the worse side)}. In a table, adjust_family then replaces p by its Holm
    adjustment in that rule ('p_holm', 'family').
  """
  d = np.asarray(deltas, np.float64)
  if d.ndim != 1 or d.size == 0:
    raise ValueError(f'paired_summary needs a non-empty list of deltas (got shape {d.shape})')
  if not np.all(np.isfinite(d)):
    raise ValueError(f'paired_summary: non-finite delta in {d.tolist()}')
  n = int(d.size)
  mean = float(d.mean())
  std = float(d.std(ddof=1)) if n > 1 else 0.
  out = {'mean': mean, 'std': std, 'wins': int(np.sum(better * d > 0)), 'n': n,
         'p': None, 'ci': None, 'shown': False, 'loss_shown': False}
  if n < 2:
    return out
  if std == 0.:
    p = 1. if mean == 0. else 0.
  else:
    p = t_two_sided_p(mean / (std / math.sqrt(n)), n - 1)
  out.update(p=p, ci=list(bootstrap_interval(d)))
  _decide(out, p, better)
  return out


def format_cell(s: dict, digits: int = 2) -> str:
  """'+0.80 +- 0.74 (3/3), p 0.21, Holm 0.42, [-0.05, +1.50]'; bold when a gain is shown
  (the Holm p is given where the summary was adjusted in a family)."""
  if not s:
    return ''
  text = f"{s['mean']:+.{digits}f} +- {s['std']:.{digits}f} ({s['wins']}/{s['n']})"
  if s['p'] is not None:
    lo, hi = s['ci']
    holm = f", Holm {s['p_holm']:.2g}" if s.get('p_holm') is not None else ''
    text += f", p {s['p']:.2g}{holm}, [{lo:+.{digits}f}, {hi:+.{digits}f}]"
  return f'**{text}**' if s['shown'] else text
