"""The files a run writes of its results: test evaluations and pseudo-views.

The edge of the math: evaluation, pseudo-view synthesis and uncertainty return arrays
and dicts; resume.py and eval.py write them with the functions here. Every
file is written atomically (report.atomic_open: temp file + rename).
"""
import os
from typing import Optional

import numpy as np

from renerf_jax import pseudo_views, report
from renerf_jax.evaluation import Evaluation
from renerf_jax.pseudo_views import PseudoViews


def save_evaluation(out_dir, ev: Evaluation, save_png=True):
  """Writes metrics.json, metrics.md and, per test view, test_XXX.png and depth_XXX.png.

  Args:
    out_dir: the folder (created). ev: evaluation.Evaluation.
    save_png: also write the renders.
  """
  os.makedirs(out_dir, exist_ok=True)
  if save_png:
    for m, image, distance in zip(ev.per_image, ev.images, ev.distances):
      report.save_image_png(os.path.join(out_dir, f"{m['name']}.png"), image)
      depth_name = m['name'].replace('test_', 'depth_', 1)
      report.save_image_png(os.path.join(out_dir, f'{depth_name}.png'),
                            report.colorize(distance))
  report.write_json(os.path.join(out_dir, 'metrics.json'), ev.summary())
  report.write_markdown(os.path.join(out_dir, 'metrics.md'), report.markdown_table(
      report.per_image_table(ev.per_image), list(ev.columns)) + '\n')


def save_pseudo_views(directory, pv: PseudoViews, meta, save_png=True):
  """Writes views.npz (atomically) and, per view, rgb / mask / uncertainty PNGs."""
  os.makedirs(directory, exist_ok=True)
  arrays = {k: np.asarray(getattr(pv, k)) for k in ('images', 'poses', 'masks',
                                                     'uncertainty')}
  with report.atomic_open(os.path.join(directory, 'views.npz'), 'wb') as f:
    np.savez_compressed(f, **arrays)
  report.write_json(os.path.join(directory, 'views.json'), meta)
  if save_png:
    for i in range(arrays['images'].shape[0]):
      report.save_image_png(os.path.join(directory, f'view_{i:03d}.png'),
                            arrays['images'][i])
      report.save_image_png(os.path.join(directory, f'mask_{i:03d}.png'),
                            arrays['masks'][i])
      if np.any(arrays['uncertainty'][i]):
        heat = pseudo_views.uncertainty_heatmap(arrays['uncertainty'][i],
                                                arrays['uncertainty'])
        report.save_image_png(os.path.join(directory, f'uncertainty_{i:03d}.png'), heat)
        report.save_image_png(os.path.join(directory, f'panel_{i:03d}.png'),
                              pseudo_views.side_by_side(arrays['images'][i], heat,
                                                        arrays['masks'][i]))


def load_pseudo_views(directory) -> Optional[PseudoViews]:
  """The PseudoViews in directory/views.npz (None: not written yet)."""
  path = os.path.join(directory, 'views.npz')
  if not os.path.isfile(path):
    return None
  with np.load(path) as z:
    return PseudoViews(**{k: z[k] for k in ('images', 'poses', 'masks', 'uncertainty')})
