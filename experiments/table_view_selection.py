"""View selection: augmentation factors, and pseudo-views at the test poses vs random ones.

Round 1 variants on top of one shared baseline per seed: the interpolation-factor presets
2x {.5}; 3x {.33,.66}, {.2,.8}, {.1,.9}; 4x; 5x; 7x (the default); 11x; then pseudo-views
rendered at the test poses only (the paper's "optimising for specific views") against as
many random unobserved poses. The presets overlap (7x holds 5x, 3x_b and 3x_c; 11x holds
7x): within one process each view is rendered once (synthesis.render_pseudo_views),
and a variant still counts the seconds its views took.

Fern on the 2-core CPU with the hour-budget table config (table_tiny.gin: 126x94,
512 rays a step), baselines from its rounds table (renerf_rounds.py): 49.6 min for
three seeds, experiments/results/view_selection_fern/fern_views_tiny.md. The first
invocation of the command below died after 42.7 min and 26 of the 30 rounds ("LLVM compilation error: Cannot
allocate memory": every run's compiled steps were kept and their memory mappings reached
Linux's 65530, fixed since by jit_cache.release_compiled between runs); the same command
resumed with the fix and finished the last four rounds in 6.9 min:

  python -m experiments.table_view_selection --name fern_views_tiny \
    --config experiments/configs/table_tiny.gin --data_dir ../shared/data/nerf_llff_data \
    --scene fern --seeds 0 1 2 \
    --baseline_from 'experiments/results/fern_rounds_tiny/Re-Nerfing (masks)/seed{seed}'

With the small table config (table_small.gin, see table_why.py: 252x189, 1024
rays a step), baselines from the rounds table (renerf_rounds.py): ten rounds of
2.3-2.6 min per seed (training ~2 min, evaluation ~18 s, a new pseudo-view ~4.5 s),
87 min for three seeds, experiments/results/view_selection_fern/fern_views_small.md. The
runs resume, so it was split over three invocations (C below the table's args): five variants (41 min),
five more (45 min: killed after 8 min and resumed) and one with all variants that only
collects them (21 s). The presets that hold one another ran in the same invocation so
that they share their views; the second took its baselines from the first's 7x runs, so
that the table shows one baseline row:

  C="--name fern_views_small --config experiments/configs/table_small.gin \
     --data_dir ../shared/data/nerf_llff_data --scene fern --seeds 0 1 2"
  python -m experiments.table_view_selection $C \
    --baseline_from 'experiments/results/fern_rounds_small/Re-Nerfing (masks)/seed{seed}' \
    --variant "7x=Config.interp_factors='7x'" --variant "5x=Config.interp_factors='5x'" \
    --variant "3x_b=Config.interp_factors='3x_b'" \
    --variant "3x_c=Config.interp_factors='3x_c'" --variant "11x=Config.interp_factors='11x'"
  python -m experiments.table_view_selection $C \
    --baseline_from 'experiments/results/fern_views_small/7x/seed{seed}' \
    --variant "2x=Config.interp_factors='2x'" --variant "3x=Config.interp_factors='3x'" \
    --variant "4x=Config.interp_factors='4x'" \
    --variant "3 test poses=Config.pseudo_targets='test'" \
    --variant "3 random poses=Config.pseudo_targets='random';Config.pseudo_n_random=3"
  python -m experiments.table_view_selection $C \
    --baseline_from 'experiments/results/fern_rounds_small/Re-Nerfing (masks)/seed{seed}'

The last two variants have as many pseudo-views as the scene has test views (fern: 3,
every 8th of its 20 images).

The paper's numbers for this table are not in the script: the project has only its
Table 1 numbers (renerf_rounds.py).
"""
from experiments import tables
from renerf_jax.datasets import load_scene

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
