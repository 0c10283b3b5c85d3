"""XLA:CPU's thread pool decides the last bits of a dot product (issue 62).

Runs the same jitted float32 dot products (shapes like a render chunk's: a long inner
dimension) in fresh processes that differ only in the CPUs they may use (their affinity)
and the CPU devices they have (--xla_force_host_platform_device_count), with the
project's XLA flags (renerf_jax imported first), and prints which runs give the same
bytes. A process's pool has max(CPUs, devices) threads: equal pools give equal bytes,
another pool size may change the last bit of some values.

  python experiments/results/multi_host/thread_pool_dot.py

Needs 2 free CPUs for every row (with one, the rows of 2 CPUs are left out).
"""
import hashlib
import os
import subprocess
import sys

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(
    os.path.abspath(__file__)))))
CHILD = r'''
import hashlib, sys
import renerf_jax  # the project's XLA flags (no YNNPACK fusions)
import jax, jax.numpy as jnp, numpy as np
rng = np.random.default_rng(0)
h = hashlib.sha256()
for m, k, n in [(4, 200000, 4), (32, 65536, 8), (64, 4096, 64), (1024, 1024, 32)]:
  a = jnp.asarray(rng.normal(size=(m, k)).astype(np.float32))
  b = jnp.asarray(rng.normal(size=(k, n)).astype(np.float32))
  h.update(np.asarray(jax.jit(jnp.dot)(a, b)).tobytes())
print(h.hexdigest()[:12], len(jax.devices()))
'''


def run(cpus, devices):
  env = dict(os.environ, JAX_PLATFORMS='cpu', PYTHONPATH=REPO,
             XLA_FLAGS=f'--xla_force_host_platform_device_count={devices}')
  out = subprocess.run([sys.executable, '-c', CHILD], env=env, cwd=REPO, check=True,
                       capture_output=True, text=True,
                       preexec_fn=lambda: os.sched_setaffinity(0, cpus)).stdout.split()
  return out[0]


def main():
  free = sorted(os.sched_getaffinity(0))
  rows = []
  for cpus in ([free[0]], free[:2]) if len(free) > 1 else ([free[0]],):
    for devices in (1, 2):
      rows.append((len(cpus), devices, max(len(cpus), devices), run(set(cpus), devices)))
  print('| CPUs | devices | pool threads | sha256 of the results |')
  print('|---|---|---|---|')
  for row in rows:
    print('| %d | %d | %d | %s |' % row)
  by_pool = {}
  for _, _, pool, digest in rows:
    by_pool.setdefault(pool, set()).add(digest)
  print('\nequal pools give equal bytes:', all(len(d) == 1 for d in by_pool.values()),
        '; pools of different sizes differ:', len(set().union(*by_pool.values())) > 1)


if __name__ == '__main__':
  main()
