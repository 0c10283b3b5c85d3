"""Shared pieces of the command-line entry points (train.py, eval.py): flags, the run
directory, one-line errors, joining a multi-process run (renerf_jax.distributed)."""
import argparse
import dataclasses
import os
import sys
import traceback
from typing import Optional, Sequence

from renerf_jax import distributed, jit_cache, process_supervisor, report, run_config, rundir
from renerf_jax.configs import config_differences, config_to_gin, fields_where, load_config
from renerf_jax.errors import USER_ERRORS, RunDirError


def parse_args(argv: Optional[Sequence[str]] = None, description: str = ''):
  """Parses --gin_configs / --gin_bindings (both repeatable) and other flags.

  Args:
    argv: command-line arguments without the program name (default sys.argv[1:]).
    description: help text.

  Returns:
    argparse.Namespace with gin_configs, gin_bindings, run_dir and the multi-process
    flags (coordinator_address, num_processes, process_id, distributed_timeout).
  """
  parser = argparse.ArgumentParser(description=description)
  parser.add_argument('--gin_configs', action='append', default=[],
                      help='gin config file (repeatable)')
  parser.add_argument('--gin_bindings', action='append', default=[],
                      help="gin binding, e.g. \"Config.max_steps=100\" (repeatable)")
  parser.add_argument('--run_dir', default=None,
                      help='run directory (default runs/<config name>)')
  group = parser.add_argument_group(
      'several processes (docs/multi_host.md); default: $JAX_COORDINATOR_ADDRESS, '
      '$JAX_NUM_PROCESSES, $JAX_PROCESS_ID, or what SLURM / Open MPI say')
  group.add_argument('--coordinator_address', default=None,
                     help="host:port of process 0 (it hosts the coordinator)")
  group.add_argument('--num_processes', type=int, default=None,
                     help='processes in the run (one per machine, or per GPU)')
  group.add_argument('--process_id', type=int, default=None,
                     help='index of this process, 0 .. num_processes - 1')
  group.add_argument('--distributed_timeout', type=int, default=300,
                     help='seconds to wait for every process to join')
  return parser.parse_args(argv)


def default_run_dir(gin_configs: Sequence[str]) -> str:
  """runs/<stems of the gin files joined by '+'>, e.g. runs/llff3_cpu+renerf."""
  stems = [os.path.splitext(os.path.basename(p))[0] for p in gin_configs]
  return os.path.join('runs', '+'.join(stems) if stems else 'default')


def exit_on_error(fn):
  """Decorator for CLI mains: known user errors become one line on stderr and exit 2.

  In a multi-process run a process ends at once on any error (os._exit, without
  jax.distributed's shutdown barrier, which would wait for the others): a failed
  collective (another process died) is one line and exit 2, other errors print their
  traceback and exit 1.
  """
  def wrapped(*args, **kwargs):
    try:
      return fn(*args, **kwargs)
    except USER_ERRORS as e:
      if distributed.is_multi():
        process_supervisor.fail_fast(f'error: {e}', 2)
      print(f'error: {e}', file=sys.stderr)
      sys.exit(2)
    except Exception as e:  # pylint: disable=broad-except
      if not distributed.is_multi():
        raise
      if process_supervisor.is_peer_failure(e):
        process_supervisor.fail_fast(distributed.peer_failure_line(process_supervisor.first_line(e)), 2)
      traceback.print_exc()
      process_supervisor.fail_fast(f'error: {distributed.describe()} failed: '
                            f'{process_supervisor.first_line(e)}', 1)
    except KeyboardInterrupt:
      if not distributed.is_multi():
        raise
      process_supervisor.fail_fast(f'error: {distributed.describe()} interrupted', 130)
  return wrapped


def join_run(args):
  """Joins a multi-process run when the flags or the environment describe one
  (distributed.start); nothing for a single process."""
  cluster = distributed.cluster_from(args.coordinator_address, args.num_processes,
                                     args.process_id, os.environ)
  if cluster is not None:
    distributed.start(cluster, args.distributed_timeout)


def setup(argv, description):
  """Parses flags, joins a multi-process run if there is one, parses gin, turns on the
  compilation cache; returns (config, run_dir)."""
  args = parse_args(argv, description)
  join_run(args)
  jit_cache.enable_compilation_cache()
  config = load_config(args.gin_configs, args.gin_bindings)
  return config, args.run_dir or default_run_dir(args.gin_configs)


def check_run_dir(config, run_dir, create):
  """Guards a run directory against being reused with a different configuration.

  The first call writes run_dir/config.json (and the operative gin config); a later call
  with a configuration differing in a field that is not 'resumable' (its category in
  configs.AFFECTS) raises RunDirError, so earlier results are never mixed with or
  overwritten by a different experiment. Only process 0 of a multi-process run writes.
  """
  path = rundir.config_json_path(run_dir)
  write = create and distributed.is_writer()
  current = report.to_jsonable(dataclasses.asdict(config))
  if os.path.isfile(path):
    # A damaged config.json or config.gin is one line (run_config); a field added to
    # Config after the run was made counts as its default value.
    saved = dict(report.to_jsonable(dataclasses.asdict(type(config)())),
                 **run_config.read_saved_config(run_dir))
    if os.path.isfile(rundir.config_gin_path(run_dir)):
      run_config.load_run_config(run_dir)
    diff = config_differences(config, saved, fields_where('resumable'))
    if diff:
      k = diff[0]
      raise RunDirError(
          f'{run_dir} holds a run made with a different configuration ({k}: '
          f'{saved.get(k)!r} there, {current.get(k)!r} now{", ..." if len(diff) > 1 else ""})'
          f'; pass --run_dir to start a new run')
    if write and saved != current:
      report.write_json(path, current)
  elif write:
    os.makedirs(run_dir, exist_ok=True)
    # config.json last: it marks the directory as made (a run killed in between would
    # otherwise never get its config.gin).
    report.write_markdown(rundir.config_gin_path(run_dir), config_to_gin(config))
    report.write_json(path, current)
  elif not create:
    raise RunDirError(f'no finished run in {run_dir} (config.json missing); train first '
                      f'or pass --run_dir')
