"""Our Gaussians against gsplat's own pure-PyTorch reference functions (issue 33 item 4).

Run once, outside CI, in an environment that has a CPU-capable `torch`, `gsplat` and
`nerfacc` (PyPI) beside renerf_jax; the project's own environment never needs them:

  python -m venv /tmp/gs && /tmp/gs/bin/pip install torch gsplat==1.4.0 nerfacc ninja
  /tmp/gs/bin/pip install -e .
  /tmp/gs/bin/python -m experiments.gsplat_check \
    --out experiments/results/gaussians_gsplat_check

On the same random Gaussians (some behind the camera, on the near plane, huge, tiny,
unnormalised quaternions) and one rotated, translated pinhole camera per seed it
compares, in float32:
  * projection: our projection.project against gsplat.cuda._torch_impl.
    _fully_fused_projection (EWA with the 0.3 px dilation, the 1.3 x fov clamp, the near
    cull, the 3-sigma radius), with 3D covariances from each side's own quaternion and
    scale code (_quat_scale_to_covar_preci): the valid set, 2D means, depths, conics, radii
    (ours follow the reference 3DGS rasteriser's eigenvalue floor, sqrt(max(0.1,
    mid^2 - det)); gsplat floors at 0.01, which changes a few radii by one pixel);
  * spherical harmonics: our params.eval_sh (degree 3) against _spherical_harmonics
    (+ 0.5, clamped at 0, as 3DGS colours them);
  * compositing is not compared: gsplat's only PyTorch compositing (`accumulate`,
    `_rasterize_to_pixels`) runs on nerfacc's and gsplat's CUDA kernels (nerfacc's
    pack_info raises "Only support cuda inputs." on CPU); our tiled rasteriser is
    tested against our dense reference in tests/test_gaussians.py instead.
gsplat's pixel centres are at integer + 0.5 and its camera is OpenCV's (x right, y down,
z forward, world-to-camera view matrices); ours is OpenGL's camera-to-world: the script
converts. Writes <out>/gsplat_check.json and .md with the largest differences.
"""
import argparse
import json
import os

import numpy as np

from experiments.tables import command_line

# pylint: disable=g-import-not-at-top


def make_gaussians(n, seed):
  """Random Gaussians in front of a camera at the origin looking down -z (camera
  coordinates), plus the extreme cases of the issue."""
  rng = np.random.default_rng(seed)
  means = np.c_[rng.uniform(-1.5, 1.5, (n, 2)), rng.uniform(-6., -1., n)]
  log_scales = rng.uniform(-4., -1., (n, 3))
  quats = rng.normal(size=(n, 4)) * rng.uniform(0.2, 5., (n, 1))  # unnormalised
  means[0] = (0., 0., 0.5)  # behind the camera
  means[1] = (0., 0., -0.01)  # on the near plane
  means[2] = (0.1, 0.1, -0.0105)  # just beyond it
  log_scales[3] = (1.5, 1.5, 1.5)  # huge
  log_scales[4] = (-12., -12., -12.)  # tiny
  sh = 0.3 * rng.normal(size=(n, 16, 3))
  f = lambda x: x.astype(np.float32)
  return f(means), f(log_scales), f(quats), f(sh)


def ours(means, log_scales, quats, sh, c2w, focal, h, w, near):
  import jax
  import jax.numpy as jnp
  from renerf_jax.gaussians import params as params_lib
  from renerf_jax.gaussians import projection
  jax.config.update('jax_platforms', 'cpu')
  n = len(means)
  proj = projection.project(jnp.asarray(means), jnp.asarray(log_scales), jnp.asarray(quats),
                            jnp.ones(n, bool), jnp.asarray(c2w), focal, h, w, near)
  dirs = means - c2w[:, 3]
  colours = params_lib.eval_sh(3, jnp.asarray(sh), jnp.asarray(dirs))
  cov3d = params_lib.covariance_3d(jnp.asarray(log_scales), jnp.asarray(quats))
  get = lambda x: np.asarray(jax.device_get(x))
  cov2d = get(proj.cov2d)
  spread = (0.5 * (cov2d[:, 0, 0] - cov2d[:, 1, 1]))**2 + cov2d[:, 0, 1]**2  # mid^2 - det
  return {'spread': spread, 'valid': get(proj.valid), 'means2d': get(proj.means2d), 'depths': get(proj.depths),
          'conics': get(proj.conics), 'radius': get(proj.radius), 'colours': get(colours),
          'cov3d': get(cov3d)}


