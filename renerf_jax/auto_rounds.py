"""Config.num_rounds = 'auto': is round r's model kept, and is another round trained?

After round r (D trained on B's pseudo-views) both models are rendered at the capture's
validation views (Config.val_views: photos neither trained on nor tested). The signal is
the paired per-view PSNR gain d_i = PSNR(D, view i) - PSNR(B, view i). The round is kept,
and the next one trained, only when the mean gain exceeds Config.auto_min_gain_se
standard errors of itself (the signal's own resampling over the views: sd(d) / sqrt(n));
else the run keeps B (the previous round's model) and trains no further round. At most
Config.auto_max_rounds rounds are trained. Nothing here looks at the test views.

Pure functions of the rounds' metrics dicts (renerf.round_step puts each model's
per-view validation PSNR in 'val_psnr_views'); the decision is made once, stored in the
round's metrics under 'auto' (result.json) and read back when a run resumes, so a later
auto_min_gain_se changes no stored decision. A round trained before the run was 'auto'
has no decision and counts as kept. The round driver's RoundState after a discard holds
the discarded round's params; selected_round names the model the run keeps (its params
are round_<k>/params.msgpack).
"""
import math
from typing import Optional, Sequence

import numpy as np

from renerf_jax.errors import ConfigError

AUTO = 'auto'


def is_auto(config) -> bool:
  """Config.num_rounds = 'auto'."""
  return config.num_rounds == AUTO


def max_rounds(config) -> int:
  """The most rounds a run trains: num_rounds, or auto_max_rounds with 'auto'."""
  return config.auto_max_rounds if is_auto(config) else config.num_rounds


def check_auto(config, scene):
  """Raises ConfigError when 'auto' cannot decide on this scene (too few validation
  views: the signal's standard error needs two)."""
  if is_auto(config) and len(scene.val_idx) < 2:
    raise ConfigError(
        f"Config.num_rounds='auto' decides on validation views, and scene "
        f'{scene.name!r} has {len(scene.val_idx)} (Config.val_views={config.val_views}); '
        'set Config.val_views >= 2 or an integer Config.num_rounds')


def decide(round_index: int, prev_views: Sequence[float], cand_views: Sequence[float],
           min_gain_se: float) -> dict:
  """Whether round `round_index`'s model replaces the previous one.

  Args:
    round_index: r >= 1, the round whose model D is the candidate.
    prev_views: per-view validation PSNR of the previous model (B), [n].
    cand_views: the same views' PSNR of D, [n].
    min_gain_se: the mean gain must exceed this many standard errors (>= 0; with 0 any
      gain above 0 keeps the round).

  Returns:
    {'round', 'take', 'gain', 'se', 'views', 'line'}: gain = mean paired gain (dB), se =
    its standard error; line = the one-line account train.py prints.
  """
  prev = np.asarray(prev_views, np.float64)
  cand = np.asarray(cand_views, np.float64)
  if prev.shape != cand.shape or prev.ndim != 1 or len(prev) < 2:
    raise ValueError(f'need two equal lists of >= 2 per-view PSNRs, got {prev.shape} '
                     f'and {cand.shape}')
  n = len(prev)
  keeps = f'round {round_index - 1}' if round_index > 1 else 'B'
  if np.isnan(cand).any():
    take, gain, se = False, float('nan'), float('nan')
    why = 'a validation PSNR of its model is NaN'
  elif np.isnan(prev).any():
    take, gain, se = True, float('nan'), float('nan')
    why = f'a validation PSNR of {keeps} is NaN'
  else:
    with np.errstate(invalid='ignore'):  # inf - inf: both views rendered exactly.
      d = np.where(prev == cand, 0., cand - prev)
    gain = float(d.mean())
    se = float(d.std(ddof=1) / math.sqrt(n)) if np.isfinite(d).all() else float('nan')
    if math.isfinite(gain) and math.isfinite(se):
      take = gain > 0. and gain > min_gain_se * se
      cmp = 'above' if take else ('not above 0' if gain <= 0. else 'within')
      why = (f'validation gain {gain:+.2f} +- {se:.2f} dB ({n} views), {cmp}'
             + ('' if cmp == 'not above 0' else f' {min_gain_se:g} standard errors'))
    else:  # A view rendered exactly by one model alone (PSNR inf).
      take = gain > 0.
      why = f'validation gain {gain:+} dB ({n} views: a view rendered exactly)'
  verb = 'kept' if take else f'discarded, the run keeps {keeps}'
  line = f'round {round_index} {verb}: {why}'
  return {'round': int(round_index), 'take': bool(take), 'gain': gain, 'se': se,
          'views': int(n), 'line': line}


def round_decision(config, prev_metrics: dict, metrics: dict) -> Optional[dict]:
  """decide() for the round whose metrics dict is `metrics` after `prev_metrics` (None
  unless Config.num_rounds = 'auto')."""
  if not is_auto(config):
    return None
  return decide(int(metrics['round']), prev_metrics['val_psnr_views'],
                metrics['val_psnr_views'], config.auto_min_gain_se)


def selected_round(metrics: Sequence[dict]) -> int:
  """The round whose model a run returns: the last round kept before the first one
  discarded (rounds without a decision, an integer num_rounds, are all kept)."""
  sel = 0
  for m in metrics[1:]:
    d = m.get('auto')
    if d is not None and not d['take']:
      break
    sel = int(m['round'])
  return sel


def stops_after(config, metrics: Sequence[dict]) -> bool:
  """True when no further round is trained after the rounds in `metrics` (with an
  integer num_rounds only the count decides, whatever decisions a run stored)."""
  if len(metrics) > max_rounds(config):
    return True
  if not is_auto(config):
    return False
  last = metrics[-1].get('auto') if metrics else None
  return last is not None and not last['take']
