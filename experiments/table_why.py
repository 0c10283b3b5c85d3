"""Table "why": what makes Re-Nerfing work (the paper's ablation of the training recipe).

Round 1 variants on top of one shared baseline per seed:
  reset + remove at K   the method: D from scratch, pseudo-views only for steps < K
  2x longer training    the baseline trained for twice the steps, no pseudo-views
  no reset              D continues from B's parameters (pseudo-views until K)
  reset + keep views    pseudo-views kept to the end (Config.pseudo_schedule='all')
  reset + add late      pseudo-views only in the last K steps ('late')
Fern, CPU, fast grid backbone, estimated from the idle-CPU rates of
benchmarks/results/throughput.md: twelve rounds of ~7 min and three 2x-long baselines of
~8 min, about 1.8 hours with the baselines reused (from a rounds table made with the same
--config; see table_masks.py):

  python experiments/table_why.py --name fern_why_fast \
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


def variants(max_steps):
  return ['reset + remove at K=',
          f'2x longer training=Config.num_rounds=0;Config.max_steps={2 * max_steps}',
          "no reset=Config.renerf_init='continue'",
          "reset + keep views=Config.pseudo_schedule='all'",
          "reset + add late=Config.pseudo_schedule='late'"]


def main():
  args = tables.parser(__doc__, default_rounds=1).parse_args()
  tables.run_table(args, args.variant or variants(tables.base_config(args).max_steps),
                   paper_note="The paper's numbers for this table are not included.")


if __name__ == '__main__':
  main()
