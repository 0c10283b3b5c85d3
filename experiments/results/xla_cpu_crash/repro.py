"""Issue 38: the XLA CPU crash of the old dense Hessian reference, reproduced on any x86 CPU.

The crash is in YNNPACK (XLA:CPU's library for dot, reduce and transpose fusions), whose
kernels are picked at run time from the CPU's own feature flags: `--xla_cpu_max_isa`
does not reach them. Under valgrind the program sees valgrind's virtual CPU, which has
no AVX-512, so YNNPACK takes the same kernels as on an AVX2-only machine.

  # From the repository root; PYTHONPATH=tests finds the test helpers it reuses, and
  # YNN=... turns XLA:CPU's YNNPACK fusions back on (renerf_jax turns them off on import
  # since the second crash, renerf_jax/xla_cpu.py; jaxlib 0.10.2's default is this value):
  YNN=--xla_cpu_experimental_ynn_fusion_type=individual_dot,reduce
  # 1. natively: train the proposal-sampler model of tests/test_proposal.py (800 steps)
  PYTHONPATH=tests python experiments/results/xla_cpu_crash/repro.py train /tmp/xla_crash_params.pkl
  # 2. under valgrind, one graph per process (about 5-15 minutes each on one core):
  XLA_FLAGS=$YNN PYTHONPATH=tests PYTHONMALLOC=malloc valgrind --log-file=vg_old.log \
    python experiments/results/xla_cpu_crash/repro.py old /tmp/xla_crash_params.pkl
  XLA_FLAGS=--xla_cpu_experimental_ynn_fusion_type= PYTHONPATH=tests PYTHONMALLOC=malloc \
    valgrind --log-file=vg_old_noynn.log \
    python experiments/results/xla_cpu_crash/repro.py old /tmp/xla_crash_params.pkl
  XLA_FLAGS=$YNN PYTHONPATH=tests PYTHONMALLOC=malloc valgrind --log-file=vg_new.log \
    python experiments/results/xla_cpu_crash/repro.py new /tmp/xla_crash_params.pkl

`old`: the reference as it was (jax.hessian = forward over reverse); `new`: the production
Hessian pass (laplace.hessian_diagonal) and the forward-mode reference of
tests/dense_reference.py on 64 rays, then the demo's Laplace-mask path
(synthesis.synthesize with Config.mask_signal = 'laplace', 2048 Hessian rays, 2 views).
"""
import dataclasses
import os
import pickle
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

import dense_reference  # tests/ (PYTHONPATH=tests)
from test_proposal import COVER

from renerf_jax.configs import Config, load_config
from renerf_jax.datasets import load_scene
from renerf_jax.datasets.scene import ray_pool
from renerf_jax.nerf import synthesis, training
from renerf_jax.nerf.fields import init_field_params
from renerf_jax.uncertainty import laplace
from renerf_jax.uncertainty.deformation import grid_size

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(
    os.path.abspath(__file__)))))

STEPS = 800


def old_reference(config, params, rays):
  """The reference before issue 38: diag(jax.hessian(loss)) (forward over reverse)."""
  cfg = dataclasses.replace(config, stop_level_grad=True)
  lo, hi = -jnp.ones(3), jnp.ones(3)
  theta0 = jnp.zeros((grid_size(1) * 3,), jnp.float32)
  rgb = lambda th: dense_reference._level_rgbs(cfg, params, rays, lo, hi, th)  # pylint: disable=protected-access
  target = jax.jit(rgb)(theta0)
  loss = lambda th: jnp.sum((rgb(th) - target)**2) / rays.origins.shape[0]
  return jax.jit(lambda: jnp.diag(jax.hessian(loss)(theta0)).reshape(-1, 3))()


def main(which, path):
  config = Config(**COVER, max_steps=STEPS)
  scene = load_scene(config)
  if which == 'train':
    pools = {'real': ray_pool(scene, scene.train_idx)}
    cam = training.Camera.of(scene)
    state = training.init_state(config, None, jax.jit(
        lambda k: init_field_params(config, k))(jax.random.PRNGKey(0)))
    for step in range(STEPS):
      state, _ = training.train_step(config, cam, False, state, pools,
                                     jax.random.PRNGKey(step))
    with open(path, 'wb') as f:
      pickle.dump(jax.device_get(state.params), f)
    return
  with open(path, 'rb') as f:
    params = jax.tree_util.tree_map(jnp.asarray, pickle.load(f))
  t = time.time()
  if which == 'old':
    rays = jax.tree_util.tree_map(lambda x: x[::192], ray_pool(scene, [0])['rays'])
    ref = np.asarray(old_reference(config, params, rays))
    print(f'old reference ok ({time.time() - t:.0f} s), sum {ref.sum():.4f}', flush=True)
    return
  rays = jax.tree_util.tree_map(lambda x: x[::48], ray_pool(scene, [0])['rays'])
  h = np.asarray(laplace.hessian_diagonal(config, params, rays, -1., 1., 1, 1e-4, chunk=8))
  print(f'production Hessian pass ok ({time.time() - t:.0f} s)', flush=True)
  ref = np.asarray(dense_reference.reference_hessian_diagonals(
      config, params, rays, -1., 1., 1)['gn'])
  print(f'forward-mode reference ok ({time.time() - t:.0f} s), max |h - ref - 2 lam| / '
        f'max ref = {np.max(np.abs(h - ref - 2e-4)) / ref.max():.2e}', flush=True)
  demo = load_config([os.path.join(REPO, 'gin_configs', 'demo_llff.gin')], [
      'Config.use_masks = True', "Config.mask_signal = 'laplace'",
      'Config.hessian_rays = 2048', "Config.interp_factors = '0.5'"])
  demo_scene = load_scene(demo)
  pv, _, _ = synthesis.synthesize(demo, demo_scene, training.init_state(
      demo, jax.random.PRNGKey(0)).params)
  print(f'demo Laplace-mask path ok ({time.time() - t:.0f} s), {pv.images.shape[0]} views, '
        f'kept {np.mean(pv.masks):.3f}', flush=True)


if __name__ == '__main__':
  main(sys.argv[1], sys.argv[2])
