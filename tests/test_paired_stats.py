"""experiments/paired.py: the paired t-test, the bootstrap interval and the 'shown' rule
on synthetic numbers with known answers."""
import math

import numpy as np
import pytest
import scipy.stats

from experiments import paired


@pytest.mark.parametrize('t,df', [(0.3, 1), (2.5, 1), (40., 1), (0.7, 2), (3.1, 2),
                                  (-5., 2)])
def test_t_p_value_matches_closed_forms(t, df):
  """df 1 (Cauchy) and df 2 have closed-form tails."""
  exact = (1. - 2. / math.pi * math.atan(abs(t)) if df == 1
           else 1. - abs(t) / math.sqrt(2. + t * t))
  assert paired.t_two_sided_p(t, df) == pytest.approx(exact, rel=1e-10, abs=1e-14)


def test_t_p_value_at_textbook_critical_values_and_extremes():
  assert paired.t_two_sided_p(2.2621571628, 9) == pytest.approx(0.05, abs=1e-9)
  assert paired.t_two_sided_p(12.7062047362, 1) == pytest.approx(0.05, abs=1e-9)
  assert paired.t_two_sided_p(1.959963985, 1e7) == pytest.approx(0.05, abs=1e-6)
  assert paired.t_two_sided_p(0., 5) == 1.
  assert paired.t_two_sided_p(1e12, 3) == pytest.approx(0., abs=1e-30)
  assert paired.t_two_sided_p(float('inf'), 3) == 0.
  with pytest.raises(ValueError, match='df'):
    paired.t_two_sided_p(1., 0)
  with pytest.raises(ValueError, match='0 <= x <= 1'):
    paired.betainc(1., 1., 1.5)
  assert paired.betainc(2., 3., 0.) == 0. and paired.betainc(2., 3., 1.) == 1.
  # I_x(1, 1) = x; I_x(a, 1) = x^a.
  assert paired.betainc(1., 1., 0.37) == pytest.approx(0.37, rel=1e-12)
  assert paired.betainc(4.5, 1., 0.8) == pytest.approx(0.8**4.5, rel=1e-12)


def test_paired_p_value_matches_scipy_on_random_pairs():
  rng = np.random.default_rng(3)
  for n in (2, 3, 5, 8, 20):
    a = rng.normal(20., 1., n)
    b = a + rng.normal(0.3, 0.5, n)
    s = paired.paired_summary(b - a)
    assert s['p'] == pytest.approx(scipy.stats.ttest_rel(b, a).pvalue, rel=1e-8)
    assert s['mean'] == pytest.approx(np.mean(b - a))
    assert s['std'] == pytest.approx(np.std(b - a, ddof=1))


def test_bootstrap_interval_known_cases():
  # Every resample of equal deltas has their mean.
  assert paired.bootstrap_interval([0.4] * 6) == pytest.approx((0.4, 0.4))
  lo, hi = paired.bootstrap_interval(np.arange(1., 9.))
  assert 1. < lo < 4.5 < hi < 8.
  lo, hi = paired.bootstrap_interval([-1., 1.] * 5)
  assert lo < 0. < hi
  # Reproducible: a fixed seed.
  d = np.random.default_rng(0).normal(size=7)
  assert paired.bootstrap_interval(d) == paired.bootstrap_interval(d)


def test_a_gain_is_shown_only_when_the_interval_excludes_zero():
  clear = paired.paired_summary([0.8, 1.1, 0.9, 1.3, 0.7, 1.0, 0.95, 1.2])
  assert clear['shown'] and not clear['loss_shown'] and clear['wins'] == 8
  assert clear['p'] < 1e-5 and clear['ci'][0] > 0.
  # The lego numbers of issue 49 (R1 minus D's-seed control, 5 seeds): every bootstrap
  # resample of five positive deltas is positive, but the t-test says p = 0.13: not shown.
  lego = paired.paired_summary([1.58, 0.70, 0.11, 0.10, 0.23])
  assert lego['ci'][0] > 0. and lego['p'] == pytest.approx(0.126, abs=5e-3)
  assert not lego['shown'] and lego['wins'] == 5
  noise = paired.paired_summary([0.5, -0.4, 0.2, -0.6, 0.3, -0.1, 0.4, -0.3])
  assert not noise['shown'] and not noise['loss_shown']
  assert noise['ci'][0] < 0. < noise['ci'][1]
  loss = paired.paired_summary([-0.5, -0.7, -0.6, -0.4, -0.55])
  assert loss['loss_shown'] and not loss['shown'] and loss['wins'] == 0
  # LPIPS: lower is better, so negative deltas are the gain.
  lp = paired.paired_summary([-0.02, -0.03, -0.025, -0.01, -0.02], better=-1.)
  assert lp['shown'] and lp['wins'] == 5 and not lp['loss_shown']


def test_seed_noise_alone_is_rarely_shown():
  """Deltas of pure noise (mean 0): the interval excludes 0 in few of 300 tables."""
  rng = np.random.default_rng(1)
  shown = [paired.paired_summary(rng.normal(0., 1., 8))['shown'] for _ in range(300)]
  assert np.mean(shown) < 0.12  # nominal 2.5% (one side); the percentile method undercovers


def test_degenerate_inputs():
  one = paired.paired_summary([0.7])
  assert one['p'] is None and one['ci'] is None and not one['shown'] and one['std'] == 0.
  same = paired.paired_summary([0.5, 0.5, 0.5])
  assert same['p'] == 0. and same['shown'] and same['ci'] == pytest.approx([0.5, 0.5])
  zero = paired.paired_summary([0., 0., 0.])
  assert zero['p'] == 1. and not zero['shown'] and not zero['loss_shown']
  huge = paired.paired_summary([1e6, 1e6 + 1e-3, 1e6 - 1e-3])
  assert huge['p'] < 1e-12 and huge['shown']
  with pytest.raises(ValueError, match='non-empty'):
    paired.paired_summary([])
  with pytest.raises(ValueError, match='non-finite'):
    paired.paired_summary([0.1, float('nan')])


