"""The few-shot split of a capture: test, training and validation views.

Test views are the standard ones: every Config.llffhold-th photo sorted by name (index %
llffhold == 0). The Config.n_input_views training views come from the other photos by
Config.train_view_selection:
  'linspace'  evenly spaced by index (np.linspace over the non-test photos, rounded):
              RegNeRF's LLFF split and the sparse 3DGS literature's;
  'coverage'  the Re-Nerfing paper's mip-NeRF 360 split ("chosen from all available
              images while preserving as much coverage of the scene as possible"): greedy
              farthest-point sampling over the non-test cameras, the distance of two
              cameras being the distance of their centres over the cameras' spread (the
              median distance of a centre from the centres' mean) plus 1 - the cosine of
              the angle between their viewing directions; the first view is the camera
              nearest the centres' mean, ties go to the lower index. Deterministic.
Config.val_views = k validation views are then taken evenly spaced by index
(np.linspace, rounded) over the photos that neither split uses, so they spread over the
capture as the test views do; tables choose steps, radii, thresholds and recipes on them,
never on test views. The rest stay unused (the oracle's pseudo-views: pseudo_targets
'unused'). Blender's layout has split files of its own (blender.blender_split).
Config.leave_out_view = j then takes the j-th training view out of training as the only
validation view (a probe of a capture with no views to spare: leave_out_view), for
every loader.
"""
import numpy as np

from renerf_jax.errors import DataError

SELECTIONS = ('linspace', 'coverage')


def leave_out_view(train_idx, val_idx, j):
  """The split of a leave-one-training-view-out probe (Config.leave_out_view).

  Args:
    train_idx: [n] the training views, in split order. val_idx: the validation views
      (must be empty: the left-out view is the probe's only one).
    j: which training view is left out (0 <= j < n), or -1: the split as it is.

  Returns:
    (train_idx without its j-th view, [that view]) int64 arrays; unchanged with j = -1.
  """
  train_idx = np.asarray(train_idx, np.int64)
  val_idx = np.asarray(val_idx, np.int64)
  if j < 0:
    return train_idx, val_idx
  if not 0 <= j < len(train_idx) or len(train_idx) < 2:
    raise DataError(f'Config.leave_out_view={j}: the split has {len(train_idx)} training '
                    f'views (leaving one out needs 2 or more, and 0 <= j < '
                    f'{len(train_idx)})')
  if len(val_idx):
    raise DataError(f'Config.leave_out_view={j}: the scene has {len(val_idx)} validation '
                    'views already; the left-out view is the only one (Config.val_views '
                    '= 0)')
  return np.delete(train_idx, j), train_idx[j:j + 1]


def evenly_spaced(candidates, n):
  """n of the candidates evenly spaced by position (np.linspace, rounded)."""
  candidates = np.asarray(candidates, np.int64)
  if n == 0:
    return candidates[:0]
  return candidates[np.round(np.linspace(0, len(candidates) - 1, n)).astype(int)]


def validation_frames(n_frames, val_views, source):
  """Config.val_views frames of a split file of n_frames (Blender's transforms_val.json),
  evenly spaced; DataError naming `source` where it has fewer."""
  if val_views > n_frames:
    raise DataError(f'Config.val_views={val_views} but {source} has {n_frames} frames')
  return evenly_spaced(np.arange(n_frames), val_views)


def camera_distances(poses):
  """[N, N] distances of cameras: centre distance / spread + (1 - cos of the angle
  between the viewing directions).

  Args:
    poses: [N, 3, 4] camera-to-world (OpenGL: the camera looks along -z).
  """
  poses = np.asarray(poses, np.float64)
  centres = poses[:, :3, 3]
  spread = float(np.median(np.linalg.norm(centres - centres.mean(0), axis=-1)))
  spread = spread if spread > 1e-12 else 1.
  dirs = -poses[:, :3, 2] / np.maximum(np.linalg.norm(poses[:, :3, 2], axis=-1,
                                                      keepdims=True), 1e-12)
  d_pos = np.linalg.norm(centres[:, None] - centres[None], axis=-1) / spread
  return d_pos + (1. - np.clip(dirs @ dirs.T, -1., 1.))


def coverage_views(poses, candidates, n):
  """n of the candidates by greedy farthest-point sampling (the module docstring's rule).

  Args:
    poses: [N, 3, 4] every camera of the capture. candidates: indices to choose from.
    n: how many (<= len(candidates)).

  Returns:
    int64 [n], in the order chosen.
  """
  candidates = np.asarray(candidates, np.int64)
  if n == 0:
    return candidates[:0]
  poses = np.asarray(poses, np.float64)[candidates]
  dist = camera_distances(poses)
  centres = poses[:, :3, 3]
  chosen = [int(np.argmin(np.linalg.norm(centres - centres.mean(0), axis=-1)))]
  nearest = dist[chosen[0]].copy()
  for _ in range(n - 1):
    nearest[chosen] = -1.
    nxt = int(np.argmax(nearest))
    chosen.append(nxt)
    nearest = np.minimum(nearest, dist[nxt])
  return candidates[np.asarray(chosen)]


def split_views(poses, n_input_views, llffhold=8, selection='linspace', val_views=0):
  """(train_idx, val_idx, test_idx) of a capture (the module docstring's rules).

  Args:
    poses: [N, 3, 4] camera-to-world of every photo, sorted by name.
    n_input_views: training views. llffhold: test period (every llffhold-th photo).
    selection: 'linspace' or 'coverage'. val_views: validation views.

  Returns:
    Three int64 arrays (train in the order chosen: by index for 'linspace'); DataError
    where the photos do not hold that many views.
  """
  n = len(poses)
  test = np.arange(0, n, llffhold, dtype=np.int64)
  rest = np.setdiff1d(np.arange(n, dtype=np.int64), test)
  if n_input_views > len(rest):
    raise DataError(f'Config.n_input_views={n_input_views} but only {len(rest)} '
                    f'non-test images are available of {n} (every '
                    f'Config.llffhold={llffhold}-th is a test view)')
  if selection == 'coverage':
    train = coverage_views(poses, rest, n_input_views)
  elif selection == 'linspace':
    train = evenly_spaced(rest, n_input_views)
  else:
    raise DataError(f'Config.train_view_selection={selection!r}: not one of {SELECTIONS}')
  unused = np.setdiff1d(rest, train)
  if val_views > len(unused):
    raise DataError(f'Config.val_views={val_views} but only {len(unused)} images are '
                    f'neither test nor training views ({n_input_views} training, '
                    f'{len(test)} test of {n})')
  return train, evenly_spaced(unused, val_views), test


def split_of(config, poses, source):
  """split_views with the Config's fields; a DataError names `source` (the scene file)."""
  try:
    return split_views(poses, config.n_input_views, config.llffhold,
                       config.train_view_selection, config.val_views)
  except DataError as e:
    raise DataError(f'{source}: {e}') from None
