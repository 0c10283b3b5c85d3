"""Chunked rendering of many rays / full images with a fixed-shape jitted function."""
import functools

import jax
import jax.numpy as jnp
import numpy as np

from renerf_jax import distributed
from renerf_jax.nerf.model import render_rays
from renerf_jax.progress import progress_bar


@functools.partial(jax.jit, static_argnums=(0,))
def _render_chunk(config, params, rays):
  out = render_rays(config, params, rays, jax.random.PRNGKey(0), train=False)[-1]
  return {'rgb': out['rgb'], 'distance': out['distance'], 'acc': out['acc']}


def render_flat(config, params, rays, chunk=None, show_progress=False, desc='render',
                chunk_fn=None):
  """Renders rays [N] in chunks of config.render_chunk (last chunk padded).

  With several processes each renders every P-th chunk (the same chunks, padded the
  same way, as one process renders) and the chunks are gathered to every process
  (distributed.map_shares), so the result does not depend on the process count.

  Args:
    config: Config. params: field parameters. rays: Rays with leading shape [N].
    chunk: rays per chunk (default config.render_chunk).
    show_progress: draw a bar. desc: its label.
    chunk_fn: optional (params, rays) -> dict replacing the default renderer.

  Returns:
    dict of host numpy arrays with leading shape [N] ('rgb', 'distance', 'acc', ...).
  """
  chunk = chunk or config.render_chunk
  fn = chunk_fn or functools.partial(_render_chunk, config)
  params = distributed.local(params)
  n = rays.origins.shape[0]
  bar = progress_bar(total=n, desc=desc, disable=not show_progress, unit='ray')

  def render_chunk(k):
    i = k * chunk
    part = jax.tree_util.tree_map(lambda x: x[i:i + chunk], rays)
    m = part.origins.shape[0]
    if m < chunk:
      part = jax.tree_util.tree_map(
          lambda x: jnp.pad(x, [(0, chunk - m)] + [(0, 0)] * (x.ndim - 1), mode='edge'),
          part)
    out = jax.tree_util.tree_map(np.asarray, fn(params, part))
    bar.update(m)
    return out
  outs = distributed.map_shares(render_chunk, -(-n // chunk))
  bar.close()
  outs = [jax.tree_util.tree_map(lambda x, k=k: x[:min(chunk, n - k * chunk)], out)
          for k, out in enumerate(outs)]
  return jax.tree_util.tree_map(lambda *xs: np.concatenate(xs, 0), *outs)


def render_image(config, params, rays, **kwargs):
  """Renders rays shaped [H, W]; returns dict of [H, W, ...] numpy arrays."""
  h, w = rays.origins.shape[:2]
  flat = jax.tree_util.tree_map(lambda x: x.reshape((h * w,) + x.shape[2:]), rays)
  out = render_flat(config, params, flat, **kwargs)
  return {k: v.reshape((h, w) + v.shape[1:]) for k, v in out.items()}
