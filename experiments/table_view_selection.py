"""View selection: augmentation factors, and pseudo-views at the test poses vs random ones.

Round 1 variants on top of one shared baseline per seed: the interpolation-factor presets
2x {.5}; 3x {.33,.66}, {.2,.8}, {.1,.9}; 4x; 5x; 7x (the default); 11x; then pseudo-views
rendered at the test poses only (the paper's "optimising for specific views") against as
many random unobserved poses. Fern on the 2-core CPU with the small table config
(llff3_small_renerf.gin, see table_why.py): a baseline of ~85 s and ten rounds of
~100-180 s per seed (training ~90 s, evaluation ~11 s, pseudo-views ~3.4 s each: 2 for
2x, 22 for 11x), so about 70 min for three seeds: over the hour the other tables take.
The runs resume, so the table can be split over several invocations with --variant (a
later invocation with all variants only collects them):

  python experiments/table_view_selection.py --name fern_views_small \
    --config gin_configs/llff3_small_renerf.gin --data_dir ../shared/data/nerf_llff_data \
    --scene fern --seeds 0 1 2

The paper's numbers for this table are not in the script: the project has only its
Table 1 numbers (renerf_rounds.py).
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import tables  # pylint: disable=g-import-not-at-top
from renerf_jax.datasets import load_scene  # pylint: disable=g-import-not-at-top

FACTORS = ('7x', '2x', '3x', '3x_b', '3x_c', '4x', '5x', '11x')


def variants(n_test):
  return ([f"{f}=Config.interp_factors='{f}'" for f in FACTORS]
          + [f"{n_test} test poses=Config.pseudo_targets='test'",
             (f"{n_test} random poses=Config.pseudo_targets='random';"
              f'Config.pseudo_n_random={n_test}')])


def main():
  args = tables.parser(__doc__, default_rounds=1).parse_args()
  n_test = len(load_scene(tables.base_config(args)).test_idx)
  tables.run_table(args, args.variant or variants(n_test),
                   paper_note="The paper's numbers for this table are not included.")


if __name__ == '__main__':
  main()