def theirs(means, log_scales, quats, sh, c2w, focal, h, w, near):
  import torch
  from gsplat.cuda import _torch_impl as ti
  t = lambda x: torch.as_tensor(np.asarray(x, np.float32))
  c2w_cv = np.eye(4, dtype=np.float64)
  c2w_cv[:3, :4] = c2w
  c2w_cv[:3, 1:3] *= -1.  # OpenGL -> OpenCV camera axes
  viewmat = np.linalg.inv(c2w_cv).astype(np.float32)
  K = np.array([[focal, 0., w / 2.], [0., focal, h / 2.], [0., 0., 1.]], np.float32)
  covars, _ = ti._quat_scale_to_covar_preci(  # pylint: disable=protected-access
      t(quats), t(np.exp(log_scales)), compute_covar=True, compute_preci=False,
      triu=False)
  radii, means2d, depths, conics, _ = ti._fully_fused_projection(  # pylint: disable=protected-access
      t(means), covars, t(viewmat)[None], t(K)[None], w, h, eps2d=0.3, near_plane=near)
  dirs = t(means) - t(c2w[:, 3])
  colours = torch.clamp(ti._spherical_harmonics(3, dirs, t(sh)) + 0.5, min=0.)  # pylint: disable=protected-access
  valid = radii[0] > 0
  get = lambda x: x.detach().numpy()
  return {'valid': get(valid), 'means2d': get(means2d[0]), 'depths': get(depths[0]),
          'conics': get(conics[0]), 'radius': get(radii[0]).astype(np.float32),
          'colours': get(colours), 'cov3d': get(covars)}


def compare(a, b, h, w):
  both = a['valid'] & b['valid']
  rel = lambda x, y: float(np.max(np.abs(x - y) / np.maximum(np.abs(y), 1e-3)))
  out = {'gaussians': int(len(a['valid'])), 'valid_ours': int(a['valid'].sum()),
         'valid_gsplat': int(b['valid'].sum()),
         'valid_disagree': int(np.sum(a['valid'] != b['valid'])),
         # Per Gaussian, relative to its covariance's largest entry.
         'cov3d_max_rel': float(np.max(np.abs(a['cov3d'] - b['cov3d']) / np.maximum(
             np.max(np.abs(b['cov3d']), axis=(1, 2), keepdims=True), 1e-30))),
         'means2d_max_abs_px': float(np.max(np.abs(a['means2d'][both] - b['means2d'][both]))),
         'depths_max_rel': rel(a['depths'][both], b['depths'][both]),
         'conics_max_rel': rel(a['conics'][both], b['conics'][both]),
         'radius_max_abs_px': float(np.max(np.abs(a['radius'][both] - b['radius'][both]))),
         'radius_differ': int(np.sum(a['radius'][both] != b['radius'][both])),
         # ... of which the eigenvalue floor decides: the reference 3DGS rasteriser
         # (and ours) takes sqrt(max(0.1, mid^2 - det)), gsplat sqrt(max(0.01, ...)).
         'radius_differ_at_floor': int(np.sum(
             (a['radius'] != b['radius']) & both & (a['spread'] < 0.1))),
         'colours_max_abs': float(np.max(np.abs(a['colours'] - b['colours'])))}
  out['image'] = f'{w}x{h}'
  return out


def main(argv=None):
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--out', required=True)
  p.add_argument('--n', type=int, default=400)
  p.add_argument('--seeds', type=int, nargs='+', default=[0, 1, 2])
  args = p.parse_args(argv)
  import gsplat
  import torch
  h, w, focal, near = 96, 128, 110., 0.01
  rows = []
  for seed in args.seeds:
    means_cam, *rest = make_gaussians(args.n, seed)
    # A rotated, translated camera (so the OpenGL -> OpenCV view-matrix conversion is
    # exercised); the Gaussians keep their place in front of it.
    q, _ = np.linalg.qr(np.random.default_rng(100 + seed).normal(size=(3, 3)))
    rot = (q * np.sign(np.linalg.det(q))).astype(np.float32)
    c2w = np.c_[rot, np.asarray([0.5, -1., 2.], np.float32)]
    g = (means_cam @ rot.T + c2w[:, 3],) + tuple(rest)
    row = compare(ours(*g, c2w, focal, h, w, near), theirs(*g, c2w, focal, h, w, near), h, w)
    rows.append(dict(seed=seed, **row))
    print(json.dumps(rows[-1]))
  os.makedirs(args.out, exist_ok=True)
  command = command_line('experiments.gsplat_check', argv)
  result = {'rows': rows, 'gsplat': gsplat.__version__, 'torch': torch.__version__,
            'command': command}
  from renerf_jax import report
  report.write_json(os.path.join(args.out, 'gsplat_check.json'), result)
  keys = [k for k in rows[0] if k not in ('image',)]
  lines = [f'# Our Gaussians against gsplat {gsplat.__version__} pure-PyTorch reference '
           f'(torch {torch.__version__}, CPU)', '',
           f'{args.n} random Gaussians per seed (extreme cases included), {rows[0]["image"]} '
           'pinhole camera, float32.', '',
           '| ' + ' | '.join(keys) + ' |', '|' + '---|' * len(keys)]
  for r in rows:
    lines.append('| ' + ' | '.join(f'{r[k]:.3g}' if isinstance(r[k], float) else str(r[k])
                                   for k in keys) + ' |')
  lines += ['', 'Command:', '', f'    {command}', '']
  report.write_markdown(os.path.join(args.out, 'gsplat_check.md'), '\n'.join(lines))


if __name__ == '__main__':
  main()
