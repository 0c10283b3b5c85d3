"""The NeRF's test-view evaluation: cheap strided PSNR during training, full metrics at
the end (evaluation.evaluate_views scores the renders)."""
import jax
import numpy as np

from renerf_jax import metrics
from renerf_jax.datasets import camera_rays
from renerf_jax.evaluation import Evaluation, evaluate_views
from renerf_jax.nerf.rendering import render_flat, render_image


def cheap_eval_fn(config, scene):
  """params -> PSNR on config.eval_n_views test views at pixel stride config.eval_stride.

  The strided pixels are an unbiased sample of the test pixels, so the PSNR tracks the
  full-image PSNR at a fraction of the rendering cost.
  """
  idx = scene.test_idx[:config.eval_n_views]
  s = config.eval_stride
  rays = camera_rays(scene, idx)
  rays = jax.tree_util.tree_map(lambda x: x[:, ::s, ::s].reshape((-1,) + x.shape[3:]), rays)
  gt = scene.images[idx][:, ::s, ::s].reshape(-1, 3)

  def fn(params):
    rgb = render_flat(config, params, rays)['rgb']
    return float(metrics.mse_to_psnr(np.mean((np.clip(rgb, 0., 1.) - gt)**2)))
  return fn


def evaluate_test_views(config, scene, params, show_progress=True) -> Evaluation:
  """Renders every test view of a NeRF and scores it (saved by round_driver).

  Args:
    config: Config. scene: Scene. params: field parameters.
    show_progress: progress bar over rays.

  Returns:
    Evaluation.
  """
  rays = camera_rays(scene, scene.test_idx)

  def render_view(j, i):
    return render_image(config, params, jax.tree_util.tree_map(lambda x: x[j], rays),
                        show_progress=show_progress, desc=f'test view {i}')
  return evaluate_views(config, scene, render_view)
