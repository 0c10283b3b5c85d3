"""Cameras and rays: pinhole rays, NDC, LLFF pose handling.

Conventions (NeRF / OpenGL): a camera-to-world matrix `c2w` is [..., 3, 4]; its rotation
columns are the camera's x (right), y (up) and z (back) axes, so the camera looks along -z;
the last column is the camera centre. Pixel (x, y) has its centre at (x + 0.5, y + 0.5),
x to the right, y down. Works with numpy and jax.numpy arrays alike (pure jnp functions).
"""
import flax
import jax.numpy as jnp
import numpy as np


@flax.struct.dataclass
class Rays:
  """A batch of rays; every field has the same leading shape [...]."""
  origins: jnp.ndarray  # [..., 3]
  directions: jnp.ndarray  # [..., 3], unnormalised (unit z in camera space).
  viewdirs: jnp.ndarray  # [..., 3], unit world-space viewing directions.
  radii: jnp.ndarray  # [..., 1], base radius of the cone at distance 1.
  near: jnp.ndarray  # [..., 1]
  far: jnp.ndarray  # [..., 1]


def distort(x, y, dist):
  """OpenCV's radial-tangential distortion of normalised image coordinates.

  Args:
    x, y: [...] undistorted normalised coordinates (x right, y down, z = 1).
    dist: (k1, k2, p1, p2).

  Returns:
    (xd, yd): the distorted coordinates.
  """
  k1, k2, p1, p2 = dist
  r2 = x * x + y * y
  radial = 1. + r2 * (k1 + k2 * r2)
  return (x * radial + 2. * p1 * x * y + p2 * (r2 + 2. * x * x),
          y * radial + p1 * (r2 + 2. * y * y) + 2. * p2 * x * y)


def undistort(xd, yd, dist, iterations=10):
  """Inverts `distort` by Newton's method started at the distorted point (as COLMAP and
  nerfstudio do); exact for dist = 0, to float precision after a few iterations for the
  distortions of real lenses.

  Args:
    xd, yd: [...] distorted normalised coordinates. dist: (k1, k2, p1, p2).
    iterations: Newton steps (static).

  Returns:
    (x, y) with distort(x, y, dist) = (xd, yd).
  """
  k1, k2, p1, p2 = dist
  x, y = xd, yd
  for _ in range(iterations):
    fx, fy = distort(x, y, dist)
    fx, fy = fx - xd, fy - yd
    r2 = x * x + y * y
    radial = 1. + r2 * (k1 + k2 * r2)
    d_radial = k1 + 2. * k2 * r2  # d radial / d r2
    j_xx = radial + 2. * x * x * d_radial + 2. * p1 * y + 6. * p2 * x
    j_xy = 2. * x * y * d_radial + 2. * p1 * x + 2. * p2 * y
    j_yx = 2. * x * y * d_radial + 2. * p1 * x + 2. * p2 * y
    j_yy = radial + 2. * y * y * d_radial + 6. * p1 * y + 2. * p2 * x
    det = j_xx * j_yy - j_xy * j_yx
    det = jnp.where(jnp.abs(det) > 1e-12, det, 1e-12)
    x = x - (j_yy * fx - j_xy * fy) / det
    y = y - (j_xx * fy - j_yx * fx) / det
  return x, y


def pixel_directions(pix_x, pix_y, focal, h, w, intrinsics=None):
  """Camera-space ray directions through pixel centres.

  Args:
    pix_x, pix_y: [...] pixel column and row indices (float or int).
    focal: focal length in pixels.
    h, w: image height and width (principal point at the image centre).
    intrinsics: None (the pinhole above), or (fx, fy, cx, cy, k1, k2, p1, p2): focal
      lengths and principal point in pixels (pixel i spans [i, i + 1]) and OpenCV
      distortion, undone on the normalised coordinates (static tuple).

  Returns:
    [..., 3] directions with z = -1.
  """
  if intrinsics is None:
    x = (pix_x + 0.5 - 0.5 * w) / focal
    y = -(pix_y + 0.5 - 0.5 * h) / focal
    return jnp.stack([x, y, -jnp.ones_like(x)], axis=-1)
  fx, fy, cx, cy = intrinsics[:4]
  x = (pix_x + 0.5 - cx) / fx
  y = (pix_y + 0.5 - cy) / fy  # OpenCV axes: y down.
  dist = tuple(intrinsics[4:8])
  if any(d != 0. for d in dist):
    x, y = undistort(x, y, dist)
  return jnp.stack([x, -y, -jnp.ones_like(x)], axis=-1)


