"""XLA's persistent compilation cache: compiled steps reused across rounds and processes.

Every Config field is a static argument of the jitted train and render steps, so a new
seed (each round trains with its own), a new variant of a table or a resumed process
recompiles steps whose computation has not changed: about 7 s for the small table
config's train step on the 2-core CPU, several steps per round. The cache is keyed on the
lowered computation (HLO) and the compile options, never on the Config, so a hit is the
executable that compiling the same computation would give; only tracing is repeated
(the first step of a new seed: 1.8 s instead of 7.1 s, of a new process: 2.4 s instead
of 7.9 s; benchmarks/results/compile_cache.md, `python benchmarks/bench_compile_cache.py`).
"""
import os

import jax

ENV_VAR = 'RENERF_JAX_CACHE_DIR'
# Steps that compile in less than this are not written (tiny helpers, not worth a file).
MIN_COMPILE_SECONDS = 0.5


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
