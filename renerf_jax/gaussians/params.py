"""Gaussian scene parameters, rotations, 3D covariances and spherical harmonics.

A scene is a fixed-capacity `Gaussians` with an `active` mask, so every shape is static.
Colours are degree-3 real spherical harmonics with 16 coefficients per channel, DC first,
in the order and with the constants of the reference 3DGS (`sh_utils.py`).
"""
import flax
import jax
import jax.numpy as jnp
import numpy as np

SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
         -1.0925484305920792, 0.5462742152960396)
SH_C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658,
         0.3731763325901154, -0.4570457994644658, 1.445305721320277,
         -0.5900435899266435)
NUM_SH = 16  # Coefficients per channel at degree 3.
_TINY = 1e-20


@flax.struct.dataclass
class Gaussians:
  """A fixed-capacity set of 3D Gaussians; every field has leading shape [N]."""
  means: jnp.ndarray  # [N, 3] world-space centres.
  log_scales: jnp.ndarray  # [N, 3] log standard deviations along the local axes.
  quats: jnp.ndarray  # [N, 4] rotations (w, x, y, z), need not be normalised.
  opacity_logits: jnp.ndarray  # [N] opacity = sigmoid(logit).
  sh: jnp.ndarray  # [N, 16, 3] SH coefficients, DC first.
  active: jnp.ndarray  # [N] bool; inactive slots are ignored entirely.


def knn_scales(points, k=3, block=1024):
  """3DGS's initial scale: sqrt(mean squared distance to the k nearest other points).

  Args:
    points: [N, 3] (N >= 2). k: neighbours (N - 1 if fewer).
    block: rows of the [block, N] distance matrix computed at a time.

  Returns:
    [N] scales, at least sqrt(1e-7) (3DGS clamps the squared distance at 1e-7).
  """
  points = jnp.asarray(points, jnp.float32)
  n = points.shape[0]
  if n < 2:
    raise ValueError(f'knn_scales needs at least 2 points, got {n}')
  k = min(k, n - 1)
  block = min(block, n)

  @jax.jit
  def rows(start):  # Mean squared distance of rows start..start+block to their k nearest.
    p = jax.lax.dynamic_slice_in_dim(points, start, block)
    d2 = jnp.sum((p[:, None, :] - points[None, :, :])**2, -1)
    self_ = start + jnp.arange(block)[:, None] == jnp.arange(n)[None, :]
    return jnp.mean(-jax.lax.top_k(-jnp.where(self_, jnp.inf, d2), k)[0], axis=-1)

  out = []
  for start in range(0, n, block):
    first = min(start, n - block)  # The last block overlaps the previous one.
    out.append(rows(first)[start - first:])
  return jnp.sqrt(jnp.maximum(jnp.concatenate(out), 1e-7))


def random_init(key, n, lo, hi, capacity=None, init_opacity=0.1, scale_factor=1.,
                knn=False):
  """Gaussians uniform in the box [lo, hi], isotropic, grey, of low opacity.

  Args:
    key: jax PRNG key.
    n: number of active Gaussians.
    lo, hi: [3] box corners.
    capacity: total slots (>= n, default n); slots n.. are inactive.
    init_opacity, scale_factor, knn: as init_at (the spacing: mean box side / n^(1/3)).

  Returns:
    Gaussians with N = capacity (init_at).
  """
  capacity = n if capacity is None else capacity
  if capacity < n:
    raise ValueError(f'capacity {capacity} < n {n}')
  lo = jnp.asarray(lo, jnp.float32)
  hi = jnp.asarray(hi, jnp.float32)
  means = lo + (hi - lo) * jax.random.uniform(key, (capacity, 3))
  return init_at(means, n, box_spacing(lo, hi, n), init_opacity, scale_factor, knn)


def box_spacing(lo, hi, n):
  """The spacing of n points spread evenly in the box [lo, hi]: mean side / n^(1/3).

  Args:
    lo, hi: [3] box corners. n: number of points (>= 1).

  Returns:
    float32 scalar.
  """
  lo = jnp.asarray(lo, jnp.float32)
  return jnp.mean(jnp.asarray(hi, jnp.float32) - lo) / float(n)**(1. / 3.)


def init_at(means, n, spacing, init_opacity=0.1, scale_factor=1., knn=False):
  """Isotropic grey Gaussians of low opacity at given centres, the first n active.

  Each scale is `scale_factor` * `spacing`, or with `knn` 3DGS's: the root mean squared
  distance to the 3 nearest of the n points; rotations are the identity, the opacity is
  `init_opacity` (logit(0.1) as in 3DGS), and all SH coefficients are zero, i.e. colour
  0.5 grey from every side.

  Args:
    means: [capacity, 3] centres (those of slots n.. are kept but inactive).
    n: number of active Gaussians (<= capacity).
    spacing: the scale without knn (e.g. the spacing of n points in their volume).
    init_opacity: initial opacity in (0, 1).
    scale_factor: multiplies the initial scale.
    knn: 3DGS's nearest-neighbour scales instead of the spacing (n >= 2; a single
      Gaussian keeps the spacing).

  Returns:
    Gaussians with N = capacity.
  """
  means = jnp.asarray(means, jnp.float32)
  capacity = means.shape[0]
  if capacity < n:
    raise ValueError(f'capacity {capacity} < n {n}')
  if knn and n >= 2:
    scale = jnp.zeros((capacity,)).at[:n].set(knn_scales(means[:n]))
    log_scales = jnp.log(jnp.maximum(scale_factor * scale, 1e-7))[:, None] * jnp.ones(3)
  else:
    log_scales = jnp.full((capacity, 3), jnp.log(scale_factor * spacing))
  quats = jnp.tile(jnp.array([1., 0., 0., 0.]), (capacity, 1))
  logit = float(np.log(init_opacity / (1. - init_opacity)))
  return Gaussians(
      means=means, log_scales=log_scales, quats=quats,
      opacity_logits=jnp.full((capacity,), logit), sh=jnp.zeros((capacity, NUM_SH, 3)),
      active=jnp.arange(capacity) < n)


