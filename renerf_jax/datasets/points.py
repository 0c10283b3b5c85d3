"""A capture's SfM points: the `.ply` point files that nerfstudio writes beside
`transforms.json` (`ply_file_path`, COLMAP's sparse points in the json's world frame),
and the points' box.

A vertex element with x y z and red green blue (uint8) properties, in the ascii or the
binary little-/big-endian form; other properties are skipped. numpy only. Every problem
is one DataError line naming the file.
"""
import numpy as np

from renerf_jax.errors import DataError

_PLY_TYPES = {'char': 'i1', 'int8': 'i1', 'uchar': 'u1', 'uint8': 'u1', 'short': 'i2',
              'int16': 'i2', 'ushort': 'u2', 'uint16': 'u2', 'int': 'i4', 'int32': 'i4',
              'uint': 'u4', 'uint32': 'u4', 'float': 'f4', 'float32': 'f4',
              'double': 'f8', 'float64': 'f8'}


def _header(data, path):
  end = data.find(b'end_header')
  if not data.startswith(b'ply') or end < 0:
    raise DataError(f'{path}: not a PLY file (no "ply" ... "end_header" header)')
  body = data.index(b'\n', end) + 1 if b'\n' in data[end:] else len(data)
  lines = data[:end].decode('ascii', 'replace').splitlines()
  fmt, elements = None, []
  for line in lines[1:]:
    f = line.split()
    if not f or f[0] in ('comment', 'obj_info'):
      continue
    if f[0] == 'format':
      fmt = f[1] if len(f) > 1 else None
    elif f[0] == 'element':
      if len(f) != 3 or not f[2].isdigit():
        raise DataError(f'{path}: bad header line {line.strip()!r}')
      elements.append([f[1], int(f[2]), []])
    elif f[0] == 'property' and elements:
      if len(f) < 3:
        raise DataError(f'{path}: bad header line {line.strip()!r}')
      if f[1] == 'list':
        raise DataError(f'{path}: list properties are not supported ({line.strip()})')
      if f[1] not in _PLY_TYPES:
        raise DataError(f'{path}: unknown property type {f[1]!r}')
      elements[-1][2].append((f[2], _PLY_TYPES[f[1]]))
  if fmt not in ('ascii', 'binary_little_endian', 'binary_big_endian'):
    raise DataError(f'{path}: unknown PLY format {fmt!r}')
  return fmt, elements, body


def read_points_ply(path):
  """The vertices of a point .ply file.

  Args:
    path: the file.

  Returns:
    (xyz float64 [P, 3], rgb float32 [P, 3] in [0, 1]); DataError where the file has no
    vertex element with x y z and red green blue, is truncated, or holds a non-finite
    position.
  """
  try:
    with open(path, 'rb') as f:
      data = f.read()
  except OSError as e:
    raise DataError(f'cannot read {path}: {type(e).__name__}: {e}') from None
  fmt, elements, body = _header(data, path)
  if not elements or elements[0][0] != 'vertex':
    raise DataError(f'{path}: the first element is not "vertex"')
  _, n, props = elements[0]
  names = [p[0] for p in props]
  for need in ('x', 'y', 'z', 'red', 'green', 'blue'):
    if need not in names:
      raise DataError(f'{path}: the vertices have no "{need}" property (x y z and red '
                      'green blue are needed)')
  if fmt == 'ascii':
    rows = data[body:].decode('ascii', 'replace').split('\n')
    rows = [r.split() for r in rows if r.strip()][:n]
    if len(rows) < n or any(len(r) < len(props) for r in rows):
      raise DataError(f'{path}: truncated ({len(rows)} of {n} vertices)')
    try:
      table = np.asarray([r[:len(props)] for r in rows], np.float64)
    except ValueError:
      raise DataError(f'{path}: a vertex holds a value that is not a number') from None
    col = lambda name: table[:, names.index(name)]
  else:
    order = '<' if fmt == 'binary_little_endian' else '>'
    dtype = np.dtype([(name, order + t) for name, t in props])
    if len(data) - body < dtype.itemsize * n:
      raise DataError(f'{path}: truncated ({(len(data) - body) // dtype.itemsize} of {n} '
                      'vertices)')
    table = np.frombuffer(data, dtype, n, body)
    col = lambda name: table[name].astype(np.float64)
  xyz = np.stack([col('x'), col('y'), col('z')], -1)
  if not np.all(np.isfinite(xyz)):
    raise DataError(f'{path}: {int(np.sum(~np.isfinite(xyz).all(-1)))} vertices have a '
                    'non-finite position')
  rgb = np.stack([col('red'), col('green'), col('blue')], -1) / 255.
  return xyz, np.clip(rgb, 0., 1.).astype(np.float32)


def points_box(xyz, percentile=1.):
  """The box of the points between the given percentiles of each axis (a few far
  outliers of SfM do not decide it): ((lo x, y, z), (hi x, y, z))."""
  lo = np.percentile(xyz, percentile, axis=0)
  hi = np.percentile(xyz, 100. - percentile, axis=0)
  return tuple(float(v) for v in lo), tuple(float(v) for v in hi)
