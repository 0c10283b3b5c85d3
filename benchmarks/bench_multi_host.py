"""What one step costs with several processes: bytes all-reduced, 1- vs 2-process step time.

taskset -c 0 python -m benchmarks.bench_multi_host --out experiments/results/multi_host/bench

1. Bytes per step: the parameter bytes (from the pytrees) and the bytes of every
   all-reduce in each NeRF config's train step compiled for 2 devices (XLA's SPMD
   partitioner inserts them: the gradients of each level that renders colour, summed
   after the all-reduce, plus a few scalars); the Gaussians' step is replicated (one
   image a step), so it all-reduces nothing.
2. Step time of --config's NeRF train step in one process (one CPU device) and in two
   processes (gloo on loopback) with the same global batch, the median of --steps after
   --warmup steps; both runs inherit this command's CPU affinity (taskset -c 0: two
   processes share one core, so no speed-up is possible here, only the overhead shows).
3. The all-reduce alone: the median time of a jitted sum over the two processes of a
   float32 vector of the config's gradient size (a gloo all-reduce on loopback).

Writes <out>.json and <out>.md (the 8-GPU estimate lives in docs/multi_host.md).
"""
import argparse
import json
import os
import subprocess
import sys
import time

import jax
import numpy as np

from benchmarks.ports import free_port

NERF_CONFIGS = ('gin_configs/demo_llff.gin', 'gin_configs/llff3_cpu.gin', 'gin_configs/llff3.gin',
                'gin_configs/llff3_fast.gin')
GAUSSIAN_CONFIGS = ('gin_configs/gaussians_llff3_cpu.gin', 'gin_configs/gaussians_llff3.gin')


def param_bytes(config_path):
  """(parameter count, float32 bytes) of a config's model, from shapes only."""
  from renerf_jax.backbones import get_backbone  # pylint: disable=g-import-not-at-top
  from renerf_jax.configs import load_config  # pylint: disable=g-import-not-at-top
  config = load_config([config_path])
  shapes = jax.eval_shape(lambda: get_backbone(config).init_params(config))
  leaves = [x for x in jax.tree_util.tree_leaves(shapes) if x.dtype != np.bool_]
  n = int(sum(np.prod(x.shape) for x in leaves))
  return config, n, int(sum(np.prod(x.shape) * x.dtype.itemsize for x in leaves))


def bytes_table(hlo_bytes):
  """Rows {config, backbone, params, param_bytes, bytes_per_step, what}.

  Args:
    hlo_bytes: {config path: all-reduced bytes in its compiled 2-device step}.
  """
  rows = []
  for path in NERF_CONFIGS:
    config, n, b = param_bytes(path)
    rows.append({'config': os.path.basename(path), 'backbone': 'nerf',
                 'batch_rays': config.batch_size, 'params': n, 'param_bytes': b,
                 'bytes_per_step': hlo_bytes[path],
                 'what': f'gradients, all-reduced per level ({hlo_bytes[path] / b:.2f} x '
                         'the parameters)'})
  for path in GAUSSIAN_CONFIGS:
    config, n, b = param_bytes(path)
    rows.append({'config': os.path.basename(path), 'backbone': 'gaussians',
                 'batch_rays': 0, 'params': n, 'param_bytes': b, 'bytes_per_step': 0,
                 'what': 'none: one image a step, the step is replicated'})
  return rows


def hlo_worker(args):
  """Prints {config: all-reduced bytes} of each NeRF config's compiled step on the
  devices this process has (run with 2 forced CPU devices)."""
  from renerf_jax.nerf import training  # pylint: disable=g-import-not-at-top
  from renerf_jax.configs import load_config  # pylint: disable=g-import-not-at-top
  from renerf_jax.datasets import load_scene  # pylint: disable=g-import-not-at-top
  from renerf_jax.nerf.pools import make_pools  # pylint: disable=g-import-not-at-top
  out = {}
  for path in NERF_CONFIGS:
    config = load_config([path], [f"Config.data_dir = '{args.data_dir}'"])
    scene = load_scene(config)
    rep = training.replicated_sharding()
    state = jax.eval_shape(lambda c=config: training.init_state(c, jax.random.PRNGKey(0)))
    state = jax.tree_util.tree_map(
        lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=rep), state)
    hlo = training.train_step.lower(config, training.Camera.of(scene), False, state,
                                    make_pools(config, scene, None),
                                    jax.random.PRNGKey(0)).compile().as_text()
    out[path] = hlo_collective_bytes(hlo).get('all-reduce', (0, 0))[1]
  print(json.dumps(out), flush=True)


