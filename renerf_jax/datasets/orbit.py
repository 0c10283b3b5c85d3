"""The embedded 360-degree scene: objects on a textured floor, cameras orbiting them.

A sphere, a box, a cylinder and a small sphere stand on a tiled floor disc (radius 2.2)
inside an environment dome (radius 7: a sky gradient over a mountain band, whose exact
depth is finite), lit by one directional light with hard shadows and ambient light. The
cameras circle the objects at distance 3.2 on a wavy orbit (elevation 16 to 40 degrees),
looking at (0, 0, 0.35); world z is up. Every Config.llffhold-th camera is a test view
and Config.n_input_views training views are spread over the others as over a
transforms.json capture's (`split.split_views`: evenly from the first to the last, so
on the closed orbit the last and the first are closer: with 48 cameras and 12 views the
gaps are 30 to 37.5 degrees and one of 15), the test views between them.

It is a small stand-in for the wide-baseline captures (lego, fox): occlusions seen from
all sides, texture at several scales, a background that is neither empty nor at one
depth. The rendered cameras go through the transforms.json loader's Scene path
(`transforms.object_scene`: pose normalisation, the scene box, unbounded contraction as
the config asks), and the z-depth maps are kept (Scene.depths: exact per sub-pixel ray,
averaged over each pixel's 2x2 like the colours).
"""
import numpy as np

from renerf_jax import cameras
from renerf_jax.datasets.procedural import camera_directions, palette
from renerf_jax.datasets.scene import Scene
from renerf_jax.datasets.split import split_of
from renerf_jax.datasets.transforms import object_scene

# (centre x, y, z, radius, texture frequency, hue phase)
_SPHERES = np.array([
    [0.45, 0.25, 0.42, 0.42, 10., 0.3],
    [-0.35, 0.68, 0.2, 0.2, 16., 3.6],
])
_BOX = (np.array([-0.72, -0.45, 0.]), np.array([-0.12, 0.05, 0.7]))  # (lo, hi) corners.
_CYLINDER = (0.15, -0.72, 0.2, 0.95)  # centre x, y, radius, height (base on the floor).
_FLOOR_RADIUS = 2.2
_DOME_RADIUS = 7.
_LIGHT = np.array([0.5, -0.35, 0.8]) / np.linalg.norm([0.5, -0.35, 0.8])
_TARGET = np.array([0., 0., 0.35])
_ORBIT_RADIUS = 3.2
# Surface kinds: 0 dome, 1 floor, 2 box, 3 cylinder, 4 + s the spheres.
DOME, FLOOR, BOX, CYLINDER, SPHERE = 0, 1, 2, 3, 4


def _hit_spheres(origins, dirs, t_best, kind, normals):
  """Updates (t_best, kind, normals) in place with the nearer sphere hits."""
  for s, (cx, cy, cz, r, _, _) in enumerate(_SPHERES):
    oc = origins - np.array([cx, cy, cz])
    b = np.sum(oc * dirs, -1)
    disc = b * b - (np.sum(oc * oc, -1) - r * r)  # dirs are unit vectors: a = 1.
    t = np.where(disc > 0, -b - np.sqrt(np.maximum(disc, 0.)), np.inf)
    hit = (t > 1e-6) & (t < t_best)
    t_best[hit] = t[hit]
    kind[hit] = SPHERE + s
    normals[hit] = (origins[hit] + t[hit, None] * dirs[hit] - [cx, cy, cz]) / r


def _hit_box(origins, dirs, t_best, kind, normals):
  """Slab test of the axis-aligned box (from inside: its far wall); updates the nearer
  hits in place, normals facing the ray."""
  lo, hi = _BOX
  with np.errstate(divide='ignore', invalid='ignore'):
    t0, t1 = (lo - origins) / dirs, (hi - origins) / dirs
  t_near = np.nanmax(np.minimum(t0, t1), -1)
  t_far = np.nanmin(np.maximum(t0, t1), -1)
  inside = t_near <= 1e-6
  t = np.where(inside, t_far, t_near)
  hit = (t_near <= t_far) & (t > 1e-6) & (t < t_best)
  axis = np.where(inside, np.argmin(np.maximum(t0, t1), -1),
                  np.argmax(np.minimum(t0, t1), -1))
  t_best[hit] = t[hit]
  kind[hit] = BOX
  n = np.zeros(dirs.shape)
  np.put_along_axis(n, axis[..., None], -np.sign(
      np.take_along_axis(dirs, axis[..., None], -1)), -1)
  normals[hit] = n[hit]


