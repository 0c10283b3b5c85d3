"""YNNPACK fusions off by default (renerf_jax.xla_cpu): the flag, and that XLA obeys it."""
import json
import os
import subprocess
import sys

import numpy as np

from conftest import REPO
from renerf_jax import xla_cpu

FLAG = xla_cpu.FLAG


def test_the_flag_is_added_once_and_a_users_choice_is_kept():
  env = {}
  assert xla_cpu.avoid_ynn_fusions(env) and env['XLA_FLAGS'] == f'{FLAG}='
  assert not xla_cpu.avoid_ynn_fusions(env) and env['XLA_FLAGS'] == f'{FLAG}='
  env = {'XLA_FLAGS': '--xla_force_host_platform_device_count=2'}
  assert xla_cpu.avoid_ynn_fusions(env)
  assert env['XLA_FLAGS'] == f'--xla_force_host_platform_device_count=2 {FLAG}='
  for chosen in (f'{FLAG}=individual_dot', f'--a=1 {FLAG}=dot', FLAG):
    env = {'XLA_FLAGS': chosen}
    assert not xla_cpu.avoid_ynn_fusions(env) and env['XLA_FLAGS'] == chosen
  env = {'XLA_FLAGS': f'{FLAG}_other=1'}  # another flag with the same prefix
  assert xla_cpu.avoid_ynn_fusions(env) and env['XLA_FLAGS'].endswith(f' {FLAG}=')


_PROBE = r'''
import json, renerf_jax, jax, jax.numpy as jnp, numpy as np
k1, k2, k3 = jax.random.split(jax.random.PRNGKey(0), 3)
x = jax.random.normal(k1, (512, 64)); w1 = jax.random.normal(k2, (64, 64)) / 8
w2 = jax.random.normal(k3, (64, 3)) / 8
f = jax.jit(lambda x, w1, w2: jnp.sum(jax.nn.relu(x @ w1) @ w2, axis=0))
text = f.lower(x, w1, w2).compile().as_text()
print(json.dumps({'ynn': text.count('__ynn'), 'out': np.asarray(f(x, w1, w2)).tolist()}))
'''


def _probe(xla_flags):
  env = dict(os.environ)
  env.pop('XLA_FLAGS', None)
  if xla_flags is not None:
    env['XLA_FLAGS'] = xla_flags
  res = subprocess.run([sys.executable, '-c', _PROBE], cwd=REPO, env=env, timeout=300,
                       capture_output=True, text=True, check=False)
  assert res.returncode == 0, res.stderr[-2000:]
  return json.loads(res.stdout.strip().splitlines()[-1])


def test_importing_the_package_compiles_without_ynn_fusions_and_the_same_numbers():
  off = _probe(None)
  on = _probe(f'{FLAG}=individual_dot,reduce')  # jaxlib 0.10.2's default, set by a user
  assert off['ynn'] == 0
  assert on['ynn'] > 0  # the flag is the one this jaxlib reads: with it the dots go to YNN
  np.testing.assert_allclose(off['out'], on['out'], rtol=1e-5, atol=1e-5)
