"""The embedded default scene: a forward-facing textured scene the code ray-casts itself.

Four textured spheres at depths 2-6 in front of a patterned back wall and a striped floor,
Lambertian shading, 17 cameras on a small spiral looking at the scene (LLFF-like), with
exact z-depth maps. It needs no download, and sparse-view synthesis on it is not trivial:
occlusion boundaries, texture at several scales and a depth range of ~3.5x.
The poses are processed exactly as LLFF poses (rescale, recentre, NDC), so the embedded
scene exercises the same code path as the reference LLFF case.
"""
import numpy as np

from renerf_jax import cameras
from renerf_jax.datasets.split import split_of
from renerf_jax.datasets.scene import (Scene, focus_depth_from_bounds,
                                       frustum_bounds)

# (centre x, y, z, radius, texture frequency, hue phase)
_SPHERES = np.array([
    [-0.95, 0.35, -3.2, 0.65, 9., 0.0],
    [0.85, -0.15, -4.6, 0.95, 6., 2.1],
    [0.05, -0.8, -2.4, 0.38, 14., 4.0],
    [1.45, 0.95, -5.6, 0.55, 11., 1.0],
])
_WALL_Z = -7.
_FLOOR_Y = -1.45
_LIGHT = np.array([0.45, 0.7, 0.55]) / np.linalg.norm([0.45, 0.7, 0.55])


def palette(t, phase):
  """Smooth colourful palette, t and phase broadcastable -> [..., 3] in [0, 1]."""
  offsets = np.array([0., 2.1, 4.2])
  return 0.5 + 0.45 * np.cos(t[..., None] + phase[..., None] + offsets)


def _shade(points, normals, kind, param):
  """Albedo texture times Lambertian shading at hit points. Returns [..., 3]."""
  x, y, z = points[..., 0], points[..., 1], points[..., 2]
  albedo = np.zeros(points.shape)
  wall = kind == 0
  checker = (np.floor(x[wall] * 2.) + np.floor(y[wall] * 2.)) % 2
  albedo[wall] = palette(1.7 * np.sin(1.3 * x[wall]) + 2.3 * np.cos(0.9 * y[wall]) +
                          1.5 * checker, np.full(checker.shape, 0.5))
  floor = kind == 1
  stripes = 0.5 + 0.5 * np.sign(np.sin(4. * x[floor] + 2. * z[floor]))
  albedo[floor] = (0.25 + 0.6 * stripes[..., None]) * np.array([0.9, 0.8, 0.6])
  for s in range(len(_SPHERES)):
    sel = kind == 2 + s
    cx, cy, cz, _, freq, phase = _SPHERES[s]
    local = points[sel] - np.array([cx, cy, cz])
    pattern = np.sin(freq * local[..., 0]) * np.cos(freq * local[..., 1]) + 2. * local[..., 2]
    albedo[sel] = palette(2.5 * pattern, np.full(pattern.shape, phase))
  lambert = np.clip(np.sum(normals * _LIGHT, -1), 0., 1.)
  return albedo * (0.35 + 0.65 * lambert[..., None])


def _cast(origins, dirs):
  """Nearest hit of each ray. Returns (t [...], points, normals, kind int [...])."""
  shape = dirs.shape[:-1]
  t_best = (_WALL_Z - origins[..., 2]) / dirs[..., 2]
  kind = np.zeros(shape, int)
  normals = np.broadcast_to(np.array([0., 0., 1.]), dirs.shape).copy()
  with np.errstate(divide='ignore', invalid='ignore'):
    t_floor = (_FLOOR_Y - origins[..., 1]) / dirs[..., 1]
  hit = (t_floor > 0) & (t_floor < t_best)
  t_best = np.where(hit, t_floor, t_best)
  kind[hit] = 1
  normals[hit] = [0., 1., 0.]
  for s, (cx, cy, cz, r, _, _) in enumerate(_SPHERES):
    oc = origins - np.array([cx, cy, cz])
    b = np.sum(oc * dirs, -1)
    c = np.sum(oc * oc, -1) - r * r
    a = np.sum(dirs * dirs, -1)
    disc = b * b - a * c
    t_s = np.where(disc > 0, (-b - np.sqrt(np.maximum(disc, 0.))) / a, np.inf)
    hit = (t_s > 0) & (t_s < t_best)
    t_best = np.where(hit, t_s, t_best)
    kind[hit] = 2 + s
    pts = origins + t_s[..., None] * dirs
    normals[hit] = (pts[hit] - np.array([cx, cy, cz])) / r
  points = origins + t_best[..., None] * dirs
  return t_best, points, normals, kind


