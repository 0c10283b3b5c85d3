"""COLMAP's sparse model files, read with numpy: cameras, images and points3D, in the
binary (`.bin`) and the text (`.txt`) forms COLMAP writes (`model_converter`).

The formats (COLMAP's `src/colmap/scene/reconstruction_io.cc`, little-endian):
  cameras.bin   uint64 n; per camera int32 id, int32 model id, uint64 width, height,
                float64 params[k] (k by model)
  images.bin    uint64 n; per image int32 id, float64 qw qx qy qz, tx ty tz (world to
                camera), int32 camera id, the name ending in a 0 byte, uint64 m, then m x
                (float64 x, y, int64 point3D id)
  points3D.bin  uint64 n; per point uint64 id, float64 x y z, uint8 r g b, float64
                error, uint64 t, then t x (int32 image id, int32 point2D index)
and the text files hold the same fields, one camera / point a line, two lines an image,
'#' lines as comments. Every problem is one DataError line naming the file.
"""
import os
import struct

import numpy as np

from renerf_jax.errors import DataError

# COLMAP's camera models: id -> (name, number of parameters).
CAMERA_MODELS = {0: ('SIMPLE_PINHOLE', 3), 1: ('PINHOLE', 4), 2: ('SIMPLE_RADIAL', 4),
                 3: ('RADIAL', 5), 4: ('OPENCV', 8), 5: ('OPENCV_FISHEYE', 8),
                 6: ('FULL_OPENCV', 12), 7: ('FOV', 5), 8: ('SIMPLE_RADIAL_FISHEYE', 4),
                 9: ('RADIAL_FISHEYE', 5), 10: ('THIN_PRISM_FISHEYE', 12),
                 11: ('RAD_TAN_THIN_PRISM_FISHEYE', 16)}
MODEL_PARAMS = {name: k for name, k in CAMERA_MODELS.values()}
# The models whose rays the project makes: pinhole with OpenCV's k1 k2 p1 p2.
SUPPORTED_MODELS = ('SIMPLE_PINHOLE', 'PINHOLE', 'SIMPLE_RADIAL', 'RADIAL', 'OPENCV')


def opencv_intrinsics(model, params, path):
  """(fx, fy, cx, cy, k1, k2, p1, p2) of a supported camera model's parameters.

  Args:
    model: the COLMAP model name. params: its parameters, COLMAP's order.
    path: the file, for the error line.
  """
  p = [float(v) for v in params]
  if model == 'SIMPLE_PINHOLE':
    return (p[0], p[0], p[1], p[2], 0., 0., 0., 0.)
  if model == 'PINHOLE':
    return (p[0], p[1], p[2], p[3], 0., 0., 0., 0.)
  if model == 'SIMPLE_RADIAL':
    return (p[0], p[0], p[1], p[2], p[3], 0., 0., 0.)
  if model == 'RADIAL':
    return (p[0], p[0], p[1], p[2], p[3], p[4], 0., 0.)
  if model == 'OPENCV':
    return tuple(p)
  raise DataError(f'{path}: camera model {model} is not supported (pinhole with k1 k2 p1 '
                  f'p2: {", ".join(SUPPORTED_MODELS)})')


class _Reader:
  """Sequential reads from a binary file's bytes; DataError naming it when short."""

  def __init__(self, path):
    self.path = path
    try:
      with open(path, 'rb') as f:
        self.data = f.read()
    except OSError as e:
      raise DataError(f'cannot read {path}: {type(e).__name__}: {e}') from None
    self.pos = 0

  def read(self, fmt, count=1):
    size = struct.calcsize('<' + fmt) * count
    if self.pos + size > len(self.data):
      raise DataError(f'{self.path}: truncated (ends at byte {len(self.data)}, '
                      f'{self.pos + size} needed)')
    out = struct.unpack_from('<' + fmt * count, self.data, self.pos)
    self.pos += size
    return out

  def array(self, dtype, count):
    dtype = np.dtype(dtype).newbyteorder('<')
    size = dtype.itemsize * count
    if self.pos + size > len(self.data):
      raise DataError(f'{self.path}: truncated (ends at byte {len(self.data)}, '
                      f'{self.pos + size} needed)')
    out = np.frombuffer(self.data, dtype, count, self.pos)
    self.pos += size
    return out

  def name(self):
    end = self.data.find(b'\0', self.pos)
    if end < 0:
      raise DataError(f'{self.path}: truncated (an image name has no end)')
    out = self.data[self.pos:end].decode('utf-8', 'replace')
    self.pos = end + 1
    return out

  def finish(self):
    if self.pos != len(self.data):
      raise DataError(f'{self.path}: {len(self.data) - self.pos} bytes after the last '
                      'record (not a COLMAP model file?)')


