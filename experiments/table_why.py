"""Table "why": what makes Re-Nerfing work (the paper's ablation of the training recipe).

Round 1 variants on top of one shared baseline per seed:
  reset + remove at K   the method: D from scratch, pseudo-views only for steps < K
  2x longer training    the baseline trained for twice the steps, no pseudo-views
  no reset              D continues from B's parameters (pseudo-views until K)
  reset + keep views    pseudo-views kept to the end (Config.pseudo_schedule='all')
  reset + add late      pseudo-views only in the last K steps ('late')
Fern on the 2-core CPU with the small table config (experiments/configs/table_small.gin:
the fast grid backbone at half resolution, 400 steps): measured 45 min for three seeds
(12.6 min for seed 0 alone on an idle CPU; seeds 1 and 2 shared the CPU with the test
suite for part of their time), experiments/results/why_ablation_fern/fern_why_small.md:

  python -m experiments.table_why --name fern_why_small \
    --config experiments/configs/table_small.gin --data_dir ../shared/data/nerf_llff_data \
    --scene fern --seeds 0 1 2

With the full-resolution fast config (--config gin_configs/llff3_fast.gin
gin_configs/renerf.gin) a seed should take about four times as long (4x the rays
trained, 4x the pixels rendered; estimated, not measured).

The paper's numbers for this table are not in the script: the project has only its
Table 1 numbers (renerf_rounds.py).
"""
from experiments import tables


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
