"""The standard 3DGS .ply layout: export of the active Gaussians, and a reader.

Binary little-endian float32 vertices with the properties of the reference
implementation's `save_ply`, in this order: x y z, nx ny nz (zeros), f_dc_0..2,
f_rest_0..44 (channel-major: the 15 higher SH coefficients of R, then of G, then of B),
opacity (the logit), scale_0..2 (log scales), rot_0..3 (the quaternion w x y z, not
normalised), so the files open in the usual 3DGS viewers. numpy only.
"""
import numpy as np

from renerf_jax import report
from renerf_jax.errors import DataError
from renerf_jax.gaussians import params as params_lib

NUM_REST = 3 * (params_lib.NUM_SH - 1)  # 45 higher-order SH coefficients.
PROPERTIES = (['x', 'y', 'z', 'nx', 'ny', 'nz'] + [f'f_dc_{i}' for i in range(3)] +
              [f'f_rest_{i}' for i in range(NUM_REST)] + ['opacity'] +
              [f'scale_{i}' for i in range(3)] + [f'rot_{i}' for i in range(4)])


def ply_header(n):
  """The header of a file of n vertices (bytes, ending with 'end_header\\n')."""
  lines = ['ply', 'format binary_little_endian 1.0', f'element vertex {n}']
  lines += [f'property float {p}' for p in PROPERTIES]
  lines += ['end_header']
  return ('\n'.join(lines) + '\n').encode('ascii')


def to_rows(gaussians):
  """[n_active, 62] float32 vertex rows of the active Gaussians, in slot order."""
  active = np.asarray(gaussians.active, bool)
  f = lambda x: np.asarray(x, np.float32)[active]
  n = int(active.sum())
  sh = f(gaussians.sh)  # [n, 16, 3]
  rest = np.transpose(sh[:, 1:], (0, 2, 1)).reshape(n, NUM_REST)  # channel-major
  return np.concatenate([f(gaussians.means), np.zeros((n, 3), np.float32), sh[:, 0],
                         rest, f(gaussians.opacity_logits)[:, None],
                         f(gaussians.log_scales), f(gaussians.quats)], axis=1)


def write_ply(path, gaussians):
  """Writes the active Gaussians to `path` atomically (temp file + rename).

  Args:
    path: destination .ply file (its directory is created).
    gaussians: params.Gaussians.

  Returns:
    The number of Gaussians written.
  """
  rows = to_rows(gaussians)
  with report.atomic_open(path, 'wb') as f:
    f.write(ply_header(rows.shape[0]))
    f.write(rows.astype('<f4').tobytes())
  return rows.shape[0]


def read_ply(path, capacity=None):
  """Reads a file of the 3DGS layout (as write_ply writes it) into Gaussians.

  Args:
    path: .ply file with exactly the PROPERTIES as float vertex properties.
    capacity: slots of the result (>= the vertex count; default the vertex count);
      slots past the vertices are zero and inactive.

  Returns:
    params.Gaussians (numpy arrays).

  Raises:
    DataError (a ValueError): one line naming the file: not a ply file, not this layout
      (e.g. a point cloud without the colours f_dc_0..2: the properties it lacks are
      named), vertex data of the wrong length, NaN or inf values (the first vertex
      named), more vertices than capacity.
  """
  try:
    with open(path, 'rb') as f:
      data = f.read()
  except OSError as e:
    raise DataError(f'cannot read {path}: {type(e).__name__}: {e.strerror}') from None
  end = data.find(b'end_header\n')
  if not data.startswith(b'ply\n') or end < 0:
    raise DataError(f'{path}: not a ply file')
  header = data[:end + len(b'end_header\n')]
  lines = header.decode('ascii', 'replace').splitlines()
  try:
    n = int(lines[2].split()[2])
  except (IndexError, ValueError):
    raise DataError(f'{path}: no vertex count in the header') from None
  if header != ply_header(n):
    names = [line.split()[-1] for line in lines if line.startswith('property ')]
    lacks = [p for p in PROPERTIES if p not in names]
    raise DataError(f'{path}: not the binary little-endian 3DGS layout'
                    + (f' (no {", ".join(lacks[:4])}{", ..." if len(lacks) > 4 else ""})'
                       if lacks else ''))
  body = data[len(header):]
  width = len(PROPERTIES)
  if len(body) != 4 * n * width:
    raise DataError(f'{path}: {len(body)} bytes of vertex data for {n} vertices')
  rows = np.frombuffer(body, '<f4').reshape(n, width).astype(np.float32)
  if not np.all(np.isfinite(rows)):
    bad = np.argwhere(~np.isfinite(rows))[0]
    raise DataError(f'{path}: vertex {bad[0]} has a NaN or inf {PROPERTIES[bad[1]]}')
  capacity = n if capacity is None else capacity
  if capacity < n:
    raise DataError(f'{path}: {n} Gaussians do not fit in capacity {capacity}')
  sh = np.concatenate([rows[:, 6:9, None],
                       rows[:, 9:9 + NUM_REST].reshape(n, 3, 15)], axis=2)
  sh = np.transpose(sh, (0, 2, 1))  # [n, 16, 3]
  o = 9 + NUM_REST

  def pad(x):
    return np.concatenate([x, np.zeros((capacity - n,) + x.shape[1:], x.dtype)])

  return params_lib.Gaussians(
      means=pad(rows[:, :3]), log_scales=pad(rows[:, o + 1:o + 4]),
      quats=pad(rows[:, o + 4:o + 8]), opacity_logits=pad(rows[:, o]), sh=pad(sh),
      active=np.arange(capacity) < n)
