"""One run over several processes (hosts) with jax.distributed.

A run launched as N processes (flags, environment, or SLURM / Open MPI detected by JAX)
calls `start` before anything else touches JAX; then:

  * training (NeRF): one global mesh over every process's devices (training.py's
    shardings use jax.devices(), which is then global); the ray batch is drawn inside
    the jitted step from replicated pools with the step's key, so the global batch and
    the random stream do not depend on the process count, and it is sharded over all
    devices; parameters are replicated and XLA all-reduces their gradients;
  * training (Gaussians): one image a step, as 3DGS trains: every process runs the same
    step on the same image (no gradient traffic, identical results);
  * rendering (pseudo-views, masks, evaluation, the cheap test PSNR): `map_shares` gives
    each process a share of the chunks (NeRF) or views (Gaussians) and gathers the
    results to every process; the Laplace Hessian is summed over the processes' rays
    with `sum_over_processes`;
  * files: only process 0 writes (`is_writer`; atomically, as with one process); every
    process reads the run directory, which must be on a file system all hosts share.

A process that dies stops the others with one line: a failed collective is caught in
cli.exit_on_error (`is_peer_failure`), and JAX's own fatal stop (the coordinator gone,
missed heartbeats) is turned into one line by the supervising parent (`supervise`).
With one process every function here is the identity or a plain loop.
"""
import dataclasses
import re
import threading
from typing import Callable, List, Mapping, Optional

import jax
import numpy as np

from renerf_jax.errors import DistributedError
from renerf_jax.process_supervisor import fail_fast, first_line, supervise

# Environment variables read when the flags are not given (the coordinator address is
# also JAX's own variable).
ENV_ADDRESS, ENV_COUNT, ENV_INDEX = ('JAX_COORDINATOR_ADDRESS', 'JAX_NUM_PROCESSES',
                                     'JAX_PROCESS_ID')
# Schedulers whose processes JAX finds by itself (jax._src.clusters): (name, count var,
# index var).
AUTO_CLUSTERS = (('SLURM', 'SLURM_NTASKS', 'SLURM_PROCID'),
                 ('Open MPI', 'OMPI_COMM_WORLD_SIZE', 'OMPI_COMM_WORLD_RANK'))


@dataclasses.dataclass(frozen=True)
class Cluster:
  """Where this process stands in a multi-process run.

  Attributes:
    num_processes: N >= 2. process_id: 0 <= i < N.
    coordinator_address: 'host:port' of process 0's coordinator; None lets JAX find it
      (SLURM, Open MPI).
    source: where the values came from ('flags', 'environment', 'SLURM', 'Open MPI').
  """
  num_processes: int
  process_id: int
  coordinator_address: Optional[str]
  source: str


def _int(value, name):
  try:
    return int(value)
  except (TypeError, ValueError):
    raise DistributedError(f'{name}={value!r} is not an integer') from None


def cluster_from(coordinator_address: Optional[str], num_processes: Optional[int],
                 process_id: Optional[int], environ: Mapping[str, str]) -> Optional[Cluster]:
  """The Cluster of this process, or None for a single-process run (pure).

  Flags win over the environment (JAX_COORDINATOR_ADDRESS, JAX_NUM_PROCESSES,
  JAX_PROCESS_ID); without either, a SLURM step or Open MPI job of more than one task is
  detected (JAX then finds the coordinator itself).

  Args:
    coordinator_address, num_processes, process_id: the flags (None: not given).
    environ: the environment.

  Returns:
    Cluster, or None when the run has one process.

  Raises:
    DistributedError: values that cannot describe a run (one line).
  """
  source = 'flags'
  if num_processes is None and process_id is None and coordinator_address is None:
    source = 'environment'
    coordinator_address = environ.get(ENV_ADDRESS)
    num_processes = environ.get(ENV_COUNT)
    process_id = environ.get(ENV_INDEX)
  if num_processes is None and process_id is None:
    for name, count_var, index_var in AUTO_CLUSTERS:
      if count_var in environ and index_var in environ:
        count = _int(environ[count_var], count_var)
        if count > 1:
          return Cluster(count, _int(environ[index_var], index_var), None, name)
    if coordinator_address is None:
      return None
  if num_processes is None or process_id is None:
    raise DistributedError('a multi-process run needs the process count and this '
                           'process\'s index: pass --num_processes and --process_id (or '
                           f'set {ENV_COUNT} and {ENV_INDEX})')
  count, index = _int(num_processes, 'num_processes'), _int(process_id, 'process_id')
  if count < 1:
    raise DistributedError(f'num_processes={count} must be at least 1')
  if not 0 <= index < count:
    raise DistributedError(f'process_id={index} is not in 0..{count - 1} '
                           f'(num_processes={count})')
  if count == 1:
    return None
  if not coordinator_address:
    raise DistributedError('a multi-process run needs --coordinator_address host:port '
                           f'(process 0\'s address; or set {ENV_ADDRESS})')
  m = re.fullmatch(r'(\[[^\]]+\]|[^:\s]+):(\d+)', coordinator_address)
  if not m or not 0 < int(m.group(2)) < 65536:
    raise DistributedError(f'coordinator_address={coordinator_address!r} is not '
                           'host:port with a port in 1..65535')
  return Cluster(count, index, coordinator_address, source)


# ------------------------------------------------------------------------ start-up


