"""A picture of a capture's split: which cameras train, validate and test.

Loads the scene of each gin config (or of one config under several bindings) and draws
the camera centres seen from above the capture (its two main axes: the principal axes of
the centres), each with a short stroke along its viewing direction: training views
(numbered in the order chosen), validation views, test views and the unused photos.
Side by side, e.g. the 'coverage' and 'linspace' selections of garden's 30 views:

  python -m experiments.plot_split --config gin_configs/garden30_data.gin \\
      --variant "coverage=" --variant "linspace=Config.train_view_selection = 'linspace'" \\
      --out experiments/results/sfm_start_garden/split_garden.png

Writes the PNG; trains nothing.
"""
import argparse

from experiments import tables
from renerf_jax import figures
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene

def main(argv=None):
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--config', nargs='+', required=True, help='gin config file(s)')
  p.add_argument('--variant', action='append', default=[],
                 help="'LABEL=binding;binding': one panel each (default: one panel)")
  p.add_argument('--gin_bindings', action='append', default=[])
  p.add_argument('--out', required=True, help='the PNG')
  args = p.parse_args(argv)
  variants = [tables.variant_spec(v) for v in args.variant] or [('', [])]
  fig, axs = figures.subplots(1, len(variants), figsize=(5.5 * len(variants), 5.5))
  for ax, (label, bindings) in zip(axs[0], variants):
    config = load_config(args.config, args.gin_bindings + list(bindings))
    scene = load_scene(config)
    figures.draw_split(ax, scene, f'{scene.name}: {label or config.train_view_selection}, '
         f'{len(scene.train_idx)} training views (numbered in the order chosen)')
  fig.tight_layout()
  figures.save_figure(fig, args.out, dpi=110)
  print(args.out)


if __name__ == '__main__':
  main()