def _count(reader, limit):
  (n,) = reader.read('Q')
  if n > limit:  # Each record takes at least a few bytes: a wrong file, not a huge one.
    raise DataError(f'{reader.path}: claims {n} records in {len(reader.data)} bytes '
                    '(not a COLMAP model file?)')
  return n


def read_cameras_bin(path):
  """{camera id: (model name, width, height, params tuple)} of cameras.bin."""
  r = _Reader(path)
  out = {}
  for _ in range(_count(r, len(r.data) // 24)):
    cam_id, model_id = r.read('i', 2)
    width, height = r.read('Q', 2)
    if model_id not in CAMERA_MODELS:
      raise DataError(f'{path}: camera {cam_id} has an unknown model id {model_id}')
    name, k = CAMERA_MODELS[model_id]
    if width < 1 or height < 1:
      raise DataError(f'{path}: camera {cam_id} is {width}x{height} pixels')
    out[cam_id] = (name, int(width), int(height), r.read('d', k))
  r.finish()
  return out


def read_images_bin(path):
  """[(image id, qvec (w x y z), tvec, camera id, name, point3D ids int64 [m])] of
  images.bin, in the file's order (-1: a 2D point with no 3D point)."""
  r = _Reader(path)
  out = []
  for _ in range(_count(r, len(r.data) // 64)):
    (image_id,) = r.read('i')
    qt = r.read('d', 7)
    (cam_id,) = r.read('i')
    name = r.name()
    (m,) = r.read('Q')
    rows = r.array([('x', 'f8'), ('y', 'f8'), ('id', 'i8')], m)
    out.append((image_id, qt[:4], qt[4:], cam_id, name, np.asarray(rows['id'])))
  r.finish()
  return out


def read_points_bin(path):
  """(ids int64 [P], xyz float64 [P, 3], rgb uint8 [P, 3], tracks: list of int32 image
  id arrays) of points3D.bin."""
  r = _Reader(path)
  n = _count(r, len(r.data) // 51)
  ids, xyz, rgb, tracks = np.zeros(n, np.int64), np.zeros((n, 3)), np.zeros(
      (n, 3), np.uint8), []
  for i in range(n):
    (ids[i],) = r.read('Q')
    xyz[i] = r.read('d', 3)
    rgb[i] = r.read('B', 3)
    r.read('d')  # Reprojection error.
    (t,) = r.read('Q')
    tracks.append(np.asarray(r.array('i4', 2 * t)[::2]))
  r.finish()
  return ids, xyz, rgb, tracks


def _text_rows(path):
  """The non-comment lines of a COLMAP text file, split on whitespace, with line numbers
  (an empty line is kept: images.txt's points line may be empty)."""
  try:
    with open(path) as f:
      lines = f.read().splitlines()
  except (OSError, UnicodeDecodeError) as e:
    raise DataError(f'cannot read {path}: {type(e).__name__}: {e}') from None
  return [(i + 1, line.split()) for i, line in enumerate(lines)
          if not line.lstrip().startswith('#')]


def _numbers(path, line, fields, kind, where):
  try:
    return [kind(v) for v in fields]
  except ValueError:
    raise DataError(f'{path}: line {line}: {where} is not a number: {" ".join(fields)}') \
        from None


def read_cameras_txt(path):
  """As read_cameras_bin, from cameras.txt (CAMERA_ID MODEL WIDTH HEIGHT PARAMS[])."""
  out = {}
  for line, f in _text_rows(path):
    if not f:
      continue
    if len(f) < 4 or f[1] not in MODEL_PARAMS:
      raise DataError(f'{path}: line {line}: not "CAMERA_ID MODEL WIDTH HEIGHT PARAMS" '
                      f'with a COLMAP model: {" ".join(f)}')
    k = MODEL_PARAMS[f[1]]
    if len(f) != 4 + k:
      raise DataError(f'{path}: line {line}: model {f[1]} has {k} parameters, the line '
                      f'{len(f) - 4}')
    cam_id, w, h = _numbers(path, line, [f[0], f[2], f[3]], int, 'an id or size')
    if w < 1 or h < 1:
      raise DataError(f'{path}: line {line}: camera {cam_id} is {w}x{h} pixels')
    out[cam_id] = (f[1], w, h, tuple(_numbers(path, line, f[4:], float, 'a parameter')))
  return out


def read_images_txt(path):
  """As read_images_bin, from images.txt (IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME,
  then a line of X Y POINT3D_ID triples)."""
  rows = _text_rows(path)
  out, j = [], 0
  while j < len(rows):
    line, f = rows[j]
    if not f:  # A blank line where an image line is due (COLMAP's reader skips it too).
      j += 1
      continue
    if len(f) < 10:
      raise DataError(f'{path}: line {line}: not "IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID '
                      f'NAME": {" ".join(f)}')
    nums = _numbers(path, line, f[1:8], float, 'a pose value')
    image_id, cam_id = _numbers(path, line, [f[0], f[8]], int, 'an id')
    pts_line, pts = rows[j + 1] if j + 1 < len(rows) else (line + 1, [])
    if len(pts) % 3:
      raise DataError(f'{path}: line {pts_line}: the points line is not X Y POINT3D_ID '
                      'triples')
    ids = np.asarray(_numbers(path, pts_line, pts[2::3], int, 'a point id'), np.int64)
    out.append((image_id, tuple(nums[:4]), tuple(nums[4:]), cam_id, ' '.join(f[9:]), ids))
    j += 2
  return out


def read_points_txt(path):
  """As read_points_bin, from points3D.txt (POINT3D_ID X Y Z R G B ERROR TRACK[])."""
  ids, xyz, rgb, tracks = [], [], [], []
  for line, f in _text_rows(path):
    if not f:
      continue
    if len(f) < 8 or (len(f) - 8) % 2:
      raise DataError(f'{path}: line {line}: not "POINT3D_ID X Y Z R G B ERROR TRACK[]"')
    ids.append(_numbers(path, line, f[:1], int, 'the id')[0])
    xyz.append(_numbers(path, line, f[1:4], float, 'a position'))
    rgb.append(_numbers(path, line, f[4:7], int, 'a colour'))
    if not all(0 <= v <= 255 for v in rgb[-1]):
      raise DataError(f'{path}: line {line}: a colour outside 0-255: {" ".join(f[4:7])}')
    tracks.append(np.asarray(_numbers(path, line, f[8::2], int, 'an image id'), np.int32))
  return (np.asarray(ids, np.int64), np.asarray(xyz, np.float64).reshape(-1, 3),
          np.asarray(rgb, np.uint8).reshape(-1, 3), tracks)


def model_files(model_dir):
  """The cameras, images and points3D files of a model folder, binary first.

  Returns:
    (cameras path, images path, points path, 'bin' or 'txt'); DataError naming the
    folder where neither form is complete.
  """
  for ext in ('bin', 'txt'):
    paths = [os.path.join(model_dir, f'{n}.{ext}') for n in ('cameras', 'images', 'points3D')]
    if all(os.path.isfile(p) for p in paths):
      return (*paths, ext)
  raise DataError(f'{model_dir}: no COLMAP model (cameras, images and points3D as .bin '
                  'or .txt)')


def read_model(model_dir):
  """A COLMAP sparse model: (cameras, images, points) as the read_* functions return them
  (the .bin files where all three are there, else the .txt files)."""
  cams, imgs, pts, ext = model_files(model_dir)
  if ext == 'bin':
    return read_cameras_bin(cams), read_images_bin(imgs), read_points_bin(pts)
  return read_cameras_txt(cams), read_images_txt(imgs), read_points_txt(pts)
