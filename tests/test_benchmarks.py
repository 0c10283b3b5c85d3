"""Tests of the benchmark scripts' bookkeeping (not of any timing)."""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from benchmarks.bench_throughput import add_speedups  # pylint: disable=g-import-not-at-top


def test_speedups_are_against_the_first_config_of_the_same_stage():
  rows = [{'config': 'a', 'stage': 'train', 'rays_per_s': 100.},
          {'config': 'a', 'stage': 'render', 'rays_per_s': 1000.},
          {'config': 'b', 'stage': 'train', 'rays_per_s': 250.},
          {'config': 'b', 'stage': 'render', 'rays_per_s': 500.}]
  add_speedups(rows)
  assert [r['speedup'] for r in rows] == [1., 1., 2.5, 0.5]
