"""Renders a `Gaussians` scene from one camera: projection, SH colour, tiles, blending."""
import functools

import jax
import jax.numpy as jnp

from renerf_jax.gaussians import blocks
from renerf_jax.gaussians import params
from renerf_jax.gaussians import projection
from renerf_jax.gaussians import rasterize as rasterize_lib
from renerf_jax.gaussians import tiles


def sanitise(gaussians):
  """Marks slots with any non-finite field inactive and zeroes all inactive fields.

  Double-where: whatever an inactive slot holds (NaN included) reaches neither the image
  nor any gradient; its gradients are exactly zero.
  """
  g = gaussians
  finite = (jnp.all(jnp.isfinite(g.means), -1) & jnp.all(jnp.isfinite(g.log_scales), -1) &
            jnp.all(jnp.isfinite(g.quats), -1) & jnp.isfinite(g.opacity_logits) &
            jnp.all(jnp.isfinite(g.sh), (-1, -2)))
  active = g.active & finite

  def keep(x, default=0.):
    return jnp.where(active.reshape((-1,) + (1,) * (x.ndim - 1)), x, default)

  return params.Gaussians(
      means=keep(g.means), log_scales=keep(g.log_scales),
      quats=keep(g.quats, jnp.array([1., 0., 0., 0.], g.quats.dtype)),
      opacity_logits=keep(g.opacity_logits), sh=keep(g.sh), active=active)


CAPACITY = 2048  # Config.gs_list_capacity's default.


@functools.partial(jax.jit, static_argnames=('height', 'width', 'sh_degree', 'cap', 'tile',
                                             'capacity'))
def render(gaussians, c2w, focal, height, width, sh_degree=3, background=None, cap=64,
           near=0.01, tile=16, means2d_offset=None, capacity=CAPACITY,
           opacity_scale=None):
  """Renders an image of the Gaussians.

  The gradient of a loss with respect to `means2d_offset` (pass zeros) is the
  view-space positional gradient d loss / d means2d of each Gaussian, in pixels, which
  3DGS densifies on (`density.accumulate`); the offset is added to the projected means
  of the valid Gaussians after tile intersection, so zeros change nothing.

  Args:
    gaussians: params.Gaussians with N slots.
    c2w: [3, 4] OpenGL camera-to-world. focal: focal length in pixels.
    height, width: static image size.
    sh_degree: static SH degree used for colour, 0..3.
    background: [3] colour (default black).
    cap: static maximum number of Gaussians blended per tile (the nearest); 0: no cap,
      every Gaussian that touches a tile is blended, up to the capacity.
    capacity: static, with cap 0: the lists of the 8x8 pixel blocks hold K * capacity
      (Gaussian, block) pairs in all (K blocks), at most 2 * capacity in one block
      (blocks.pair_lists); where it binds the farthest are dropped (cap_bound says
      where).
    near: near-plane depth.
    tile: static tile size.
    means2d_offset: optional [N, 2] pixel offset added to the projected means (zeros:
      the screen-space gradient probe); None: no offset.
    opacity_scale: optional [N] factors of the opacities (DropGaussian's, dropout.py:
      0 drops a Gaussian); None: none.

  Returns:
    dict with rgb [H, W, 3], depth [H, W] (weighted sum of view depths, unnormalised:
    depth / acc is the expected depth), acc [H, W] (1 - final transmittance), cap_bound
    (fraction of tiles with more than `cap` Gaussians, or, with cap 0, where the
    capacity dropped some), count [T] (Gaussians per tile),
    valid [N] and radius [N] (the projection's culling mask and pixel radii).
  """
  dtype = gaussians.means.dtype
  background = (jnp.zeros(3, dtype) if background is None
                else jnp.asarray(background, dtype))
  g = sanitise(gaussians)
  proj = projection.project(g.means, g.log_scales, g.quats, g.active, c2w, focal,
                            height, width, near)
  colours = params.eval_sh(sh_degree, g.sh, g.means - c2w[:3, 3])
  opacities = jax.nn.sigmoid(g.opacity_logits)
  if opacity_scale is not None:
    opacities = opacities * opacity_scale
  means2d = proj.means2d
  if means2d_offset is not None:
    means2d = means2d + jnp.where(proj.valid[:, None], means2d_offset, 0.)
  if cap:
    ids, count = tiles.tile_intersect(proj.means2d, proj.radius, proj.depths, proj.valid,
                                      height, width, tile, cap)
    rgb, depth, acc = rasterize_lib.rasterize(ids, means2d, proj.conics, colours,
                                              opacities, proj.depths, height, width,
                                              background, tile)
    cap_bound = jnp.mean(count > cap)
  else:
    block = min(rasterize_lib.BLOCK, tile)
    ids, length, count, bound = blocks.pair_lists(
        proj.means2d, proj.radius, proj.conics, opacities, proj.depths, proj.valid,
        height, width, tile, block, capacity)
    rgb, depth, acc = rasterize_lib.rasterize_blocks(
        ids, length, means2d, proj.conics, colours, opacities, proj.depths, height,
        width, background, tile, block=block)
    cap_bound = jnp.mean(bound.astype(dtype))
  return dict(rgb=rgb, depth=depth, acc=acc, cap_bound=cap_bound,
              count=count, valid=proj.valid, radius=proj.radius)