def convert_to_ndc(origins, directions, focal, h, w, near=1.):
  """Maps rays to normalised device coordinates of a forward-facing scene.

  The ray is first moved to the plane z = -near; then (x, y, z) -> (-f x / (w/2 z),
  -f y / (h/2 z), 1 + 2 near / z). Depth in [near, inf) maps to NDC z in [-1, 1), so the
  NDC ray runs over t in [0, 1]. Rays nearly parallel to the image plane (|d_z| ~ 0) are
  clamped to a tiny forward component, giving large but finite coordinates.

  Args:
    origins, directions: [..., 3] world-space rays (camera looking along -z).
    focal, h, w: pinhole intrinsics.
    near: the near plane mapped to NDC z = -1.

  Returns:
    (origins_ndc, directions_ndc), each [..., 3].
  """
  eps = 1e-6
  dz = directions[..., 2]
  dz = jnp.where(jnp.abs(dz) < eps, jnp.where(dz > 0, eps, -eps), dz)
  directions = jnp.concatenate([directions[..., :2], dz[..., None]], axis=-1)
  t = -(near + origins[..., 2]) / dz
  origins = origins + t[..., None] * directions
  ox, oy, oz = origins[..., 0], origins[..., 1], origins[..., 2]
  dx, dy = directions[..., 0], directions[..., 1]
  ax, ay = -2. * focal / w, -2. * focal / h
  o_ndc = jnp.stack([ax * ox / oz, ay * oy / oz, 1. + 2. * near / oz], axis=-1)
  d_ndc = jnp.stack([ax * (dx / dz - ox / oz), ay * (dy / dz - oy / oz), -2. * near / oz],
                    axis=-1)
  return o_ndc, d_ndc


def _world_rays(c2w, pix_x, pix_y, focal, h, w, intrinsics=None):
  dirs_cam = pixel_directions(pix_x, pix_y, focal, h, w, intrinsics)
  rot = c2w[..., :3, :3]
  directions = jnp.einsum('...ij,...j->...i', rot, dirs_cam)
  origins = jnp.broadcast_to(c2w[..., :3, 3], directions.shape)
  return origins, directions


def pixel_rays(c2w, pix_x, pix_y, focal, h, w, use_ndc, near, far, intrinsics=None):
  """Rays through arbitrary pixels of pinhole cameras, with mip-NeRF cone radii.

  The radius is the distance to the ray of the pixel one row below, times 2 / sqrt(12)
  (the std of a pixel-wide box): between directions in world space, or between origins in
  NDC space (where all NDC directions start on the near plane).

  Args:
    c2w: [..., 3, 4] camera-to-world matrices broadcasting against pix_x.
    pix_x, pix_y: [...] pixel coordinates.
    focal, h, w: pinhole intrinsics.
    intrinsics: None, or a static (fx, fy, cx, cy, k1, k2, p1, p2) (pixel_directions;
      not with use_ndc, whose mapping assumes the centred pinhole).
    use_ndc: static bool; convert to NDC (forward-facing scenes).
    near, far: scalar bounds stored per ray (NDC: 0 and 1).

  Returns:
    Rays with leading shape [...].
  """
  if use_ndc and intrinsics is not None:
    raise ValueError('NDC rays need the centred pinhole camera (intrinsics=None)')
  origins, directions = _world_rays(c2w, pix_x, pix_y, focal, h, w, intrinsics)
  _, directions_below = _world_rays(c2w, pix_x, pix_y + 1., focal, h, w, intrinsics)
  viewdirs = directions / jnp.linalg.norm(directions, axis=-1, keepdims=True)
  if use_ndc:
    origins, directions_ndc = convert_to_ndc(origins, directions, focal, h, w)
    origins_below, _ = convert_to_ndc(
        jnp.broadcast_to(c2w[..., :3, 3], directions_below.shape), directions_below,
        focal, h, w)
    dx = jnp.linalg.norm(origins_below - origins, axis=-1, keepdims=True)
    directions = directions_ndc
  else:
    dx = jnp.linalg.norm(directions_below - directions, axis=-1, keepdims=True)
  radii = dx * 2. / np.sqrt(12.)
  ones = jnp.ones_like(radii)
  return Rays(origins=origins, directions=directions, viewdirs=viewdirs, radii=radii,
              near=ones * near, far=ones * far)


