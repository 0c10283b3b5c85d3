"""XLA:CPU settings the project needs on every x86 CPU: YNNPACK fusions off by default.

jaxlib 0.10.2 hands dot, reduce and transpose fusions to YNNPACK (`__ynn_fusion`),
whose kernels are picked at run time from the CPU's own instruction set. On CPUs
without AVX-512 some of them read outside their buffers: the project's suite crashed
twice on a 2-core AMD EPYC without AVX-512 (issue 38: a transpose inside the old dense
Hessian reference, found under valgrind, experiments/results/xla_cpu_crash; and a
worker that died with a segfault in tests/test_model.py, issue 49's CI run), and
upstream reports the same family of faults (jax-ml/jax#39257, #40412, fixed in
XNNPACK after jaxlib 0.10.2). The fault happens on a worker thread, so the Python
stack names whatever ran at that moment, not the graph at fault. Without the fusions
XLA compiles the same operations itself; the results agree to float tolerance
(tests/test_xla_cpu.py) and the cost in speed is in benchmarks/results/ynn_fusions.md.

The flag must be in XLA_FLAGS before the CPU backend starts (the first computation),
which importing renerf_jax first guarantees for the project's own entry points (train.py,
eval.py, the experiments, the tests). A user who wants the fusions back sets
XLA_FLAGS=--xla_cpu_experimental_ynn_fusion_type=individual_dot,reduce (jaxlib 0.10.2's
default) or any other value: a value already in XLA_FLAGS is never overridden.
"""
import os

FLAG = '--xla_cpu_experimental_ynn_fusion_type'


def avoid_ynn_fusions(environ=None) -> bool:
  """Adds `FLAG=` (no YNNPACK fusions) to XLA_FLAGS unless XLA_FLAGS sets FLAG already.

  Args:
    environ: the environment to edit (default os.environ; child processes inherit it).

  Returns:
    True when the flag was added, False when XLA_FLAGS already chose a value.
  """
  environ = os.environ if environ is None else environ
  flags = environ.get('XLA_FLAGS', '')
  if any(f == FLAG or f.startswith(FLAG + '=') for f in flags.split()):
    return False
  environ['XLA_FLAGS'] = f'{flags} {FLAG}='.strip()
  return True
