"""How well a per-pixel uncertainty U ranks a model's per-pixel error: sparsification.

Pure numpy. U and the error are pooled over all pixels of a scene's test views.

Conventions:
  * Sparsification curve: remove the fraction f of pixels with the largest U; the curve
    is the mean error of the kept pixels, divided by the mean error of all pixels (so the
    curve starts at 1 and scenes with different error levels are comparable). The oracle
    curve removes by the error itself; the random ranking's curve is the constant 1.
  * Fractional counts and ties: keeping m = (1 - f) N pixels (m real), the kept error is
    the cumulative error of the floor(m) least uncertain pixels plus the fractional rest
    of the next one; pixels with equal U are never ordered arbitrarily: each takes the
    mean error of its tie group (the expectation over random tie-breaking). So constant
    U gives exactly the random curve, and U = error gives exactly the oracle.
  * Non-finite U: NaN ranks as the most uncertain (removed first, even before +inf);
    +inf and -inf keep their order (most and least uncertain).
  * All-zero error (or no pixels): every curve is 0, AUSE = AURG = 0 and the mask lift 1
    (nothing to rank); no warnings.
  * Areas are trapezoids over the given removed fractions (default 0, 0.01, ..., 0.99,
    i.e. f in [0, 0.99]): AUSE = area(curve - oracle) >= 0, lower is better, 0 for a
    perfect ranking; AURG = area(1 - curve), > 0 better than random, < 0 worse.
"""
import numpy as np

# Removed fractions of the areas: 0, 0.01, ..., 0.99.
DEFAULT_FRACTIONS = np.arange(100) / 100.


def _ranked_errors(u, err):
  """Errors sorted by increasing U, each replaced by the mean error of its U tie group.

  Args:
    u: [...] uncertainties (any real, NaN allowed). err: [...] errors, same size, finite.

  Returns:
    [N] float64 errors, least uncertain first.
  """
  u = np.asarray(u, np.float64).reshape(-1)
  err = np.asarray(err, np.float64).reshape(-1)
  if u.shape != err.shape:
    raise ValueError(f'u has {u.size} pixels but err has {err.size}')
  nan = np.isnan(u)
  # Primary key: NaN last; secondary: u (NaN replaced, only ties among NaNs matter).
  order = np.lexsort((np.where(nan, 0., u), nan))
  us, es, ns = u[order], err[order], nan[order]
  if us.size == 0:
    return es
  same = (us[1:] == us[:-1]) | (ns[1:] & ns[:-1])
  group = np.concatenate([[0], np.cumsum(~same)])
  sums = np.bincount(group, weights=es)
  counts = np.bincount(group)
  return (sums / counts)[group]


def _kept_error(ranked, keep):
  """Sum of the error of the `keep` least uncertain pixels (keep real in [0, N]).

  Args:
    ranked: [N] from _ranked_errors. keep: [K] numbers of kept pixels.

  Returns:
    [K] float64 sums (linear in keep between integers).
  """
  n = ranked.size
  cum = np.concatenate([[0.], np.cumsum(ranked)])
  keep = np.clip(np.asarray(keep, np.float64), 0., n)
  k = np.minimum(np.floor(keep).astype(np.int64), n)
  nxt = ranked[np.minimum(k, n - 1)] if n else np.zeros_like(keep)
  return cum[k] + (keep - k) * np.where(k < n, nxt, 0.)


def sparsification_curve(u, err, fractions=DEFAULT_FRACTIONS):
  """Normalised mean error of the kept pixels after removing the most uncertain ones.

  Args:
    u: [...] per-pixel uncertainty (larger: less certain; see the module docstring for
      ties and non-finite values). err: [...] per-pixel error >= 0, same size.
    fractions: [K] removed fractions in [0, 1).

  Returns:
    [K] float64: mean error of the (1 - f) N least uncertain pixels / mean error of all
    N pixels (all zeros when the total error is 0 or N = 0).
  """
  ranked = _ranked_errors(u, err)
  fractions = np.asarray(fractions, np.float64)
  n = ranked.size
  total = float(ranked.sum())
  if n == 0 or total <= 0.:
    return np.zeros(fractions.shape)
  keep = (1. - fractions) * n
  return (_kept_error(ranked, keep) / keep) / (total / n)


def oracle_curve(err, fractions=DEFAULT_FRACTIONS):
  """The sparsification curve of the error itself (the best any U can do).

  Args:
    err: [...] per-pixel error. fractions: [K] removed fractions.

  Returns:
    [K] float64.
  """
  return sparsification_curve(err, err, fractions)


def random_curve(err, fractions=DEFAULT_FRACTIONS):
  """The curve of a random ranking: the constant 1 (0 when the total error is 0).

  Args:
    err: [...] per-pixel error. fractions: [K] removed fractions.

  Returns:
    [K] float64.
  """
  err = np.asarray(err, np.float64)
  return np.full(np.shape(fractions), 1. if err.size and err.sum() > 0. else 0.)


def _area(y, fractions):
  fractions = np.asarray(fractions, np.float64)
  if fractions.size < 2:
    return 0.
  return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(fractions)))


