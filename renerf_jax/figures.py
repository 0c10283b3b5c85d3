# Copyright 2024 renerf-jax authors.
"""Figures and images of results: Agg plots of metrics against time, PNG images, colour
maps; every file written atomically through report.atomic_open.

Depends on numpy, imageio and matplotlib only (matplotlib imported lazily, through its Agg
backend); report.py holds the JSON / Markdown writers and the table arithmetic.
"""
from typing import Mapping, Sequence, Tuple

import numpy as np

from renerf_jax.report import atomic_open

Curve = Sequence[Tuple[float, ...]]  # (seconds, value) or (seconds, value, std) points


def subplots(nrows, ncols, figsize):
  """A matplotlib Figure on an Agg canvas (no pyplot state) and its axes [nrows, ncols]."""
  from matplotlib.backends.backend_agg import FigureCanvasAgg  # pylint: disable=g-import-not-at-top
  from matplotlib.figure import Figure  # pylint: disable=g-import-not-at-top
  fig = Figure(figsize=figsize)
  FigureCanvasAgg(fig)
  return fig, fig.subplots(nrows, ncols, squeeze=False)


def save_figure(fig, path, dpi=120):
  """Renders a matplotlib Figure with Agg and writes it atomically as PNG."""
  from matplotlib.backends.backend_agg import FigureCanvasAgg  # pylint: disable=g-import-not-at-top
  FigureCanvasAgg(fig)
  with atomic_open(path, 'wb') as f:
    fig.savefig(f, format='png', dpi=dpi, bbox_inches='tight')


def _draw_curves(ax, curves: Mapping[str, Curve], metric, logx=False):
  """Draws one line with markers per label on `ax`; (t, value, std) points get error bars."""
  for label, points in curves.items():
    points = list(points)
    width = len(points[0]) if points else 2
    pts = np.asarray(points, dtype=np.float64).reshape(-1, width)
    order = np.argsort(pts[:, 0], kind='stable')
    if width == 3:
      ax.errorbar(pts[order, 0], pts[order, 1], yerr=pts[order, 2], marker='o',
                  markersize=3, capsize=3, label=str(label))
    else:
      ax.plot(pts[order, 0], pts[order, 1], marker='o', markersize=3, label=str(label))
  ax.set_xlabel('wall-clock time [s]')
  ax.set_ylabel(metric.upper() if metric.lower() in ('psnr', 'ssim', 'lpips')
                else metric)
  if logx:
    ax.set_xscale('log')
  ax.grid(True, alpha=0.4)
  if curves:
    ax.legend(fontsize='small')


def plot_error_vs_time(curves: Mapping[str, Curve],
                       path,
                       metric='psnr',
                       title=None,
                       logx=False):
  """Plots a metric against wall-clock time, one line per method, as a PNG.

  Args:
    curves: dict label -> list of (seconds, value) pairs (any order).
    path: destination PNG file (written atomically).
    metric: str, name of the plotted metric (y-axis label).
    title: optional title; default '<metric> vs. wall-clock time'.
    logx: bool, logarithmic time axis.
  """
  from matplotlib.figure import Figure  # pylint: disable=g-import-not-at-top
  fig = Figure(figsize=(6, 4))
  ax = fig.add_subplot(1, 1, 1)
  _draw_curves(ax, curves, metric, logx=logx)
  ax.set_title(title or f'{metric.upper()} vs. wall-clock time')
  save_figure(fig, path)


def plot_metrics_vs_time(curves_by_metric: Mapping[str, Mapping[str, Curve]],
                         path,
                         title=None,
                         logx=False):
  """One subplot per metric (e.g. psnr, ssim, lpips) against wall-clock time.

  Args:
    curves_by_metric: dict metric -> (dict label -> list of (seconds, value)).
    path: destination PNG file (written atomically).
    title: optional figure title.
    logx: bool, logarithmic time axes.
  """
  from matplotlib.figure import Figure  # pylint: disable=g-import-not-at-top
  n = max(1, len(curves_by_metric))
  fig = Figure(figsize=(4.5 * n, 3.8))
  for i, (metric, curves) in enumerate(curves_by_metric.items()):
    ax = fig.add_subplot(1, n, i + 1)
    _draw_curves(ax, curves, metric, logx=logx)
    ax.set_title(metric.upper())
  if title:
    fig.suptitle(title)
  save_figure(fig, path)


def save_panels(path, images, titles, panel_inches=2.4):
  """Images side by side, each under its title, as one PNG (atomically).

  Args:
    path: destination file. images: [H, W, 3] floats in [0, 1] or uint8, same size.
    titles: one string per image. panel_inches: the width of one panel.
  """
  h, w = np.asarray(images[0]).shape[:2]
  fig, axes = subplots(1, len(images), (panel_inches * len(images),
                                        panel_inches * h / w + 0.4))
  for ax, img, title in zip(axes[0], images, titles):
    ax.imshow(to_uint8(img), interpolation='nearest')
    ax.set_title(title, fontsize=9)
    ax.axis('off')
  save_figure(fig, path)