_CLUSTER: Optional[Cluster] = None


def describe(cluster: Optional[Cluster] = None) -> str:
  """'process i of N' of this process (or of `cluster`)."""
  c = cluster or _CLUSTER
  if c is None:
    return f'process {jax.process_index()} of {jax.process_count()}'
  return f'process {c.process_id} of {c.num_processes}'


def start(cluster: Cluster, timeout_s: int = 300, supervised: bool = True):
  """Joins the run: supervise (fork), then jax.distributed.initialize with gloo CPU
  collectives. Call before any JAX computation.

  Args:
    cluster: this process's Cluster.
    timeout_s: seconds to wait for every process to join; after that, one error line
      and exit 2 (JAX's own timeout would abort with a stack trace).
    supervised: fork the supervising parent (see `supervise`).
  """
  global _CLUSTER
  if supervised:
    supervise(lambda reason: peer_failure_line(reason, cluster))
  _CLUSTER = cluster
  jax.config.update('jax_cpu_collectives_implementation', 'gloo')
  where = cluster.coordinator_address or f'the coordinator {cluster.source} names'

  def give_up():
    fail_fast(f'error: {describe(cluster)}: not every process joined within {timeout_s} '
              f's through {where}; start all {cluster.num_processes} processes with the '
              'same coordinator address (process 0 hosts it), or raise '
              '--distributed_timeout', 2)
  timer = threading.Timer(timeout_s, give_up)
  timer.daemon = True
  timer.start()
  try:
    jax.distributed.initialize(cluster.coordinator_address, cluster.num_processes,
                               cluster.process_id, initialization_timeout=timeout_s + 60)
  except Exception as e:  # pylint: disable=broad-except
    timer.cancel()
    raise DistributedError(f'{describe(cluster)}: jax.distributed.initialize failed: '
                           f'{first_line(e)}') from None
  timer.cancel()


def is_multi() -> bool:
  """Whether this process joined a multi-process run through `start`."""
  return _CLUSTER is not None


def is_writer() -> bool:
  """Whether this process writes the run's files (process 0)."""
  return jax.process_index() == 0


def sync(name: str):
  """A barrier of all processes (nothing with one process)."""
  if jax.process_count() > 1:
    from jax.experimental import multihost_utils  # pylint: disable=g-import-not-at-top
    multihost_utils.sync_global_devices(name)


# ------------------------------------------------------------------------ arrays


def replicate(tree, sharding):
  """Global arrays of `tree` placed with `sharding` when there are several processes
  (jit over a multi-process mesh takes global arrays only); `tree` itself otherwise."""
  if jax.process_count() == 1:
    return tree
  return jax.device_put(tree, sharding)


def local(tree):
  """Host copies of a (replicated) pytree when there are several processes, so that a
  process can compute on its own (a global array would make every jit a collective);
  `tree` itself otherwise."""
  if jax.process_count() == 1:
    return tree
  return jax.tree_util.tree_map(
      lambda x: np.asarray(x) if isinstance(x, jax.Array) else x, tree)


def share(n: int, index: Optional[int] = None, count: Optional[int] = None) -> List[int]:
  """The items of 0..n-1 that process `index` of `count` computes: k = index mod count."""
  index = jax.process_index() if index is None else index
  count = jax.process_count() if count is None else count
  return list(range(index, n, count))


def map_shares(fn: Callable, n: int) -> list:
  """[fn(k) for k in range(n)], each k computed by one process, the results gathered.

  fn(k) returns a pytree of arrays whose shapes do not depend on k. Process p computes
  k = p, p + P, ...; the results travel in one all-gather. A process with no item
  computes fn(0) once to have the shapes (only when n < P).

  Args:
    fn: k -> pytree of host arrays. n: number of items.

  Returns:
    The n results in order (host numpy arrays), on every process.
  """
  count = jax.process_count()
  if count == 1:
    return [fn(k) for k in range(n)]
  from jax.experimental import multihost_utils  # pylint: disable=g-import-not-at-top
  if n == 0:
    return []
  mine = [jax.tree_util.tree_map(np.asarray, fn(k)) for k in share(n)]
  per = -(-n // count)
  pad = mine[0] if mine else jax.tree_util.tree_map(np.asarray, fn(0))
  mine += [pad] * (per - len(mine))
  stacked = jax.tree_util.tree_map(lambda *xs: np.stack(xs), *mine)
  gathered = multihost_utils.process_allgather(stacked)  # [P, per, ...]
  return [jax.tree_util.tree_map(lambda g, k=k: np.asarray(g[k % count, k // count]),
                                 gathered) for k in range(n)]


def sum_over_processes(x):
  """sum_p x_p of a host or device array, in process order, on every process (`x`
  itself with one process)."""
  if jax.process_count() == 1:
    return x
  from jax.experimental import multihost_utils  # pylint: disable=g-import-not-at-top
  parts = multihost_utils.process_allgather(np.asarray(x))
  total = parts[0].copy()
  for part in parts[1:]:
    total += part
  return total


def peer_failure_line(reason: str, cluster: Optional[Cluster] = None) -> str:
  """The one line a process prints when the run lost another process."""
  return (f'error: {describe(cluster)} stopped: another process of the run died or cannot '
          f'be reached ({reason}); process 0 has checkpointed every finished step: rerun '
          'the same command on every machine to resume')