def test_format_cell_bolds_a_shown_gain():
  s = paired.paired_summary([0.8, 1.1, 0.9, 1.2])
  text = paired.format_cell(s)
  assert text.startswith('**+1.00 +- 0.18 (4/4), p 0.') and text.endswith('**')
  n = paired.format_cell(paired.paired_summary([0.5, -0.4, 0.2]))
  assert not n.startswith('**') and '(2/3), p ' in n
  assert paired.format_cell(paired.paired_summary([0.3])) == '+0.30 +- 0.00 (1/1)'
  assert paired.format_cell({}) == ''


def test_holm_adjustment_on_known_families():
  """Holm by hand: sorted p times (m, m-1, ...), made monotone, capped at 1; None skipped."""
  assert paired.holm_adjust([0.01, 0.04, 0.03, 0.005]) == pytest.approx([0.03, 0.06, 0.06,
                                                                         0.02])
  assert paired.holm_adjust([0.5, None, 0.2]) == [pytest.approx(0.5), None,
                                                  pytest.approx(0.4)]
  assert paired.holm_adjust([0.6, 0.7]) == pytest.approx([1., 1.])  # capped
  assert paired.holm_adjust([0.03]) == pytest.approx([0.03])  # a family of one
  assert paired.holm_adjust([]) == []
  # Ties keep one value; order given is kept.
  assert paired.holm_adjust([0.02, 0.02, 0.001]) == pytest.approx([0.04, 0.04, 0.003])


def test_a_family_decides_shown_on_the_holm_p():
  """Issue 62's 3DGS fox table: R1 - control p 0.027 and R1 - control 2x p 0.041 are
  shown alone, not beside a third comparison of the same table (Holm 0.081, 0.12)."""
  clear = paired.paired_summary([0.8, 1.1, 0.9, 1.3, 0.7])  # p ~ 1e-3
  weak = paired.paired_summary([0.3, 0.9, 0.4, 1.2, 0.2])  # p 0.036
  noise = paired.paired_summary([0.5, -0.6, 0.2, -0.3, 0.1])
  assert weak['shown'] and 0.01 < weak['p'] < 0.05 and weak['ci'][0] > 0.
  family = paired.adjust_family([clear, weak, noise, {}])
  assert [s['family'] for s in family] == [3, 3, 3]
  assert weak['p_holm'] == pytest.approx(2 * weak['p'])  # second smallest of 3
  assert clear['p_holm'] == pytest.approx(3 * clear['p']) and clear['shown']
  assert not weak['shown'] and not noise['shown'] and noise['p_holm'] == pytest.approx(
      noise['p'])
  assert '(5/5), p 0.0' in paired.format_cell(weak) and ', Holm 0.0' in paired.format_cell(weak)
  assert not paired.format_cell(weak).startswith('**')
  # A loss in a family: LPIPS, lower is better.
  loss = paired.paired_summary([0.02, 0.03, 0.025, 0.02, 0.03], better=-1.)
  paired.adjust_family([loss, paired.paired_summary([0.01, -0.01, 0.0], better=-1.)],
                       better=-1.)
  assert loss['loss_shown'] and not loss['shown'] and loss['p_holm'] == pytest.approx(
      2 * loss['p'])


@pytest.mark.parametrize('x,d1,d2', [(0.5, 2, 2), (3.63, 7, 7), (1., 4, 9), (12., 1, 3)])
def test_f_distribution_matches_closed_form_and_scipy(x, d1, d2):
  got = paired.f_cdf(x, d1, d2)
  assert got == pytest.approx(scipy.stats.f.cdf(x, d1, d2), rel=1e-9)
  if d1 == d2 == 2:
    assert got == pytest.approx(x / (1. + x), rel=1e-12)  # F(2, 2)'s closed form


def test_f_test_of_two_spreads():
  """Issue 62: lego's B, std 0.25 (faces clamped) against 0.13 dB (empty outside the
  box), 8 seeds each: "the spread halves" is not shown (p 0.11)."""
  clamped = [22.085, 22.249, 21.64, 22.483, 22.258, 22.247, 22.046, 22.315]
  empty = [22.361, 22.199, 22.237, 22.129, 22.081, 22.077, 22.165, 21.912]
  t = paired.f_test(clamped, empty)
  assert (t['std_a'], t['std_b']) == pytest.approx((0.2514, 0.1319), abs=1e-4)
  assert t['p'] == pytest.approx(0.110, abs=1e-3) and not t['shown']
  # Symmetric, and equal to scipy's two-sided F-test.
  assert paired.f_test(empty, clamped)['p'] == pytest.approx(t['p'], rel=1e-9)
  ratio = np.var(clamped, ddof=1) / np.var(empty, ddof=1)
  assert t['p'] == pytest.approx(2 * scipy.stats.f.sf(ratio, 7, 7), rel=1e-9)
  # A spread 4x smaller over 8 seeds each is shown.
  rng = np.random.default_rng(0)
  wide, narrow = rng.normal(0., 1., 8), rng.normal(0., 0.25, 8)
  assert paired.f_test(wide, narrow)['shown']
  assert paired.f_test([1., 2.], [3., 4.])['p'] == pytest.approx(1.)
  assert paired.f_test([1., 1., 1.], [2., 2.])['p'] == 1.
  with pytest.raises(ValueError, match='at least 2'):
    paired.f_test([1.], [1., 2.])