def ause(u, err, fractions=DEFAULT_FRACTIONS):
  """Area Under the Sparsification Error: area between U's curve and the oracle's.

  Args:
    u: [...] uncertainty. err: [...] error >= 0. fractions: [K] increasing removed
      fractions (the trapezoid's abscissae).

  Returns:
    float >= 0 (lower is better; 0 when U ranks like the error).
  """
  return _area(sparsification_curve(u, err, fractions) - oracle_curve(err, fractions),
               fractions)


def aurg(u, err, fractions=DEFAULT_FRACTIONS):
  """Area Under the Random Gain: area between the random ranking's curve and U's.

  Args:
    u: [...] uncertainty. err: [...] error >= 0. fractions: [K] increasing fractions.

  Returns:
    float: > 0 better than random, ~0 for U independent of the error, < 0 worse.
  """
  return _area(random_curve(err, fractions) - sparsification_curve(u, err, fractions),
               fractions)


def mask_lift(u, err, keep_frac: float):
  """Mean error of the masked-out pixels over the mean error of the kept ones.

  The keep_frac N least uncertain pixels are kept (fractional counts and ties as in the
  module docstring: the expected lift of a mask that keeps exactly keep_frac N pixels).

  Args:
    u: [...] uncertainty. err: [...] error >= 0. keep_frac: fraction kept, in (0, 1).

  Returns:
    float: 1 for a mask independent of the error (in expectation), > 1 when the masked
    pixels are the worse ones; inf if the kept pixels have zero error and the masked
    ones not; 1 when the total error is 0; nan when keep_frac is not in (0, 1) or N = 0.
  """
  ranked = _ranked_errors(u, err)
  n = ranked.size
  if n == 0 or not 0. < keep_frac < 1.:
    return float('nan')
  total = float(ranked.sum())
  if total <= 0.:
    return 1.
  keep = keep_frac * n
  kept = float(_kept_error(ranked, [keep])[0])
  masked_mean = max(total - kept, 0.) / (n - keep)
  kept_mean = kept / keep
  return float('inf') if kept_mean <= 0. else masked_mean / kept_mean


def quality(u, err, keep_frac: float, fractions=DEFAULT_FRACTIONS):
  """All of the above for one U.

  Args:
    u: [...] uncertainty. err: [...] error. keep_frac: the mask's kept fraction.
    fractions: [K] removed fractions.

  Returns:
    dict: ause, aurg, lift (floats), curve and oracle ([K] lists).
  """
  curve = sparsification_curve(u, err, fractions)
  oracle = oracle_curve(err, fractions)
  rand = random_curve(err, fractions)
  return {'ause': _area(curve - oracle, fractions), 'aurg': _area(rand - curve, fractions),
          'lift': mask_lift(u, err, keep_frac), 'curve': curve.tolist(),
          'oracle': oracle.tolist()}


# --------------------------------------------------------------- per-pixel errors


def rgb_squared_error(rgb, gt):
  """Per-pixel squared error, mean over the colour channels.

  Args:
    rgb: [..., 3] rendered colour (clipped to [0, 1] here). gt: [..., 3] in [0, 1].

  Returns:
    [...] float64.
  """
  rgb = np.clip(np.asarray(rgb, np.float64), 0., 1.)
  return np.mean((rgb - np.asarray(gt, np.float64))**2, axis=-1)


def ndc_t_to_z_depth(t, world_origins, world_directions, near: float = 1.):
  """Camera z-depth of the point at NDC ray parameter t (forward-facing NDC rays).

  cameras.convert_to_ndc maps a world point with z coordinate z_w to NDC z = 1 + 2 near
  / z_w, and an NDC ray's z runs from -1 (t = 0) to 1 (t = 1), so the point at t has
  z_w = -near / (1 - t). On the world ray o + s d with d = R (x, y, -1) (cameras'
  unnormalised directions) the parameter s = (z_w - o_z) / d_z is the camera z-depth.

  Args:
    t: [...] NDC ray parameter in [0, 1) (render_rays' 'distance' in NDC).
    world_origins, world_directions: [..., 3] the same pixels' world-space rays
      (cameras.pixel_rays with use_ndc=False).
    near: the NDC near plane (cameras' default 1).

  Returns:
    [...] float64 z-depth (inf at t = 1).
  """
  t = np.asarray(t, np.float64)
  o = np.asarray(world_origins, np.float64)
  d = np.asarray(world_directions, np.float64)
  with np.errstate(divide='ignore'):
    z_w = -near / (1. - t)
  return (z_w - o[..., 2]) / d[..., 2]


def depth_abs_error(pred_depth, true_depth, cap: float):
  """|predicted - true| depth, the prediction clipped to [0, cap] first.

  Args:
    pred_depth: [...] rendered depth (may be inf where the ray hit nothing).
    true_depth: [...] true depth. cap: the largest predicted depth counted (e.g. twice
      the largest true depth), so one empty ray cannot dominate the mean.

  Returns:
    [...] float64 >= 0.
  """
  pred = np.clip(np.nan_to_num(np.asarray(pred_depth, np.float64), nan=cap, posinf=cap),
                 0., cap)
  return np.abs(pred - np.asarray(true_depth, np.float64))
