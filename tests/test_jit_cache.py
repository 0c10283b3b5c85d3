"""The persistent compilation cache: a second process reuses the first one's executables."""
import os
import subprocess
import sys

from conftest import REPO

SCRIPT = '''
import logging, sys
import jax, jax.numpy as jnp
from renerf_jax import jit_cache
jit_cache.MIN_COMPILE_SECONDS = 0.
print('dir', jit_cache.enable_compilation_cache(sys.argv[1]))
logging.basicConfig(level=logging.DEBUG, stream=sys.stdout)
@jax.jit
def f(x):
  for _ in range(20):
    x = jnp.sin(x @ x.T) + x
  return x
print('sum', float(f(jnp.ones((16, 16))).sum()))
'''


def _run(cache_dir):
  env = dict(os.environ)
  env.pop('RENERF_JAX_CACHE_DIR', None)
  return subprocess.run([sys.executable, '-c', SCRIPT, cache_dir], cwd=REPO, env=env,
                        capture_output=True, text=True, timeout=300, check=True).stdout


def test_second_process_loads_the_compiled_step_from_the_cache(tmp_path):
  cache = str(tmp_path / 'xla')
  first = _run(cache)
  files = sorted(os.listdir(cache))
  assert f'dir {cache}' in first and any(f.startswith('jit_f') for f in files)
  assert "Persistent compilation cache hit for 'jit_f'" not in first
  second = _run(cache)
  assert "Persistent compilation cache hit for 'jit_f'" in second
  assert sorted(os.listdir(cache)) == files  # nothing compiled anew
  # The cached executable computes the same result.
  assert [l for l in first.splitlines() if l.startswith('sum')] == [
      l for l in second.splitlines() if l.startswith('sum')]


def test_cache_off_and_default_dir(monkeypatch):
  from renerf_jax import jit_cache  # pylint: disable=g-import-not-at-top
  monkeypatch.setenv('RENERF_JAX_CACHE_DIR', 'off')
  assert jit_cache.enable_compilation_cache() is None
  monkeypatch.delenv('RENERF_JAX_CACHE_DIR')
  assert jit_cache.default_cache_dir().endswith(os.path.join('.cache', 'renerf_jax', 'xla'))


MAPS_SCRIPT = '''
import functools, sys
import jax, jax.numpy as jnp
from renerf_jax import jit_cache
release = sys.argv[1] == '1'
@functools.partial(jax.jit, static_argnums=0)
def f(k, x):  # A new static k compiles a new executable, as a new Config does.
  for _ in range(10):
    x = jnp.sin(x * k) + x
  return x
f(-1., jnp.ones(8)).block_until_ready()
if release:
  jit_cache.release_compiled()
before = jit_cache.mapped_regions()
for k in range(30):
  f(float(k), jnp.ones(8)).block_until_ready()
  if release:
    jit_cache.release_compiled()
print('growth', jit_cache.mapped_regions() - before)
'''


def _maps_growth(release):
  env = dict(os.environ, RENERF_JAX_CACHE_DIR='off')
  out = subprocess.run([sys.executable, '-c', MAPS_SCRIPT, '1' if release else '0'],
                       cwd=REPO, env=env, capture_output=True, text=True, timeout=300,
                       check=True).stdout
  return int(out.split('growth')[-1])


def test_release_compiled_keeps_the_memory_mappings_flat():
  """Each compiled executable holds memory mappings; a table compiles new ones every run
  (a new Config) and died at Linux's 65530 once. Released between compiles, the count
  stays flat; kept, it grows with every compile."""
  kept, released = _maps_growth(False), _maps_growth(True)
  assert kept >= 30, kept
  assert released <= 5, released
