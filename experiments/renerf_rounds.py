"""Table 1 of the paper: LLFF 3-view Re-Nerfing rounds, and the baseline at equal time.

Baseline, R1, R2, R3 (each round a model trained from scratch on the real views plus the
previous round's pseudo-views), and the baseline trained for the same total wall time as
the rounds (the control that tells "more compute" from "Re-Nerfing"). Mean +- std over
seeds with a fixed step count per round. Fern, CPU, fast grid backbone, estimated from
the idle-CPU rates of benchmarks/results/throughput.md (a 650-step training ~3.5 min plus
~1 min of evaluation, 12 pseudo-views ~2.4 min): ~25 min per seed, ~75 min for 3 seeds,
and the equal-time baselines as long again. fern_rounds_fast was made before the lr change
of llff3_fast.gin (and before the 2.7x faster grid renderer: ~38 min per seed); to resume
or reuse it add --gin_bindings "Config.lr_final = 1e-3".

  python experiments/renerf_rounds.py --name fern_rounds_fast \
    --config gin_configs/llff3_fast_renerf.gin --data_dir ../shared/data/nerf_llff_data \
    --scene fern --seeds 0 1 2

Paper scale: --config gin_configs/llff3_renerf.gin. See experiments/tables.py for the run
directories, baseline sharing and the equal-time rule.
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import tables  # pylint: disable=g-import-not-at-top

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