def image_rays(c2w, h, w, focal, use_ndc, near, far, intrinsics=None):
  """All rays of an h x w image of one camera, shaped [h, w] (intrinsics: pixel_rays)."""
  pix_x, pix_y = jnp.meshgrid(jnp.arange(w, dtype=jnp.float32),
                              jnp.arange(h, dtype=jnp.float32), indexing='xy')
  return pixel_rays(jnp.asarray(c2w, jnp.float32)[None, None], pix_x, pix_y, focal, h, w,
                    use_ndc, near, far, intrinsics)


def normalize(x):
  return x / np.linalg.norm(x, axis=-1, keepdims=True)


def view_matrix(lookdir, up, position):
  """Camera-to-world matrix from a back (z) axis, an up hint and a centre.

  Args:
    lookdir: [3] the camera's z axis (back direction, as in LLFF's averaging).
    up: [3] approximate up vector.
    position: [3] camera centre.

  Returns:
    [3, 4] camera-to-world matrix.
  """
  vec2 = normalize(lookdir)
  vec0 = normalize(np.cross(up, vec2))
  vec1 = normalize(np.cross(vec2, vec0))
  return np.stack([vec0, vec1, vec2, position], axis=1)


def average_pose(poses):
  """The mean camera of [N, 3, 4] poses: mean centre, mean z axis, mean y axis."""
  position = poses[:, :3, 3].mean(0)
  z_axis = poses[:, :3, 2].sum(0)
  up = poses[:, :3, 1].sum(0)
  return view_matrix(z_axis, up, position)


def recenter_poses(poses):
  """Expresses poses [N, 3, 4] in the frame of their average pose.

  Returns:
    (recentred poses [N, 3, 4], the 4x4 world-to-new-world transform).
  """
  bottom = np.array([[0, 0, 0, 1.]])
  avg = np.concatenate([average_pose(poses), bottom], 0)
  transform = np.linalg.inv(avg)
  full = np.concatenate([poses, np.broadcast_to(bottom, (poses.shape[0], 1, 4))], 1)
  return (transform @ full)[:, :3, :4], transform


def llff_to_opengl(poses):
  """LLFF's camera axes [down, right, back] -> [right, up, back]. poses: [N, 3, >=4]."""
  return np.concatenate([poses[:, :, 1:2], -poses[:, :, 0:1], poses[:, :, 2:]], axis=-1)


def process_llff_poses(poses, bounds, bd_factor=0.75):
  """LLFF normalisation: rescale so the nearest bound is 1/bd_factor, then recentre.

  Args:
    poses: [N, 3, 4] OpenGL-convention camera-to-world matrices.
    bounds: [N, 2] near/far depth bounds per image.
    bd_factor: RegNeRF/mip-NeRF use 0.75 (scale = 1 / (0.75 * min bound)).

  Returns:
    (poses [N, 3, 4], bounds [N, 2], scale).
  """
  scale = 1. / (bounds.min() * bd_factor)
  poses = poses.copy()
  poses[:, :3, 3] *= scale
  bounds = bounds * scale
  poses, _ = recenter_poses(poses)
  return poses, bounds, scale