_DTYPE_BYTES = {'f32': 4, 'f64': 8, 's32': 4, 'u32': 4, 'pred': 1, 'f16': 2, 'bf16': 2,
                's64': 8, 'u64': 8, 's8': 1, 'u8': 1}


def hlo_collective_bytes(hlo_text):
  """{op: (count, bytes)} of the all-reduce / all-gather / reduce-scatter results in a
  compiled HLO module's text (what the partitioner inserted)."""
  import re  # pylint: disable=g-import-not-at-top
  out = {}
  for line in hlo_text.splitlines():
    m = re.search(r' = (.*) (all-reduce|all-gather|reduce-scatter)(?:-start)?\(', line)
    if not m:
      continue
    size = sum(_DTYPE_BYTES.get(t, 4) * int(np.prod([int(d) for d in dims.split(',') if d]))
               for t, dims in re.findall(r'(\w+)\[([\d,]*)\]', m.group(1)))
    count, total = out.get(m.group(2), (0, 0))
    out[m.group(2)] = (count + 1, total + size)
  return out


def worker(args):
  """One process of the timing run: prints one JSON line (process 0)."""
  from renerf_jax import distributed  # pylint: disable=g-import-not-at-top
  from renerf_jax.nerf import training  # pylint: disable=g-import-not-at-top
  from renerf_jax.configs import load_config  # pylint: disable=g-import-not-at-top
  from renerf_jax.datasets import load_scene  # pylint: disable=g-import-not-at-top
  from renerf_jax.nerf.pools import make_pools  # pylint: disable=g-import-not-at-top
  if args.num_processes > 1:
    distributed.start(distributed.Cluster(args.num_processes, args.process_id,
                                          args.coordinator_address, 'flags'),
                      supervised=False)
  config = load_config([args.config])
  scene = load_scene(config)
  rep = training.replicated_sharding()
  state = jax.device_put(training.init_state(config, jax.random.PRNGKey(0)), rep)
  pools = distributed.replicate(make_pools(config, scene, None), rep)
  cam = training.Camera.of(scene)
  hlo = training.train_step.lower(config, cam, False, state, pools, distributed.replicate(
      jax.random.PRNGKey(0), rep)).compile().as_text()
  times = []
  for i in range(args.warmup + args.steps):
    key = distributed.replicate(jax.random.PRNGKey(i), rep)
    t = time.perf_counter()
    state, stats = training.train_step(config, cam, False, state, pools, key)
    loss = float(jax.device_get(stats['loss']))
    times.append(time.perf_counter() - t)
  out = {'processes': jax.process_count(), 'devices': jax.device_count(),
         'step_s': float(np.median(times[args.warmup:])), 'last_loss': loss,
         'collectives': hlo_collective_bytes(hlo)}
  if jax.process_count() > 1:
    _, n, _ = param_bytes(args.config)
    sharding = training.data_sharding()
    x = jax.make_array_from_process_local_data(sharding, np.ones((1, n), np.float32))
    total = jax.jit(lambda a: a.sum(0), out_shardings=rep)
    jax.block_until_ready(total(x))
    ar = []
    for _ in range(args.steps):
      t = time.perf_counter()
      jax.block_until_ready(total(x))
      ar.append(time.perf_counter() - t)
    out['allreduce_s'] = float(np.median(ar))
    out['allreduce_bytes'] = 4 * n
  if jax.process_index() == 0:
    print(json.dumps(out), flush=True)


