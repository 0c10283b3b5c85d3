"""Masks ablation (the paper's rows: augmented views / stop aug. views / + masks).

Round 1 on top of the baseline: pseudo-views kept for the whole training ("augmented
views", Config.pseudo_schedule='all'), removed at step K ("stop aug. views", the method),
and removed at K with the Laplace-uncertainty masks ("+ masks", Config.use_masks=True:
the Hessian pass runs and the most uncertain pixels are left out of the loss). The three
variants share one baseline per seed (taken from the rounds table with --baseline_from).
Fern, CPU, fast grid backbone, estimated from the idle-CPU rates of
benchmarks/results/throughput.md: nine rounds of ~7 min (pseudo-views ~2.4 min, training
and evaluation ~4.5 min, plus a ~50 s Hessian pass for '+ masks'), about 65 min with the
baselines reused from a rounds table made with the same --config (for fern_rounds_fast,
made before llff3_fast.gin's lr change, add --gin_bindings "Config.lr_final = 1e-3"):

  python experiments/table_masks.py --name fern_masks_fast \
    --config gin_configs/llff3_fast_renerf.gin --data_dir ../shared/data/nerf_llff_data \
    --scene fern --seeds 0 1 2 \
    --baseline_from 'experiments/results/fern_rounds_fast/Re-Nerfing/seed{seed}'

The paper's numbers for this table are not in the script: the project has only its
Table 1 numbers (renerf_rounds.py).
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import tables  # pylint: disable=g-import-not-at-top

VARIANTS = ["augmented views=Config.pseudo_schedule='all'",
            'stop aug. views=',
            '+ masks=Config.use_masks=True']


def main():
  args = tables.parser(__doc__, default_rounds=1).parse_args()
  tables.run_table(args, args.variant or VARIANTS,
                   paper_note="The paper's numbers for this table are not included.")


if __name__ == '__main__':
  main()
