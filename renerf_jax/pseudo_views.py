"""Pseudo-views: model B rendered at poses between neighbouring training cameras.

Nothing here writes a file: round_driver.save_pseudo_views does, at the edge.
"""
import time

import flax
import jax.numpy as jnp
import numpy as np

from renerf_jax import poses as pose_lib
from renerf_jax import figures, random_poses
from renerf_jax.errors import ConfigError


@flax.struct.dataclass
class PseudoViews:
  """Synthesised training views (a pytree of arrays)."""
  images: jnp.ndarray  # [M, H, W, 3] in [0, 1].
  poses: jnp.ndarray  # [M, 3, 4] camera-to-world.
  masks: jnp.ndarray  # [M, H, W] 1 = pixel enters the loss, 0 = masked.
  uncertainty: jnp.ndarray  # [M, H, W] rendered uncertainty (zeros when masks are off).


def parse_factors(spec: str):
  """Config.interp_factors ('7x', a preset, or '0.25,0.5') -> tuple of interpolation
  factors in (0, 1), parsed once by poses.resolve_factors; a bad spec is a ConfigError."""
  try:
    return pose_lib.resolve_factors(spec)
  except ValueError as e:
    raise ConfigError(f'Config.interp_factors={spec!r}: {e}') from None


def pseudo_view_poses(config, scene):
  """Poses of the pseudo-views and a description of each.

  'interp': every factor between every neighbouring pair of training cameras (position
  lerp, rotation SLERP; pairs from config.sequencing). 'test': the test poses (the
  paper's "optimising for specific views"). 'random': config.pseudo_n_random random
  unobserved poses, drawn like the depth-TV poses (the control for 'test' in the view
  selection table). 'unused': the poses of the photos the split leaves unused (neither
  training nor test views; with Config.pseudo_source='photo' the oracle trains on those
  photos themselves). Targets combine with '+', e.g. 'interp+test'.

  Returns:
    (poses [M, 3, 4] float32, meta: list of dicts).
  """
  out, meta = [], []
  targets = config.pseudo_targets.split('+')
  for t in targets:
    if t not in ('interp', 'test', 'random', 'unused'):
      raise ConfigError(f'Config.pseudo_targets={config.pseudo_targets!r} '
                        "(interp, test, random, unused or a '+' combination)")
  if config.pseudo_source == 'photo' and targets != ['unused']:
    raise ConfigError(f"Config.pseudo_source='photo' needs Config.pseudo_targets="
                      f"'unused', not {config.pseudo_targets!r}: real photos exist only "
                      'at the unused views (test photos are never trained on)')
  if config.pseudo_source == 'photo' and config.use_masks:
    raise ConfigError("Config.pseudo_source='photo' takes no masks (set Config.use_masks"
                      '=False): every pixel of a photo is real')
  if 'interp' in targets:
    train = np.asarray(scene.poses[scene.train_idx], np.float64)
    if len(train) < 2:
      raise ConfigError(f'Re-Nerfing needs at least 2 training views to interpolate '
                        f'pseudo-views, got {len(train)} (Config.n_input_views); use '
                        f"Config.pseudo_targets='test' or Config.num_rounds=0")
    poses, info = pose_lib.interpolated_poses(train, parse_factors(config.interp_factors),
                                              config.sequencing)
    out.append(poses)
    meta += [{'kind': 'interp', 'pair': [int(scene.train_idx[i]) for i in m['pair']],
              'beta': float(m['beta'])} for m in info]
  if 'test' in targets:
    out.append(np.asarray(scene.poses[scene.test_idx], np.float64))
    meta += [{'kind': 'test', 'view': int(i)} for i in scene.test_idx]
  if 'random' in targets:
    out.append(random_target_poses(config, scene))
    meta += [{'kind': 'random', 'index': i} for i in range(config.pseudo_n_random)]
  if 'unused' in targets:
    idx = unused_views(scene)
    if not len(idx):
      raise ConfigError(f'Config.pseudo_targets={config.pseudo_targets!r}: scene '
                        f'{scene.name!r} has no unused photos (each one trains or tests)')
    out.append(np.asarray(scene.poses[idx], np.float64))
    meta += [{'kind': 'unused', 'view': int(i)} for i in idx]
  return np.concatenate(out, 0).astype(np.float32), meta


def unused_views(scene):
  """Indices of the scene's photos that are neither training, test nor validation views,
  ascending."""
  used = set(np.asarray(scene.train_idx).tolist()) | set(np.asarray(scene.test_idx).tolist())
  used |= set(np.asarray(scene.val_idx).tolist())  # Validation views stay unseen.
  return np.array([i for i in range(len(scene.poses)) if i not in used], np.int64)


def photo_pseudo_views(config, scene):
  """The oracle's pseudo-views: the real photos at the unused views, in place of B's
  renders at the same poses (Config.pseudo_source='photo', pseudo_targets='unused').

  Returns:
    (PseudoViews with masks of ones, timing {'seconds', 'render_seconds': 0}, meta).
  """
  t0 = time.perf_counter()
  poses, meta = pseudo_view_poses(config, scene)
  images = np.asarray(scene.images[np.array([m['view'] for m in meta])], np.float32)
  m, h, w = images.shape[:3]
  pv = PseudoViews(images=images, poses=poses, masks=np.ones((m, h, w), np.float32),
                   uncertainty=np.zeros((m, h, w), np.float32))
  return pv, {'seconds': time.perf_counter() - t0, 'render_seconds': 0.}, meta


def random_target_poses(config, scene):
  """config.pseudo_n_random random unobserved poses [n, 3, 4] (float64).

  Drawn by the generator of the depth-TV poses (forward-facing: within and slightly
  beyond the training cameras, looking at the focus point; 360: on the sphere of the
  training cameras), from a seed of their own, so they are the same in every round.
  """
  if config.pseudo_n_random < 1:
    raise ConfigError(f'Config.pseudo_n_random={config.pseudo_n_random} must be >= 1 '
                      "with Config.pseudo_targets containing 'random'")
  rng = np.random.default_rng([config.seed, 7919])
  train = np.asarray(scene.poses[scene.train_idx], np.float64)
  return random_poses.random_unobserved_poses(train, config.pseudo_n_random, rng,
                                              scene.forward_facing, scene.focus_depth,
                                              config.random_pose_spread)


def uncertainty_heatmap(u, ref=None):
  """[H, W, 3] turbo heat-map of U, coloured by each pixel's quantile of U in `ref`
  (default u; pass all views to share one scale): histogram-equalised. U often clusters
  just below the prior sigma (vertices seen by few rays), where a linear or log scale
  shows one colour; the quantile shows the ordering that a keep-fraction threshold uses.
  Non-finite U is drawn black."""
  u = np.asarray(u, np.float64)
  ref = np.asarray(u if ref is None else ref, np.float64).reshape(-1)
  ref = np.sort(ref[np.isfinite(ref)])
  q = np.full(u.shape, np.nan)
  ok = np.isfinite(u)
  if ref.size:
    q[ok] = np.searchsorted(ref, u[ok], side='right') / ref.size
  return figures.colorize(q, lo=0., hi=1.)


def side_by_side(image, heat, mask):
  """[H, 3W + 2 gap, 3] panel: pseudo-view | uncertainty heat-map | view with the masked
  pixels blacked out (what training sees)."""
  mask = np.asarray(mask, np.float32).reshape(image.shape[:2] + (1,))
  gap = np.ones(image.shape[:1] + (4, 3), np.float32)
  return np.concatenate([image[..., :3], gap, heat[..., :3], gap, image[..., :3] * mask],
                        axis=1)
