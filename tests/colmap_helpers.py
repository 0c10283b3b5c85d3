"""A tiny COLMAP model writer (binary or text), for the tests of datasets/colmap_io.py
and datasets/colmap.py: the same byte layout the reader documents."""
import os
import struct

from renerf_jax.datasets import colmap_io


def _num(v):
  return repr(float(v))


def write_model(model_dir, cameras, images, points, ext='bin'):
  """Writes a model in COLMAP's binary or text form (tests make small models with it).

  Args:
    model_dir: the folder (created). cameras, images, points: as read_model returns
      them (images' point3D ids and points' tracks may be empty).
    ext: 'bin' or 'txt'.
  """
  os.makedirs(model_dir, exist_ok=True)
  ids = {name: i for i, (name, _) in colmap_io.CAMERA_MODELS.items()}
  p = lambda n: os.path.join(model_dir, f'{n}.{ext}')
  ids_pts, xyz, rgb, tracks = points
  if ext == 'txt':
    with open(p('cameras'), 'w') as f:
      f.write('# CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n')
      for c, (m, w, h, prm) in cameras.items():
        f.write(' '.join(map(str, [c, m, w, h, *map(_num, prm)])) + '\n')
    with open(p('images'), 'w') as f:
      for i, q, t, c, name, pids in images:
        f.write(' '.join(map(str, [i, *map(_num, q), *map(_num, t), c, name])) + '\n')
        f.write(' '.join(f'0.0 0.0 {int(v)}' for v in pids) + '\n')
    with open(p('points3D'), 'w') as f:
      for k in range(len(ids_pts)):
        track = ' '.join(f'{int(v)} 0' for v in tracks[k])
        f.write(' '.join(map(str, [int(ids_pts[k]), *map(_num, xyz[k].tolist()),
                                   *rgb[k].tolist(), 0.5])) + (' ' + track if track else '')
                + '\n')
    return
  with open(p('cameras'), 'wb') as f:
    f.write(struct.pack('<Q', len(cameras)))
    for c, (m, w, h, prm) in cameras.items():
      f.write(struct.pack('<iiQQ', c, ids[m], w, h) + struct.pack(f'<{len(prm)}d', *prm))
  with open(p('images'), 'wb') as f:
    f.write(struct.pack('<Q', len(images)))
    for i, q, t, c, name, pids in images:
      f.write(struct.pack('<i7di', i, *q, *t, c) + name.encode() + b'\0')
      f.write(struct.pack('<Q', len(pids)))
      for v in pids:
        f.write(struct.pack('<ddq', 0., 0., int(v)))
  with open(p('points3D'), 'wb') as f:
    f.write(struct.pack('<Q', len(ids_pts)))
    for k in range(len(ids_pts)):
      f.write(struct.pack('<Q3d3Bd', int(ids_pts[k]), *xyz[k].tolist(), *rgb[k].tolist(),
                          0.5))
      f.write(struct.pack('<Q', len(tracks[k])))
      for v in tracks[k]:
        f.write(struct.pack('<ii', int(v), 0))