def timed_run(args, n):
  """Runs the worker as n processes; returns process 0's JSON."""
  port = free_port()
  base = [sys.executable, '-m', 'benchmarks.bench_multi_host', '--worker',
          '--config', args.config, '--steps', str(args.steps), '--warmup', str(args.warmup),
          '--num_processes', str(n), '--coordinator_address', f'127.0.0.1:{port}']
  env = dict(os.environ, JAX_PLATFORMS='cpu')
  env.pop('XLA_FLAGS', None)
  procs = [subprocess.Popen(base + ['--process_id', str(i)], env=env,
                            stdout=subprocess.PIPE, text=True) for i in range(n)]
  try:
    outs = [p.communicate(timeout=1800)[0] for p in procs]
  finally:
    for p in procs:
      if p.poll() is None:
        p.kill()
  line = [ln for ln in outs[0].splitlines() if ln.startswith('{')][-1]
  return json.loads(line)


def main():
  p = argparse.ArgumentParser(description=__doc__)
  p.add_argument('--config', default='gin_configs/demo_llff.gin')
  p.add_argument('--steps', type=int, default=30)
  p.add_argument('--warmup', type=int, default=3)
  p.add_argument('--out', default='experiments/results/multi_host/bench')
  p.add_argument('--data_dir', default='../shared/data/nerf_llff_data',
                 help='LLFF scenes (llff3*.gin load fern to build their step)')
  p.add_argument('--worker', action='store_true', help=argparse.SUPPRESS)
  p.add_argument('--hlo', action='store_true', help=argparse.SUPPRESS)
  p.add_argument('--num_processes', type=int, default=1, help=argparse.SUPPRESS)
  p.add_argument('--process_id', type=int, default=0, help=argparse.SUPPRESS)
  p.add_argument('--coordinator_address', default=None, help=argparse.SUPPRESS)
  args = p.parse_args()
  if args.worker:
    worker(args)
    return
  if args.hlo:
    hlo_worker(args)
    return
  from experiments.tables import command_line  # pylint: disable=g-import-not-at-top
  from renerf_jax import report  # pylint: disable=g-import-not-at-top
  env = dict(os.environ, JAX_PLATFORMS='cpu',
             XLA_FLAGS='--xla_force_host_platform_device_count=2')
  res = subprocess.run([sys.executable, '-m', 'benchmarks.bench_multi_host', '--hlo',
                        '--data_dir', args.data_dir], env=env, capture_output=True,
                       text=True, timeout=1800, check=True)
  rows = bytes_table(json.loads(res.stdout.strip().splitlines()[-1]))
  one, two = timed_run(args, 1), timed_run(args, 2)
  result = {'command': command_line('benchmarks.bench_multi_host'),
            'affinity': sorted(os.sched_getaffinity(0)), 'config': args.config,
            'steps': args.steps, 'one_process': one, 'two_processes': two,
            'bytes_per_step': rows}
  os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
  report.write_json(args.out + '.json', result)
  text = (f"Step of {os.path.basename(args.config)} (median of {args.steps}), CPU cores "
          f"{result['affinity']}: one process {one['step_s']:.4f} s, two processes "
          f"{two['step_s']:.4f} s; the all-reduce of {two['allreduce_bytes']} bytes alone "
          f"{two['allreduce_s'] * 1e3:.2f} ms. Losses after the last step: "
          f"{one['last_loss']!r} / {two['last_loss']!r}. Collectives in the compiled "
          f"two-process step ((count, bytes) by op): {two['collectives']}.\n\n" +
          report.markdown_table(rows, [
              ('config', 'config'), ('backbone', 'backbone'), ('batch_rays', 'rays/step'),
              ('params', 'parameters'), ('param_bytes', 'parameter bytes'),
              ('bytes_per_step', 'bytes all-reduced / step'),
              ('what', 'what')]) + '\n')
  report.write_markdown(args.out + '.md', text)
  print(text)


if __name__ == '__main__':
  main()