def _hit_cylinder(origins, dirs, t_best, kind, normals):
  """The vertical cylinder's side and top cap; updates the nearer hits in place."""
  cx, cy, r, height = _CYLINDER
  ox, oy = origins[..., 0] - cx, origins[..., 1] - cy
  dx, dy = dirs[..., 0], dirs[..., 1]
  a = dx * dx + dy * dy
  b = ox * dx + oy * dy
  disc = b * b - a * (ox * ox + oy * oy - r * r)
  with np.errstate(divide='ignore', invalid='ignore'):
    t = np.where((disc > 0) & (a > 1e-12), (-b - np.sqrt(np.maximum(disc, 0.))) / a, np.inf)
    z = origins[..., 2] + t * dirs[..., 2]
    t = np.where((z >= 0.) & (z <= height), t, np.inf)
    hit = (t > 1e-6) & (t < t_best)
    t_best[hit] = t[hit]
    kind[hit] = CYLINDER
    p = origins[hit] + t[hit, None] * dirs[hit]
    normals[hit] = np.stack([(p[:, 0] - cx) / r, (p[:, 1] - cy) / r, np.zeros(len(p))], -1)
    t_cap = (height - origins[..., 2]) / dirs[..., 2]
    px, py = ox + t_cap * dx, oy + t_cap * dy
    hit = (t_cap > 1e-6) & (t_cap < t_best) & (px * px + py * py <= r * r)
  t_best[hit] = t_cap[hit]
  kind[hit] = CYLINDER
  normals[hit] = [0., 0., 1.]


def cast(origins, dirs):
  """Nearest hit of each ray (dirs: unit vectors).

  Args:
    origins, dirs: [..., 3] ray origins (inside the dome) and unit directions.

  Returns:
    (t [...], points [..., 3], normals [..., 3], kind int [...]): the distance to the
    nearest surface (always finite: the dome closes the scene), where it is, its normal
    and its kind (DOME, FLOOR, BOX, CYLINDER, SPHERE + s).
  """
  shape = dirs.shape[:-1]
  b = np.sum(origins * dirs, -1)  # The dome, from inside: the far root.
  t_best = -b + np.sqrt(b * b - (np.sum(origins * origins, -1) - _DOME_RADIUS**2))
  kind = np.full(shape, DOME)
  normals = -(origins + t_best[..., None] * dirs) / _DOME_RADIUS
  with np.errstate(divide='ignore', invalid='ignore'):
    t_floor = -origins[..., 2] / dirs[..., 2]
  p_floor = origins + np.where(np.isfinite(t_floor), t_floor, 0.)[..., None] * dirs
  hit = ((t_floor > 1e-6) & (t_floor < t_best) &
         (np.sum(p_floor[..., :2]**2, -1) <= _FLOOR_RADIUS**2))
  t_best[hit] = t_floor[hit]
  kind[hit] = FLOOR
  normals[hit] = [0., 0., 1.]
  for hit_fn in (_hit_box, _hit_cylinder, _hit_spheres):
    hit_fn(origins, dirs, t_best, kind, normals)
  return t_best, origins + t_best[..., None] * dirs, normals, kind


