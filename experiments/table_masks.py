"""Masks ablation (the paper's rows: augmented views / stop aug. views / + masks).

Round 1 on top of the baseline: pseudo-views kept for the whole training ("augmented
views", Config.pseudo_schedule='all'), removed at step K ("stop aug. views", the method),
and removed at K with the Laplace-uncertainty masks ("+ masks", Config.use_masks=True:
the Hessian pass runs and the most uncertain pixels are left out of the loss). The three
variants share one baseline per seed (taken from the rounds table with --baseline_from).
Fern on the 2-core CPU with the hour-budget table config (table_tiny.gin: 126x94,
512 rays a step), baselines and '+ masks' from its rounds table: 8.9 min for three
seeds, experiments/results/masks_ablation_fern/fern_masks_tiny.md:

  python -m experiments.table_masks --name fern_masks_tiny \
    --config experiments/configs/table_tiny.gin --data_dir ../shared/data/nerf_llff_data \
    --scene fern --seeds 0 1 2 \
    --baseline_from 'experiments/results/fern_rounds_tiny/Re-Nerfing (masks)/seed{seed}'

With the small table config (table_small.gin, see table_why.py), baselines and
the '+ masks' rounds taken from the rounds table
(renerf_rounds.py: the same config with Config.use_masks=True, so its R1 is this
table's '+ masks' and is copied, not trained again): 21.5 min for three seeds,
experiments/results/masks_ablation_fern/fern_masks_small.md:

  python -m experiments.table_masks --name fern_masks_small \
    --config experiments/configs/table_small.gin --data_dir ../shared/data/nerf_llff_data \
    --scene fern --seeds 0 1 2 \
    --baseline_from 'experiments/results/fern_rounds_small/Re-Nerfing (masks)/seed{seed}'

Without the rounds table's runs it trains the baselines and '+ masks' too (about 20 min
more: a baseline ~2.5 min, a masked round ~4 min a seed).

Fast grid backbone at full resolution:
experiments/results/masks_ablation_fern/fern_masks_fast.md was made with the 650-step llff3_fast_renerf.gin of commit d6dd94a (restore it with
`git checkout d6dd94a -- gin_configs` to resume or reproduce), the baselines taken from
the baseline table made with the same config:

  python -m experiments.table_masks --name fern_masks_fast \
    --config gin_configs/llff3_fast_renerf.gin --data_dir ../shared/data/nerf_llff_data \
    --scene fern --seeds 0 1 2 \
    --baseline_from 'experiments/results/fern_fast_baseline/Re-Nerfing/seed{seed}'

Its rounds took 443-482 s each (pseudo-views and training; the '+ masks' Hessian pass
56-58 s), plus about a minute of evaluation.

The paper's numbers for this table are not in the script: the project has only its
Table 1 numbers (renerf_rounds.py).
"""
from experiments import tables

VARIANTS = ["augmented views=Config.pseudo_schedule='all'",
            'stop aug. views=',
            "+ masks=Config.use_masks=True;Config.mask_signal='laplace'"]


def main():
  args = tables.parser(__doc__, default_rounds=1).parse_args()
  tables.run_table(args, args.variant or VARIANTS,
                   paper_note="The paper's numbers for this table are not included.")


if __name__ == '__main__':
  main()