def camera_poses(n_views):
  """n_views cameras on a spiral in the z = 0 plane, looking at (0, 0, -4.2). [N, 3, 4]."""
  poses = []
  target = np.array([0., 0., -4.2])
  for i in range(n_views):
    angle = 2. * np.pi * 2. * i / n_views
    radius = 0.35 + 0.65 * (i / max(n_views - 1, 1))
    pos = np.array([0.5 * radius * np.cos(angle), 0.32 * radius * np.sin(angle),
                    0.08 * np.sin(3. * angle)])
    poses.append(cameras.view_matrix(pos - target, np.array([0., 1., 0.]), pos))
  return np.stack(poses)


def camera_directions(h, w, focal, supersample):
  """Directions (camera frame, OpenGL: x right, y up, z = -1) through the centres of the
  supersample^2 sub-pixels of every pixel of a centred pinhole. [H ss, W ss, 3]."""
  ss = supersample
  ys, xs = np.meshgrid(np.arange(h * ss), np.arange(w * ss), indexing='ij')
  return np.stack([(xs + 0.5 - 0.5 * w * ss) / (focal * ss),
                   -(ys + 0.5 - 0.5 * h * ss) / (focal * ss), -np.ones(xs.shape)], -1)


def render_views(poses, h, w, focal, supersample=2):
  """Ray-casts the scene. Returns (images [N, H, W, 3], z-depths [N, H, W])."""
  ss = supersample
  dirs_cam = camera_directions(h, w, focal, ss)
  images, depths = [], []
  for c2w in poses:
    dirs = dirs_cam @ c2w[:3, :3].T
    origins = np.broadcast_to(c2w[:3, 3], dirs.shape)
    t, points, normals, kind = _cast(origins, dirs)
    rgb = _shade(points, normals, kind, None)
    images.append(rgb.reshape(h, ss, w, ss, 3).mean((1, 3)))
    depths.append(t.reshape(h, ss, w, ss).mean((1, 3)))  # |dir_cam.z| = 1: t = z-depth.
  return np.clip(np.stack(images), 0., 1.), np.stack(depths)


def load_procedural(config) -> Scene:
  """Builds the embedded scene at config.procedural_size with config.procedural_views
  cameras, processed like LLFF (bounds from the true depths, rescale, recentre, NDC;
  Scene.world_bounds from the frusta as for LLFF)."""
  h, w = config.procedural_size
  focal = 1.05 * w
  poses = camera_poses(config.procedural_views)
  images, depths = render_views(poses, h, w, focal)
  bounds = np.stack([np.percentile(depths.reshape(len(poses), -1), 0.1, axis=1) * 0.9,
                     np.percentile(depths.reshape(len(poses), -1), 99.9, axis=1) * 1.1], -1)
  poses, bounds, scale = cameras.process_llff_poses(poses, bounds)
  train_idx, val_idx, test_idx = split_of(config, poses, 'the procedural scene')
  near, far = (0., 1.) if config.use_ndc else (float(bounds.min() * .9), float(bounds.max()))
  return Scene(name='procedural', images=images.astype(np.float32),
               poses=poses.astype(np.float32), focal=float(focal), near=near, far=far,
               use_ndc=config.use_ndc, white_bkgd=False, train_idx=train_idx,
               test_idx=test_idx, val_idx=val_idx, depths=(depths * scale).astype(np.float32),
               forward_facing=True, focus_depth=focus_depth_from_bounds(bounds),
               bbox=((-1.,) * 3, (1.,) * 3) if config.use_ndc else ((-far,) * 3, (far,) * 3),
               world_bounds=frustum_bounds(poses[train_idx], bounds[train_idx], focal, h, w))