def _albedo(points, kind):
  """Texture colour of each surface point. Returns [..., 3] in [0, 1]."""
  x, y, z = points[..., 0], points[..., 1], points[..., 2]
  out = np.zeros(points.shape)
  sel = kind == DOME  # Sky gradient over a mountain band, both by direction.
  d = points[sel] / _DOME_RADIUS
  az, el = np.arctan2(d[:, 1], d[:, 0]), np.arcsin(np.clip(d[:, 2], -1., 1.))
  ridge = 0.12 + 0.07 * np.sin(3. * az) + 0.04 * np.sin(7. * az + 1.)
  sky = (np.array([0.95, 0.8, 0.6]) + np.clip(el, 0., 1.)[:, None] *
         (np.array([0.35, 0.55, 0.9]) - np.array([0.95, 0.8, 0.6])))
  rock = (0.35 + 0.15 * np.sign(np.sin(9. * az + 14. * el)))[:, None] * np.array(
      [0.55, 0.65, 0.5])
  out[sel] = np.where((el < ridge)[:, None], rock, sky)
  sel = kind == FLOOR  # Tiles of two scales, hue varying across the floor.
  checker = (np.floor(x[sel] * 2.5) + np.floor(y[sel] * 2.5)) % 2
  fine = (np.floor(x[sel] * 10.) + np.floor(y[sel] * 10.)) % 2
  out[sel] = (0.45 + 0.35 * checker + 0.1 * fine)[:, None] * palette(
      0.8 * np.hypot(x[sel], y[sel]), np.full(checker.shape, 1.2))
  sel = kind == BOX
  stripes = 0.5 + 0.5 * np.sign(np.sin(12. * (x[sel] + y[sel]) + 9. * z[sel]))
  out[sel] = (0.3 + 0.6 * stripes)[:, None] * np.array([0.85, 0.45, 0.3])
  sel = kind == CYLINDER
  angle = np.arctan2(y[sel] - _CYLINDER[1], x[sel] - _CYLINDER[0])
  out[sel] = palette(3. * np.sign(np.sin(6. * angle)) + 4. * z[sel],
                      np.full(angle.shape, 4.4))
  for s, (cx, cy, cz, _, freq, phase) in enumerate(_SPHERES):
    sel = kind == SPHERE + s
    local = points[sel] - np.array([cx, cy, cz])
    pattern = np.sin(freq * local[:, 0]) * np.cos(freq * local[:, 1]) + 2. * local[:, 2]
    out[sel] = palette(2.5 * pattern, np.full(pattern.shape, phase))
  return out


def shade(points, normals, kind):
  """Albedo x (ambient + Lambert in the light, zero in shadow); the dome is unlit."""
  lambert = np.clip(np.sum(normals * _LIGHT, -1), 0., 1.)
  lit = kind != DOME
  _, _, _, blocker = cast(points[lit] + 1e-4 * normals[lit],
                          np.broadcast_to(_LIGHT, points[lit].shape))
  light = np.ones(kind.shape)
  light[lit] = 0.4 + 0.6 * lambert[lit] * (blocker == DOME)
  return _albedo(points, kind) * light[..., None]


def camera_poses(n_views):
  """n_views cameras on a wavy orbit around the objects. Returns c2w [N, 3, 4]."""
  poses = []
  for i in range(n_views):
    azimuth = 2. * np.pi * i / n_views
    elevation = np.deg2rad(28. + 12. * np.sin(2. * azimuth))
    pos = _ORBIT_RADIUS * np.array([np.cos(elevation) * np.cos(azimuth),
                                    np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
    poses.append(cameras.view_matrix(pos - _TARGET, np.array([0., 0., 1.]), pos))
  return np.stack(poses)


def render_views(poses, h, w, focal, supersample=2):
  """Ray-casts the scene from OpenGL cameras (pinhole, centred principal point).

  Returns:
    (images [N, H, W, 3] in [0, 1], z-depths [N, H, W]), each pixel the mean of
    supersample^2 sub-pixel rays.
  """
  ss = supersample
  dirs_cam = camera_directions(h, w, focal, ss)
  norm = np.linalg.norm(dirs_cam, axis=-1)
  images, depths = [], []
  for c2w in poses:
    dirs = (dirs_cam / norm[..., None]) @ c2w[:3, :3].T
    t, points, normals, kind = cast(np.broadcast_to(c2w[:3, 3], dirs.shape), dirs)
    rgb = shade(points, normals, kind)
    images.append(rgb.reshape(h, ss, w, ss, 3).mean((1, 3)))
    depths.append((t / norm).reshape(h, ss, w, ss).mean((1, 3)))  # z-depth.
  return np.clip(np.stack(images), 0., 1.), np.stack(depths)


def load_orbit(config) -> Scene:
  """The embedded 360-degree scene at Config.procedural_size (H, W) with
  Config.procedural_views cameras; the split and the Scene as for a transforms.json
  capture (Config.n_input_views, Config.llffhold, Config.normalize_poses, near / far)."""
  h, w = config.procedural_size
  focal = 0.5 * w / np.tan(np.deg2rad(26.))  # A 52-degree horizontal field of view.
  poses = camera_poses(config.procedural_views)
  images, depths = render_views(poses, h, w, focal)
  train_idx, val_idx, test_idx = split_of(config, poses, 'the orbit scene')
  box = ((-_FLOOR_RADIUS,) * 2 + (-0.1,), (_FLOOR_RADIUS,) * 2 + (1.2,))
  return object_scene(config, 'orbit', images, poses, focal, box, train_idx, test_idx,
                      depths=depths, val_idx=val_idx)
