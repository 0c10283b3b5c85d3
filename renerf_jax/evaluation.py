"""Test-view evaluation: cheap strided PSNR during training, full metrics at the end."""
import os

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


def evaluate_test_views(config, scene, params, out_dir, show_progress=True):
  """Renders every test view of a NeRF, writes PNGs and per-image + mean metrics.

  Args:
    config: Config. scene: Scene. params: field parameters.
    out_dir: folder for test_XXX.png, depth_XXX.png, metrics.json, metrics.md (None:
      nothing is written).
    show_progress: progress bar over rays.

  Returns:
    dict {'per_image': [...], 'mean': {...}}.
  """
  rays = camera_rays(scene, scene.test_idx)

  def render_view(j, i):
    return render_image(config, params, jax.tree_util.tree_map(lambda x: x[j], rays),
                        show_progress=show_progress, desc=f'test view {i}')
  return evaluate_views(config, scene, render_view, out_dir)


def evaluate_views(config, scene, render_view, out_dir):
  """Per-image and mean metrics of any backbone's test renders (and their PNGs).

  Args:
    config: Config (config.lpips_nets). scene: Scene.
    render_view: (j, i) -> {'rgb': [H, W, 3], 'distance': [H, W]} of test view i, the
      j-th of scene.test_idx (distance: the depth shown in depth_XXX.png).
    out_dir: folder for test_XXX.png, depth_XXX.png, metrics.json, metrics.md (None:
      nothing is written).

  Returns:
    dict {'per_image': [...], 'mean': {...}}.
  """
  if out_dir is not None:
    os.makedirs(out_dir, exist_ok=True)
  per_image = []
  for j, i in enumerate(scene.test_idx):
    out = render_view(j, i)
    pred = np.clip(out['rgb'], 0., 1.)
    m = metrics.image_metrics(pred, scene.images[i], config.lpips_nets)
    m['name'] = f'test_{int(i):03d}'
    per_image.append(m)
    if out_dir is None:
      continue
    report.save_image_png(os.path.join(out_dir, f'test_{int(i):03d}.png'), pred)
    report.save_image_png(os.path.join(out_dir, f'depth_{int(i):03d}.png'),
                          report.colorize(out['distance']))
  rows = report.per_image_table(per_image)
  mean = {k: v for k, v in rows[-1].items() if k != 'name'}
  result = {'per_image': per_image, 'mean': mean}
  if out_dir is None:
    return result
  report.write_json(os.path.join(out_dir, 'metrics.json'), result)
  report.write_markdown(os.path.join(out_dir, 'metrics.md'), report.markdown_table(
      rows, ['name', 'psnr', 'ssim'] + [f'lpips_{n}' for n in config.lpips_nets] +
      (['avg_err'] if 'alex' in config.lpips_nets else [])) + '\n')
  return result
