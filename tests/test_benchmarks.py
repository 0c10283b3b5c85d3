"""Tests of the benchmark scripts' bookkeeping (not of any timing)."""
import os

from benchmarks.bench_throughput import add_speedups


def test_speedups_are_against_the_first_config_of_the_same_stage():
  rows = [{'config': 'a', 'stage': 'train', 'rays_per_s': 100.},
          {'config': 'a', 'stage': 'render', 'rays_per_s': 1000.},
          {'config': 'b', 'stage': 'train', 'rays_per_s': 250.},
          {'config': 'b', 'stage': 'render', 'rays_per_s': 500.}]
  add_speedups(rows)
  assert [r['speedup'] for r in rows] == [1., 1., 2.5, 0.5]


def test_hessian_bench_matches_the_previous_pass_and_computes_fewer_padded_rays(tmp_path):
  """benchmarks/bench_hessian.py: the frozen previous pass and today's give the same
  diagonal; 100 rays in chunks of at most 64 compute 100 (2 x 50) instead of 128."""
  from benchmarks import bench_hessian  # pylint: disable=g-import-not-at-top
  bindings = ["Config.dataset_loader = 'procedural'", 'Config.procedural_size = (16, 20)',
              'Config.num_samples = 8', 'Config.net_depth = 2', 'Config.net_width = 32',
              'Config.skip_layer = 1', 'Config.net_width_viewdirs = 16']
  demo = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                      'gin_configs', 'demo_llff.gin')
  args = ['--configs', demo, '--rays', '100', '--chunk', '64',
          '--log2_res', '3', '--repeats', '1', '--out', str(tmp_path / 'h')]
  for b in bindings:
    args += ['--gin_bindings', b]
  (row,) = bench_hessian.main(args)
  assert row['rays'] == 100 and row['finite']
  assert (row['rays_computed_previous'], row['rays_computed_today']) == (128, 100)
  assert row['max_rel_diff'] < 1e-5
  assert row['parts']['rays'] == 50 and row['parts']['sensitivities_s'] > 0
  assert '| 128 / 100 |' in (tmp_path / 'h.md').read_text()
