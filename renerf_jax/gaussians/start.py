"""The start of a Gaussian scene: random (3DGS on Blender: uniform in the scene's world
box, or among the box's points that enough training cameras see) or, with
Config.gs_init = 'sfm', the capture's SfM points that the training views see.
"""
import jax
import numpy as np

from renerf_jax.errors import DataError
from renerf_jax.gaussians import params as params_lib


def world_box(scene):
  """The scene's world-space box (lo [3], hi [3]) where random Gaussians are placed.

  Scene.world_bounds; without it, Scene.bbox when the scene is not in NDC.
  """
  if scene.world_bounds is not None:
    lo, hi = scene.world_bounds
  elif not scene.use_ndc:
    lo, hi = scene.bbox
  else:
    raise ValueError(f'scene {scene.name!r} is in NDC and has no Scene.world_bounds: '
                     'Gaussians need a world-space box')
  return np.asarray(lo, np.float32), np.asarray(hi, np.float32)


def views_seeing(points, poses, focal, height, width, near):
  """How many cameras see each point: in front of the camera deeper than `near` and
  inside its centred pinhole image.

  Args:
    points: [P, 3] world points. poses: [V, 3, 4] camera-to-world (OpenGL: looking
      along -z). focal: pixels. height, width: the image size. near: depth.

  Returns:
    [P] int counts in [0, V].
  """
  points = np.asarray(points, np.float64)
  poses = np.asarray(poses, np.float64)
  cam = np.einsum('vji,vpj->vpi', poses[:, :3, :3], points[None] - poses[:, None, :3, 3])
  depth = -cam[..., 2]
  front = depth > near
  safe = np.where(front, depth, 1.)
  u = focal * cam[..., 0] / safe + 0.5 * width
  v = -focal * cam[..., 1] / safe + 0.5 * height
  seen = front & (u >= 0.) & (u <= width) & (v >= 0.) & (v <= height)
  return seen.sum(0)


def seen_points(key, n, lo, hi, scene, min_views, rounds=64):
  """n points uniform in the box [lo, hi] among those that at least `min_views` of the
  scene's training cameras see (views_seeing beyond Scene.near): rejection sampling,
  4 n candidates a round.

  Returns:
    [n, 3] float32; DataError where `rounds` rounds find fewer (the cameras see too
    little of the box).
  """
  poses = np.asarray(scene.poses)[np.asarray(scene.train_idx)]
  kept, total = [], 0
  for r in range(rounds):
    cand = np.asarray(jax.random.uniform(jax.random.fold_in(key, r), (4 * n, 3)))
    cand = lo + (hi - lo) * cand
    cand = cand[views_seeing(cand, poses, scene.focal, scene.height, scene.width,
                             scene.near) >= min_views]
    kept.append(cand)
    total += len(cand)
    if total >= n:
      return np.concatenate(kept)[:n].astype(np.float32)
  raise DataError(f'scene {scene.name!r}: Config.gs_init_views={min_views}: only {total} '
                  f'of {rounds * 4 * n} random points in its box (needed: {n}) are seen '
                  f'by {min_views} or more training views; lower Config.gs_init_views')


SFM_MIN_VIEWS = 2  # A point needs two training views to be triangulated from them.


def sfm_start(scene, key, max_points):
  """The SfM points of the training views: those 2 or more training views see.

  From COLMAP's tracks where the scene has them (Scene.point_views), else by projection
  into the training cameras (views_seeing beyond Scene.near). The capture's points were
  triangulated from all its photos, so this start is kinder than an SfM run on the
  training views alone.

  Args:
    scene: Scene with points. key: PRNG key of the subsample.
    max_points: at most this many (a uniform subsample without replacement, seeded).

  Returns:
    (positions [n, 3] float32, colours [n, 3] float32 in [0, 1]); DataError where the
    scene has no points or the training views see fewer than 2.
  """
  if scene.points is None:
    raise DataError(f"scene {scene.name!r}: Config.gs_init='sfm' needs SfM points (a "
                    "COLMAP model's points3D or a transforms.json ply_file_path)")
  train = np.asarray(scene.train_idx)
  if scene.point_views is not None:
    counts = scene.point_views[:, train].sum(1)
  else:
    counts = views_seeing(scene.points, np.asarray(scene.poses)[train], scene.focal,
                          scene.height, scene.width, scene.near)
  keep = np.flatnonzero(counts >= SFM_MIN_VIEWS)
  if len(keep) < 2:
    raise DataError(f"scene {scene.name!r}: Config.gs_init='sfm': {len(keep)} of its "
                    f'{len(scene.points)} SfM points are seen by {SFM_MIN_VIEWS} or more '
                    'training views')
  if len(keep) > max_points:
    keep = np.sort(np.asarray(jax.random.choice(key, keep, (max_points,), replace=False)))
  return (np.asarray(scene.points[keep], np.float32),
          np.asarray(scene.point_colors[keep], np.float32))


def init_gaussians(config, scene, key):
  """config.gs_init_points Gaussians: from the SfM points (config.gs_init = 'sfm',
  sfm_start, at most gs_init_points, at the points' colours), else random and grey in
  the scene's world box.

  No SfM points: uniform in the box, or with config.gs_init_views = k >= 1 uniform
  among the box's points that k or more training cameras see (seen_points); then
  params.init_at (isotropic; scale = the distance to the 3 nearest points as in 3DGS, or
  the points' spacing in the box without config.gs_init_knn; opacity
  config.gs_init_opacity) in a capacity of config.gs_capacity slots.
  """
  if config.gs_init == 'sfm':  # At most gs_init_points of them, coloured.
    pts, rgb = sfm_start(scene, key, config.gs_init_points)
    n = len(pts)
    means = np.zeros((config.gs_capacity, 3), np.float32)
    means[:n] = pts
    g = params_lib.init_at(means, n, params_lib.box_spacing(pts.min(0), pts.max(0), n),
                           init_opacity=config.gs_init_opacity, knn=config.gs_init_knn)
    dc = (rgb - 0.5) / params_lib.SH_C0  # Colour = SH_C0 * DC + 0.5 (3DGS's RGB2SH).
    return g.replace(sh=g.sh.at[:n, 0].set(dc))
  lo, hi = world_box(scene)
  if config.gs_init_views == 0:
    return params_lib.random_init(key, config.gs_init_points, lo, hi,
                                  capacity=config.gs_capacity,
                                  init_opacity=config.gs_init_opacity,
                                  knn=config.gs_init_knn)
  n = config.gs_init_points
  means = np.zeros((config.gs_capacity, 3), np.float32)
  means[:n] = seen_points(key, n, lo, hi, scene, config.gs_init_views)
  return params_lib.init_at(means, n, params_lib.box_spacing(lo, hi, n),
                            init_opacity=config.gs_init_opacity, knn=config.gs_init_knn)