def to_uint8(img):
  """Converts a float image in [0, 1] to uint8 (uint8 input passes through).

  Args:
    img: array [H, W], [H, W, 1], [H, W, 3] or [H, W, 4]; floats in [0, 1]
      (clipped; NaN -> 0) or uint8.

  Returns:
    uint8 array [H, W] or [H, W, 3|4], values in [0, 255].
  """
  img = np.asarray(img)
  if img.ndim == 3 and img.shape[-1] == 1:
    img = img[..., 0]
  if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[-1] not in (3, 4)):
    raise ValueError(f'Expected [H, W] or [H, W, 3|4] image, got {img.shape}')
  if img.dtype == np.uint8:
    return img
  img = np.nan_to_num(img.astype(np.float64), nan=0., posinf=1., neginf=0.)
  return np.round(np.clip(img, 0., 1.) * 255.).astype(np.uint8)


def save_image_png(path, img):
  """Atomically saves an image as an 8-bit PNG.

  Args:
    path: destination file.
    img: float array in [0, 1] (or uint8), [H, W], [H, W, 1], [H, W, 3|4].
  """
  import imageio.v3 as iio  # pylint: disable=g-import-not-at-top
  data = iio.imwrite('<bytes>', to_uint8(img), extension='.png')
  with atomic_open(path, 'wb') as f:
    f.write(data)


def colorize(x, lo=None, hi=None, cmap='turbo', invalid_color=(0., 0., 0.)):
  """Maps a 2D scalar field (depth, uncertainty, ...) to an RGB heat map.

  Args:
    x: array [H, W] of any real dtype; NaN/inf entries are treated as invalid.
    lo: value mapped to the low end of the colormap; default: finite min.
    hi: value mapped to the high end of the colormap; default: finite max.
    cmap: matplotlib colormap name.
    invalid_color: RGB in [0, 1] used for non-finite entries.

  Returns:
    float32 array [H, W, 3] in [0, 1], always finite. Constant inputs (or
    hi <= lo) map to the low end of the colormap.
  """
  import matplotlib  # pylint: disable=g-import-not-at-top
  x = np.asarray(x, dtype=np.float64)
  if x.ndim != 2:
    raise ValueError(f'colorize expects a 2D array, got shape {x.shape}')
  valid = np.isfinite(x)
  finite = x[valid]
  if lo is None:
    lo = float(finite.min()) if finite.size else 0.
  if hi is None:
    hi = float(finite.max()) if finite.size else 1.
  span = hi - lo
  safe = np.where(valid, x, lo)
  if not np.isfinite(span) or span <= 0:
    t = np.zeros_like(safe)
  else:
    t = np.clip((safe - lo) / span, 0., 1.)
  rgb = matplotlib.colormaps[cmap](t)[..., :3]
  rgb[~valid] = np.asarray(invalid_color, dtype=np.float64)
  return np.clip(rgb, 0., 1.).astype(np.float32)


SPLIT_STYLE = {'unused': ('lightgrey', 12), 'test': ('tab:red', 30), 'validation': ('tab:green', 30),
         'train': ('tab:blue', 36)}


def plane_axes(centres):
  """The two principal axes of camera centres [N, 3] (rows [2, 3]): the capture's floor."""
  centred = centres - centres.mean(0)
  return np.linalg.svd(centred, full_matrices=False)[2][:2]


def draw_split(ax, scene, title):
  """A capture's cameras seen from above (the centres' two principal axes), each with a
  stroke along its viewing direction: training views (numbered in the order chosen),
  validation, test and unused views (experiments/plot_split.py, the capture notebook)."""
  centres = np.asarray(scene.poses[:, :3, 3], np.float64)
  axes = plane_axes(centres)
  xy = (centres - centres.mean(0)) @ axes.T
  dirs = -np.asarray(scene.poses[:, :3, 2], np.float64) @ axes.T
  length = 0.06 * np.ptp(xy, axis=0).max()
  groups = {'unused': np.setdiff1d(np.arange(len(xy)), np.concatenate(
      [scene.train_idx, scene.val_idx, scene.test_idx])), 'test': scene.test_idx,
            'validation': scene.val_idx, 'train': scene.train_idx}
  for name, idx in groups.items():
    idx = np.asarray(idx, int)
    colour, size = SPLIT_STYLE[name]
    ax.scatter(xy[idx, 0], xy[idx, 1], s=size, c=colour, label=f'{name} ({len(idx)})',
               zorder=3 if name == 'train' else 2)
    for i in idx:
      ax.plot([xy[i, 0], xy[i, 0] + length * dirs[i, 0]],
              [xy[i, 1], xy[i, 1] + length * dirs[i, 1]], c=colour, lw=0.8)
  for k, i in enumerate(scene.train_idx):
    ax.annotate(str(k + 1), xy[i], fontsize=6, xytext=(2, 2), textcoords='offset points')
  ax.set_aspect('equal')
  ax.set_title(title, fontsize=9)
  ax.legend(fontsize=7, loc='best')
