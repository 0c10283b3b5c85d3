"""XLA's persistent compilation cache: compiled steps reused across rounds and processes.

Every Config field is a static argument of the jitted train and render steps, so a new
seed (each round trains with its own), a new variant of a table or a resumed process
recompiles steps whose computation has not changed: about 7 s for the small table
config's train step on the 2-core CPU, several steps per round. The cache is keyed on the
lowered computation (HLO) and the compile options, never on the Config, so a hit is the
executable that compiling the same computation would give; only tracing is repeated
(the first step of a new seed: 1.8 s instead of 7.1 s, of a new process: 2.4 s instead
of 7.9 s; benchmarks/results/compile_cache.md, `python -m benchmarks.bench_compile_cache`).
"""
import os

import jax

ENV_VAR = 'RENERF_JAX_CACHE_DIR'
# Every compile is written, the tiny ones too: flax's and optax's inits run op by op,
# dozens of small programs a training run that release_compiled (between a table's runs)
# would otherwise compile again. A one-seed table of the test suite's tiny config ran in
# 62 s with 0.5 here and 34 s with 0, the cache warm (12 MB, 174 files).
MIN_COMPILE_SECONDS = 0.


def default_cache_dir():
  """$RENERF_JAX_CACHE_DIR, else ~/.cache/renerf_jax/xla; '' or 'off' disables it."""
  return os.environ.get(ENV_VAR, os.path.join(os.path.expanduser('~'), '.cache',
                                               'renerf_jax', 'xla'))


def enable_compilation_cache(path=None):
  """Turns on the persistent compilation cache in `path` (default default_cache_dir()).

  Args:
    path: cache directory (created if missing); '' or 'off' leaves the cache off.

  Returns:
    The directory in use, or None when the cache is off.
  """
  path = default_cache_dir() if path is None else str(path)
  if path in ('', 'off'):
    return None
  os.makedirs(path, exist_ok=True)
  jax.config.update('jax_compilation_cache_dir', path)
  jax.config.update('jax_persistent_cache_min_compile_time_secs', MIN_COMPILE_SECONDS)
  jax.config.update('jax_persistent_cache_min_entry_size_bytes', 0)
  return path


def mapped_regions():
  """Number of memory mappings of this process (lines of /proc/self/maps; None where
  the file does not exist, e.g. off Linux)."""
  try:
    with open('/proc/self/maps', 'rb') as f:
      return sum(1 for _ in f)
  except OSError:
    return None


def release_compiled():
  """Drops every in-memory compiled executable (jax.clear_caches) and frees them.

  Each executable XLA's CPU backend compiles holds memory mappings of its own, and a
  Config is a static argument, so every (variant, seed) of a table compiles its steps
  afresh and the old ones are never called again. Kept, they pile up: the ten-variant
  view-selection table died after 26 runs in one process with "LLVM compilation error:
  Cannot allocate memory" (Linux's limit of 65530 mappings per process). Calling this
  between runs keeps the count flat; with the persistent cache on, the next run's
  compiles are cache hits.
  """
  import gc  # pylint: disable=g-import-not-at-top
  jax.clear_caches()
  gc.collect()
