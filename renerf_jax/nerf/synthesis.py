"""The NeRF's pseudo-views: B rendered at the pseudo-view poses, one view at a time, and
with Config.use_masks the uncertainty masks (Laplace or a Hessian-free signal) cut from
one render pass."""
import time

import jax
import numpy as np

from renerf_jax import pseudo_views
from renerf_jax.datasets import camera_rays, ray_pool
from renerf_jax.nerf import contraction
from renerf_jax.nerf.rendering import render_flat
from renerf_jax.progress import progress_bar
from renerf_jax.pseudo_views import PseudoViews, pseudo_view_poses


def render_view(config, params, rays):
  """One view's colours and the seconds the render took: render_pseudo_views' default
  render_fn.

  Args:
    config: Config. params: model B. rays: Rays of one view, flat [H * W, ...].

  Returns:
    (rgb [H * W, 3] float32 clipped to [0, 1], wall seconds).
  """
  t0 = time.perf_counter()
  rgb = np.clip(np.asarray(render_flat(config, params, rays)['rgb'], np.float32), 0., 1.)
  return rgb, time.perf_counter() - t0


def render_pseudo_views(config, scene, params, poses, show_progress=True, render_fn=None):
  """Renders model `params` at `poses`; all pixels valid (masks of ones).

  Each view's rays are made and rendered on their own (they start a chunk), so a view's
  pixels do not depend on which other views a round renders.

  Args:
    config: Config. scene: Scene (camera). params: model B. poses: [M, 3, 4].
    show_progress: draw a progress bar over views.
    render_fn: (config, params, rays of one view) -> (rgb [H * W, 3] in [0, 1], the
      seconds it costs); None: render_view. (experiments/sharing.py passes one that
      renders each distinct view once per process and reports the seconds of that
      render.)

  Returns:
    (PseudoViews, info: {'render_seconds': the wall time of this call, each view's
    render counted with the seconds render_fn reports for it}).
  """
  t0 = time.perf_counter()
  m, h, w = len(poses), scene.height, scene.width
  render_fn = render_fn or render_view
  images = np.zeros((m, h, w, 3), np.float32)
  reported = measured = 0.
  bar = progress_bar(total=m, unit='view', disable=not show_progress,
                     desc=f'pseudo-views ({m})')
  for i in range(m):
    # One pose at a time: batched ray generation differs in the last bit between batches.
    rays = camera_rays(scene, None, poses[i:i + 1])
    view = jax.tree_util.tree_map(lambda v: np.asarray(v).reshape((h * w,) + v.shape[3:]),
                                  rays)
    t_view = time.perf_counter()
    rgb, s = render_fn(config, params, view)
    measured += time.perf_counter() - t_view
    reported += float(s)
    images[i] = np.asarray(rgb, np.float32).reshape(h, w, 3)
    bar.update(1)
  bar.close()
  pv = PseudoViews(images=images, poses=np.asarray(poses),
                   masks=np.ones((m, h, w), np.float32),
                   uncertainty=np.zeros((m, h, w), np.float32))
  return pv, {'render_seconds': time.perf_counter() - t0 - measured + reported}


def synthesize(config, scene, params, show_progress=False, sigma_fn=None, render_fn=None):
  """Pseudo-views of model `params`, with uncertainty masks if config.use_masks.

  With masks, the Hessian pass runs first and the colours and the uncertainty of the
  pseudo-views come out of one render pass.

  Args:
    config, scene: Config and Scene. params: model B.
    show_progress: draw progress bars.
    sigma_fn: the Hessian pass (uncertainty.masks.compute_masks' sigma_fn; None:
      uncertainty.laplace.vertex_sigma_pass).
    render_fn: renders one unmasked view (pseudo_views.render_pseudo_views' render_fn;
      None: pseudo_views.render_view).

  Returns:
    (PseudoViews, timing: {'seconds': total; 'render_seconds'; with masks
    'hessian_seconds', 'mu', 'kept_fraction'}, meta: a description of each view). The
    Hessian pass and each view's render count with the seconds sigma_fn / render_fn
    report for them: a function that reuses earlier work reports what that work cost, so
    sharing work never makes a round look cheaper.
  """
  if config.pseudo_source == 'photo':
    return pseudo_views.photo_pseudo_views(config, scene)
  t0 = time.perf_counter()
  poses, meta = pseudo_view_poses(config, scene)
  pose_seconds = time.perf_counter() - t0
  if config.use_masks:
    pv, timing = masked_pseudo_views(config, scene, params, poses, show_progress, sigma_fn)
  else:
    pv, timing = render_pseudo_views(config, scene, params, poses, show_progress, render_fn)
  timing['seconds'] = (pose_seconds + timing['render_seconds'] +
                       timing.get('hessian_seconds', 0.))
  return pv, timing, meta


def masked_pseudo_views(config, scene, params, poses, show_progress=False, sigma_fn=None):
  """Pseudo-views at `poses` with Laplace-uncertainty masks (pixels with U > mu masked).

  Returns:
    (PseudoViews with masks and uncertainty, timing: {'render_seconds': the wall time
    of all but the Hessian pass, 'hessian_seconds': the pass's as sigma_fn reports
    them, 'mu', 'kept_fraction'}).
  """
  from renerf_jax.uncertainty import masks as uncertainty_masks  # pylint: disable=g-import-not-at-top
  t0 = time.perf_counter()
  # The deformation grid spans the space the fields see: the contracted cube with
  # Config.contraction (as Bayes' Rays does on unbounded scenes), else the scene box.
  lo, hi = contraction.CONTRACTED_BOX if config.contraction else scene.bbox
  rays = camera_rays(scene, None, poses)
  train_rays = ray_pool(scene, scene.train_idx)['rays']
  t_masks = time.perf_counter()
  res = uncertainty_masks.compute_masks(config, params, train_rays, rays, np.asarray(lo),
                                        np.asarray(hi), show_progress=show_progress,
                                        sigma_fn=sigma_fn)
  masks_wall = time.perf_counter() - t_masks
  pv = PseudoViews(images=np.clip(res.rgb, 0., 1.), poses=np.asarray(poses),
                   masks=np.asarray(res.mask, np.float32),
                   uncertainty=np.asarray(res.uncertainty, np.float32))
  render_seconds = time.perf_counter() - t0 - masks_wall + res.render_seconds
  return pv, {'render_seconds': render_seconds, 'hessian_seconds': res.hessian_seconds,
              'mu': float(res.mu), 'kept_fraction': float(np.mean(pv.masks))}
