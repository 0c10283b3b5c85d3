"""Resampling distorted photos to a centred pinhole camera (COLMAP's image undistorter).

A capture with OpenCV distortion and an off-centre principal point (transforms.json's
`fl_x fl_y cx cy k1 k2 p1 p2`) renders as a centred pinhole camera of one focal length
after resampling: each output pixel's ray is mapped through the distortion into the photo
(cameras.distort: the forward model is closed form, so no inversion is needed) and the
photo is sampled bilinearly there. The output keeps the photo's size; its focal length is
the smallest (within 1e-4) at which every output pixel lands inside the photo, so the
border that no photo pixel covers is cropped away, as COLMAP does by default.
"""
import numpy as np

from renerf_jax import cameras


def _sources(focal, h, w, intrinsics, border=False):
  """Source pixel positions (x, y; pixel i's centre at i) of the pixels of the centred
  h x w pinhole camera of `focal` (pixels), through the photo's intrinsics: [h, w]
  each, or [2 (h + w)] of the image's outline alone with `border`."""
  fx, fy, cx, cy = intrinsics[:4]
  if border:
    u = np.concatenate([np.arange(w), np.arange(w), np.zeros(h), np.full(h, w - 1.)])
    v = np.concatenate([np.zeros(w), np.full(w, h - 1.), np.arange(h), np.arange(h)])
  else:
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
  x = (u + 0.5 - 0.5 * w) / focal
  y = (v + 0.5 - 0.5 * h) / focal
  xd, yd = cameras.distort(x, y, tuple(float(d) for d in intrinsics[4:8]))
  return fx * xd + cx - 0.5, fy * yd + cy - 0.5


def _inside(focal, h, w, intrinsics, border=False):
  sx, sy = _sources(focal, h, w, intrinsics, border)
  return bool(np.all((sx >= 0.) & (sx <= w - 1.) & (sy >= 0.) & (sy <= h - 1.)))


def pinhole_focal(h, w, intrinsics, border=False):
  """The smallest focal length (pixels, within 1e-4 relative) of a centred h x w pinhole
  camera whose every pixel maps inside the photo of `intrinsics`.

  Args:
    h, w: the photo's size.
    intrinsics: (fx, fy, cx, cy, k1, k2, p1, p2), pixel i spanning [i, i + 1].
    border: test the image's outline alone (COLMAP's undistorter does; exact for the
      distortions whose extreme sources lie on the outline, e.g. a small radial k1).

  Returns:
    The focal length; ValueError where no focal up to 100 x max(fx, fy) fits (the
    principal point outside the photo) or one of a quarter of min(fx, fy) does (a
    distortion that folds the image).
  """
  hi = float(max(intrinsics[0], intrinsics[1]))
  while not _inside(hi, h, w, intrinsics, border):
    hi *= 2.
    if hi > 100. * max(intrinsics[0], intrinsics[1]):
      raise ValueError(f'no centred pinhole camera of a {h}x{w} image fits inside the '
                       f'photo of intrinsics {tuple(float(v) for v in intrinsics)}')
  lo = 0.25 * float(min(intrinsics[0], intrinsics[1]))
  if _inside(lo, h, w, intrinsics, border):  # The bisection needs lo outside, hi inside.
    raise ValueError(f'the photo of intrinsics {tuple(float(v) for v in intrinsics)} '
                     f'holds a centred pinhole camera of focal {lo:g}: a distortion that '
                     'folds the image')
  while hi - lo > 1e-4 * hi:
    mid = 0.5 * (lo + hi)
    lo, hi = (lo, mid) if _inside(mid, h, w, intrinsics, border) else (mid, hi)
  return hi


def bilinear(images, sx, sy):
  """Bilinear samples of images [N, H, W, C] at positions sx, sy [h, w] (pixel i's
  centre at i, inside [0, W - 1] x [0, H - 1]): [N, h, w, C]."""
  height, width = images.shape[1:3]
  x0 = np.clip(np.floor(sx).astype(np.int64), 0, width - 2 if width > 1 else 0)
  y0 = np.clip(np.floor(sy).astype(np.int64), 0, height - 2 if height > 1 else 0)
  x1, y1 = np.minimum(x0 + 1, width - 1), np.minimum(y0 + 1, height - 1)
  ax, ay = (sx - x0)[..., None], (sy - y0)[..., None]
  top = images[:, y0, x0] * (1. - ax) + images[:, y0, x1] * ax
  bottom = images[:, y1, x0] * (1. - ax) + images[:, y1, x1] * ax
  return top * (1. - ay) + bottom * ay


def undistort_images(images, intrinsics):
  """Photos of a distorted, off-centre camera resampled to a centred pinhole camera.

  Args:
    images: [N, H, W, C] photos, all of one camera.
    intrinsics: (fx, fy, cx, cy, k1, k2, p1, p2) of that camera (pixel i spans
      [i, i + 1]; OpenCV distortion on normalised coordinates).

  Returns:
    (images [N, H, W, C] of the input dtype, focal): the centred pinhole camera of
    `focal` (pinhole_focal) and the same size, each pixel the photo's bilinear sample
    along that pixel's ray.
  """
  h, w = images.shape[1:3]
  focal = pinhole_focal(h, w, intrinsics)
  sx, sy = _sources(focal, h, w, intrinsics)
  out = bilinear(np.asarray(images, np.float64), sx, sy)
  return out.astype(images.dtype), focal


def undistort_each(images, intrinsics):
  """Photos of one size, each with its own camera, resampled to one shared centred
  pinhole camera (COLMAP captures with a camera per photo).

  Args:
    images: [N, H, W, C] photos. intrinsics: N tuples (fx, fy, cx, cy, k1, k2, p1, p2).

  Returns:
    (images [N, H, W, C] of the input dtype, focal): the shared focal is the largest of
    the photos' pinhole_focal (tested on each outline), so that every output pixel of
    every view lands inside its own photo.
  """
  h, w = images.shape[1:3]
  focal = max(pinhole_focal(h, w, intr, border=True) for intr in set(map(tuple, intrinsics)))
  out = np.empty_like(images)
  for i, intr in enumerate(intrinsics):
    sx, sy = _sources(focal, h, w, intr)
    out[i] = bilinear(np.asarray(images[i:i + 1], np.float64), sx, sy)[0].astype(images.dtype)
  return out, focal