def quat_to_rotmat(quats):
  """Rotation matrices of (w, x, y, z) quaternions, normalised first.

  A (near-)zero quaternion maps to the identity, with zero gradient (double where).

  Args:
    quats: [..., 4].

  Returns:
    [..., 3, 3].
  """
  norm2 = jnp.sum(quats**2, axis=-1, keepdims=True)
  ok = norm2 > _TINY
  identity = jnp.array([1., 0., 0., 0.], quats.dtype)
  q = jnp.where(ok, quats, identity)
  q = q / jnp.sqrt(jnp.where(ok, norm2, 1.))
  w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
  rows = [
      [1. - 2. * (y * y + z * z), 2. * (x * y - w * z), 2. * (x * z + w * y)],
      [2. * (x * y + w * z), 1. - 2. * (x * x + z * z), 2. * (y * z - w * x)],
      [2. * (x * z - w * y), 2. * (y * z + w * x), 1. - 2. * (x * x + y * y)],
  ]
  return jnp.stack([jnp.stack(r, axis=-1) for r in rows], axis=-2)


def covariance_3d(log_scales, quats):
  """World-space covariances R S S^T R^T with S = diag(exp(log_scales)).

  Args:
    log_scales: [..., 3]. quats: [..., 4] (w, x, y, z).

  Returns:
    [..., 3, 3] symmetric positive semi-definite matrices.
  """
  m = quat_to_rotmat(quats) * jnp.exp(log_scales)[..., None, :]
  return jnp.matmul(m, jnp.swapaxes(m, -1, -2), precision=jax.lax.Precision.HIGHEST)


def sh_basis(degree, dirs):
  """Real SH basis functions of the reference 3DGS, up to `degree` (static, 0..3).

  Args:
    degree: static int in [0, 3].
    dirs: [..., 3] directions, normalised inside; a zero vector gives only the DC term
      (all higher basis functions 0), with zero gradient.

  Returns:
    [..., (degree + 1)^2] basis values, ordered as the SH coefficients.
  """
  if not 0 <= degree <= 3:
    raise ValueError(f'SH degree {degree} not in [0, 3]')
  norm2 = jnp.sum(dirs**2, axis=-1, keepdims=True)
  ok = norm2 > _TINY
  d = jnp.where(ok, dirs, 0.) / jnp.sqrt(jnp.where(ok, norm2, 1.))
  x, y, z = d[..., 0], d[..., 1], d[..., 2]
  out = [jnp.full_like(x, SH_C0)]
  if degree >= 1:
    out += [-SH_C1 * y, SH_C1 * z, -SH_C1 * x]
  if degree >= 2:
    xx, yy, zz = x * x, y * y, z * z
    out += [SH_C2[0] * x * y, SH_C2[1] * y * z, SH_C2[2] * (2. * zz - xx - yy),
            SH_C2[3] * x * z, SH_C2[4] * (xx - yy)]
  if degree >= 3:
    out += [SH_C3[0] * y * (3. * xx - yy), SH_C3[1] * x * y * z,
            SH_C3[2] * y * (4. * zz - xx - yy), SH_C3[3] * z * (2. * zz - 3. * xx - 3. * yy),
            SH_C3[4] * x * (4. * zz - xx - yy), SH_C3[5] * z * (xx - yy),
            SH_C3[6] * x * (xx - 3. * yy)]
  return jnp.stack(out, axis=-1)


def eval_sh(degree, sh, dirs):
  """RGB colour of SH coefficients seen along `dirs`: max(SH(dirs) + 0.5, 0) as in 3DGS.

  Only the first (degree + 1)^2 coefficients are used.

  Args:
    degree: static int in [0, 3].
    sh: [..., C >= (degree + 1)^2, 3] coefficients, DC first.
    dirs: [..., 3] viewing directions (from the camera to the Gaussian), any length.

  Returns:
    [..., 3] colours >= 0.
  """
  basis = sh_basis(degree, dirs)
  nb = basis.shape[-1]
  rgb = jnp.einsum('...k,...kc->...c', basis, sh[..., :nb, :],
                   precision=jax.lax.Precision.HIGHEST)  # float32, also on GPUs.
  return jnp.maximum(rgb + 0.5, 0.)
