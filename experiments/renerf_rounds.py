"""Table 1 of the paper: LLFF 3-view Re-Nerfing rounds, and the baseline at equal time.

Baseline, R1, R2, R3 (each round a model trained from scratch on the real views plus the
previous round's pseudo-views), and the baseline trained for the same total wall time as
the rounds (the control that tells "more compute" from "Re-Nerfing"). Mean +- std over
seeds with a fixed step count per round.

Fern on the 2-core CPU with the hour-budget table config
(experiments/configs/table_tiny.gin: the small config at 126x94 with 512 rays a step)
and the Laplace masks on (the full method),
experiments/results/renerf_rounds_fern/fern_rounds_tiny.md, in one invocation of 53 min (rounds
26.6 min, equal-time control 26.5 min; a masked round 2.4 min):

  python -m experiments.renerf_rounds --name fern_rounds_tiny \
    --config experiments/configs/table_tiny.gin --data_dir ../shared/data/nerf_llff_data \
    --scene fern --seeds 0 1 2 --variant 'Re-Nerfing (masks)=Config.use_masks=True'

With the small table config (table_small.gin, see table_why.py: 252x189, 1024
rays a step), the same table is
experiments/results/renerf_rounds_fern/fern_rounds_small.md, which takes longer than an hour. The rounds of three seeds took 49 min (an
invocation of 17 min, killed and resumed by a second of 32 min), the equal-time control
39 min more (a third invocation, without --no_equal_time: it reuses the finished rounds):

  python -m experiments.renerf_rounds --name fern_rounds_small \
    --config experiments/configs/table_small.gin --data_dir ../shared/data/nerf_llff_data \
    --scene fern --seeds 0 1 2 \
    --variant 'Re-Nerfing (masks)=Config.use_masks=True' [--no_equal_time]

Fast grid backbone at full resolution: fern_rounds_fast was made with llff3_fast.gin as
it was before its lr change (650 steps with annealing, lr 1e-2 -> 1e-3) and took about
38 min per seed for the rounds, the equal-time baselines as long again. To resume or
reproduce it, restore the configs of commit d6dd94a (`git checkout d6dd94a --
gin_configs`) and run

  python -m experiments.renerf_rounds --name fern_rounds_fast \
    --config gin_configs/llff3_fast_renerf.gin --data_dir ../shared/data/nerf_llff_data \
    --scene fern --seeds 0 1 2 --gin_bindings "Config.lr_final = 1e-3"

Paper scale: --config gin_configs/llff3.gin gin_configs/renerf.gin. See
experiments/tables.py for the run directories, baseline sharing and the equal-time rule.
"""
from experiments import tables

# Re-Nerfing paper, LLFF 3 views, mean over the 8 scenes, RegNeRF base (PSNR, SSIM, LPIPS).
PAPER_LLFF3 = {('*', 'baseline'): (19.08, .685, .148), ('*', 'R1'): (19.35, .713, .133),
               ('*', 'R2'): (19.47, .724, .126), ('*', 'R3'): (19.52, .725, .127)}


def main():
  p = tables.parser(__doc__, default_rounds=3)
  p.add_argument('--no_equal_time', action='store_true',
                 help='skip the baseline trained for the total time of the rounds')
  args = p.parse_args()
  tables.run_table(args, args.variant or ['Re-Nerfing='], paper=PAPER_LLFF3,
                   equal_time=not args.no_equal_time,
                   paper_note='Paper: Re-Nerfing, LLFF 3-view mean of 8 scenes, RegNeRF '
                              'base, full GPU scale.')


if __name__ == '__main__':
  main()
