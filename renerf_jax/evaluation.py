"""Test-view evaluation of any backbone: its renders scored (PSNR, SSIM, LPIPS) per view.

Nothing here writes a file: round_driver.save_evaluation does, at the edge (and eval.py).
"""
import dataclasses

import numpy as np

from renerf_jax import metrics, report


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
