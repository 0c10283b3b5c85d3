"""Cameras and images of the web viewer (view.py): pure conversions, no server.

The viewer's browser camera (viser) is OpenCV-style: rotation `wxyz` and `position` of
camera-to-world, looking along +z with -y up, and a vertical field of view. Our poses
are OpenGL camera-to-world [3, 4] (looking along -z, +y up). A render at the browser's
camera is a Scene with the browser's image size and focal and no photos (view_scene).
"""
import dataclasses

import numpy as np

from renerf_jax import figures, quaternions
from renerf_jax.datasets.scene import Scene

_GL_TO_CV = np.diag([1., -1., -1.])  # Flips the y and z camera axes (either way round).


def pose_from_browser(wxyz, position) -> np.ndarray:
  """OpenGL camera-to-world [3, 4] of a browser camera.

  Args:
    wxyz: [4] quaternion (w, x, y, z) of the OpenCV camera-to-world rotation.
    position: [3] camera centre in world coordinates.

  Returns:
    [3, 4] float32 OpenGL camera-to-world.
  """
  rot = quaternions.quaternion_to_rotation(np.asarray(wxyz, np.float64)) @ _GL_TO_CV
  return np.concatenate([rot, np.asarray(position, np.float64).reshape(3, 1)],
                        axis=1).astype(np.float32)


def browser_from_pose(pose):
  """(wxyz [4], position [3]) float64 of the browser camera at an OpenGL pose [3, 4]
  (the inverse of pose_from_browser; the rotation is orthonormalised first)."""
  pose = np.asarray(pose, np.float64)
  u, _, vt = np.linalg.svd(pose[:3, :3])
  rot = u @ vt
  return quaternions.rotation_to_quaternion(rot @ _GL_TO_CV), pose[:3, 3].copy()


def browser_pixel(point, wxyz, position, fov, width, height):
  """Where a world point appears in a browser's canvas (pixels from its top left).

  Args:
    point: [3] world point. wxyz, position: the browser camera (OpenCV camera-to-world).
    fov: its vertical field of view (radians). width, height: the canvas in pixels.

  Returns:
    (x, y) floats, or None for a point behind the camera.
  """
  rot = quaternions.quaternion_to_rotation(np.asarray(wxyz, np.float64))
  c = rot.T @ (np.asarray(point, np.float64) - np.asarray(position, np.float64))
  if c[2] <= 0.:
    return None
  f = .5 * height / np.tan(.5 * fov)
  return float(c[0] / c[2] * f + .5 * width), float(c[1] / c[2] * f + .5 * height)


def frustum_centre(pose, scale):
  """World centre of the image plane of a frustum drawn `scale` in front of the camera at
  an OpenGL pose (where a click on the frustum's image lands)."""
  pose = np.asarray(pose, np.float64)
  return pose[:3, 3] - scale * pose[:3, 2]


def fov_y(height: int, focal: float) -> float:
  """Vertical field of view in radians of a pinhole `height` pixels high."""
  return float(2. * np.arctan(0.5 * height / focal))


def focal_for_fov(height: int, fov: float) -> float:
  """Focal length in pixels giving vertical field of view `fov` (radians)."""
  if not 0. < fov < np.pi:
    raise ValueError(f'field of view {fov} rad is outside (0, pi)')
  return float(0.5 * height / np.tan(0.5 * fov))


def render_size(aspect: float, long_side: int):
  """(height, width) of a render with the browser's aspect (width / height) whose longer
  side is `long_side` pixels (each at least 1, the shorter rounded)."""
  if not (np.isfinite(aspect) and aspect > 0.) or long_side < 1:
    raise ValueError(f'bad render size: aspect {aspect}, long side {long_side}')
  if aspect >= 1.:
    return max(1, int(round(long_side / aspect))), int(long_side)
  return int(long_side), max(1, int(round(long_side * aspect)))


def view_scene(scene: Scene, height: int, width: int, focal: float) -> Scene:
  """The scene with a centred pinhole camera of the given size and focal and no photos
  (for rendering at any camera; the rays keep the scene's NDC / near / far)."""
  return dataclasses.replace(scene, images=np.zeros((1, height, width, 3), np.float32),
                             focal=float(focal), intrinsics=None, depths=None)


def scene_camera_scene(scene: Scene) -> Scene:
  """The scene's own camera (its size, focal and intrinsics) without its photos."""
  return dataclasses.replace(scene, images=scene.images[:1] * 0., depths=None)


LAYERS = ('rgb', 'depth', 'acc', 'uncertainty', 'error')


