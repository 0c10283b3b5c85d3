"""Test-view evaluation: cheap strided PSNR during training, full metrics at the end.

Nothing here writes a file: round_driver.save_evaluation does, at the edge (and eval.py).
"""
import dataclasses

import jax
import numpy as np

from renerf_jax import metrics, report
from renerf_jax.datasets import camera_rays
from renerf_jax.rendering import render_flat, render_image


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


@dataclasses.dataclass(frozen=True)
class Evaluation:
  """One model's test views: metrics and the renders they were computed from.

  Attributes:
    per_image: per-view metric dicts ('name': test_XXX, 'psnr', 'ssim', 'lpips_*', ...).
    mean: their means (report.per_image_table's last row, without 'name').
    images: [N, H, W, 3] renders clipped to [0, 1], in scene.test_idx order.
    distances: [N, H, W] rendered depth (distance along the ray).
    columns: the metric columns of the markdown table.
  """
  per_image: list
  mean: dict
  images: np.ndarray
  distances: np.ndarray
  columns: tuple

  def summary(self) -> dict:
    """{'per_image': [...], 'mean': {...}}: what metrics.json holds."""
    return {'per_image': self.per_image, 'mean': self.mean}


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


def view_name(i):
  """The name of scene view i in metrics.json ('test_003'), also its renders' file name."""
  return f'test_{int(i):03d}'


def evaluate_views(config, scene, render_view) -> Evaluation:
  """Per-image and mean metrics of any backbone's test renders.

  Args:
    config: Config (config.lpips_nets). scene: Scene.
    render_view: (j, i) -> {'rgb': [H, W, 3], 'distance': [H, W]} of test view i, the
      j-th of scene.test_idx (distance: the depth of the depth maps).

  Returns:
    Evaluation.
  """
  per_image, images, distances = [], [], []
  for j, i in enumerate(scene.test_idx):
    out = render_view(j, i)
    pred = np.clip(out['rgb'], 0., 1.)
    m = metrics.image_metrics(pred, scene.images[i], config.lpips_nets)
    m['name'] = view_name(i)
    per_image.append(m)
    images.append(np.asarray(pred, np.float32))
    distances.append(np.asarray(out['distance'], np.float32))
  rows = report.per_image_table(per_image)
  mean = {k: v for k, v in rows[-1].items() if k != 'name'}
  columns = (('name', 'psnr', 'ssim') + tuple(f'lpips_{n}' for n in config.lpips_nets) +
             (('avg_err',) if 'alex' in config.lpips_nets else ()))
  return Evaluation(per_image=per_image, mean=mean, images=np.stack(images),
                    distances=np.stack(distances), columns=columns)