def layer_image(layer: str, out, photo=None, depth_range=None) -> np.ndarray:
  """The picture of one layer of a render.

  Args:
    layer: one of LAYERS: 'rgb'; 'depth' (turbo, near = blue, over depth_range or the
      render's 2-98% quantiles); 'acc' (accumulated opacity, grey); 'uncertainty'
      (1 - acc, the project's default mask signal, turbo over [0, 1]); 'error'
      (|render - photo| averaged over RGB, turbo over [0, 0.25]; needs `photo`).
    out: {'rgb': [H, W, 3], 'depth': [H, W], 'acc': [H, W]} of one view.
    photo: [H, W, 3] real photo at the same camera (for 'error').
    depth_range: (lo, hi) of the depth colour map (None: from the render).

  Returns:
    [H, W, 3] float32 in [0, 1].
  """
  rgb = np.clip(np.asarray(out['rgb'], np.float32), 0., 1.)
  if layer == 'rgb':
    return rgb
  if layer == 'depth':
    d = np.asarray(out['depth'], np.float64)
    d = np.where(np.asarray(out['acc']) > 1e-3, d, np.nan)
    if depth_range is None:
      fin = d[np.isfinite(d)]
      depth_range = ((float(np.quantile(fin, .02)), float(np.quantile(fin, .98)))
                     if fin.size else (0., 1.))
    return figures.colorize(d, lo=depth_range[0], hi=depth_range[1])
  if layer == 'acc':
    return np.repeat(np.clip(np.asarray(out['acc'], np.float32), 0., 1.)[..., None], 3, -1)
  if layer == 'uncertainty':
    return figures.colorize(1. - np.asarray(out['acc'], np.float64), lo=0., hi=1.)
  if layer == 'error':
    if photo is None:
      raise ValueError("layer 'error' needs the photo at the view's camera")
    err = np.mean(np.abs(rgb - np.asarray(photo, np.float32)[..., :3]), axis=-1)
    return figures.colorize(err, lo=0., hi=.25)
  raise ValueError(f'unknown layer {layer!r} ({", ".join(LAYERS)})')


def split_view(left, right, frac: float = .5, line=(1., 1., 1.)) -> np.ndarray:
  """[H, W, 3]: `left` left of column round(frac W), `right` from it on, with a one-pixel
  divider (nerfstudio's split-screen comparison of two models at one camera)."""
  left, right = np.asarray(left, np.float32), np.asarray(right, np.float32)
  if left.shape != right.shape:
    raise ValueError(f'split_view: shapes differ ({left.shape} vs {right.shape})')
  w = left.shape[1]
  c = int(np.clip(round(frac * w), 0, w))
  out = np.concatenate([left[:, :c], right[:, c:]], axis=1)
  if 0 < c < w:
    out[:, c] = line
  return out


def letterbox(image, aspect: float, fill=(0., 0., 0.)) -> np.ndarray:
  """The image centred on a `fill` canvas of the given aspect (width / height), so that a
  render of a photo's camera shows undistorted in a browser window of another shape."""
  image = np.asarray(image, np.float32)
  h, w = image.shape[:2]
  if w / h > aspect:  # Wider than the window: pad above and below.
    ch, cw = int(round(w / aspect)), w
  else:
    ch, cw = h, int(round(h * aspect))
  out = np.empty((max(ch, h), max(cw, w), image.shape[2]), np.float32)
  out[:] = fill
  y0, x0 = (out.shape[0] - h) // 2, (out.shape[1] - w) // 2
  out[y0:y0 + h, x0:x0 + w] = image
  return out


def frustum_scale(poses, frac: float = .25) -> float:
  """A frustum size for drawing cameras: `frac` of the median distance from each camera
  to its nearest neighbour (1 for a single camera or coincident cameras)."""
  c = np.asarray(poses, np.float64)[:, :3, 3]
  if len(c) < 2:
    return 1.
  d = np.linalg.norm(c[:, None] - c[None], axis=-1)
  d[np.diag_indices(len(c))] = np.inf
  nn = np.min(d, axis=1)
  nn = nn[np.isfinite(nn) & (nn > 0)]
  return float(frac * np.median(nn)) if nn.size else 1.


def mean_up(poses) -> np.ndarray:
  """The unit mean of the cameras' up vectors (OpenGL +y columns): the world's up for
  the browser's orbit controls."""
  up = np.asarray(poses, np.float64)[:, :3, 1].mean(0)
  n = np.linalg.norm(up)
  return up / n if n > 0 else np.array([0., 1., 0.])


def masked_view(image, mask, tint=(1., 0., 1.), strength=.6) -> np.ndarray:
  """A pseudo-view with its masked pixels (mask 0: left out of D's loss) tinted."""
  image = np.asarray(image, np.float32)[..., :3]
  m = np.asarray(mask, np.float32)[..., None]
  return m * image + (1. - m) * ((1. - strength) * image + strength * np.asarray(tint))
