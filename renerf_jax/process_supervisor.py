"""A process of a multi-process run as its own supervisor: the forked parent that forwards
the child's stderr (hiding JAX's native log lines, keeping its fatal reason), passes on
signals and ends like the child, and the one-line errors of a run that lost a process.

Used by distributed.start and cli; os, signal and re, and jax for its error type only.
"""
import os
import re
import signal
import sys
from typing import Callable, Optional

import jax


_PEER_FAILURE = re.compile(r'gloo|connection (reset|closed|refused)|broken pipe|'
                           r'coordination service|heartbeat|socket closed',
                           re.IGNORECASE)


def first_line(exc) -> str:
  """The first non-empty line of an exception's message, at most 200 characters."""
  lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
  text = lines[0] if lines else type(exc).__name__
  return text[:200] + ('...' if len(text) > 200 else '')


def is_peer_failure(exc) -> bool:
  """Whether an exception is a collective or coordination failure (another process
  died or cannot be reached), not an error of this process."""
  # XLA raises a failed gloo collective as a ValueError ('UNKNOWN: Gloo AllGather
  # failed: ... Connection reset by peer'), others as JaxRuntimeError.
  return isinstance(exc, (jax.errors.JaxRuntimeError, ValueError, RuntimeError)) and (
      bool(_PEER_FAILURE.search(str(exc))))


def fail_fast(line: str, code: int):
  """Prints `line` to stderr and ends this process now, skipping jax.distributed's
  shutdown barrier (which would wait for, or abort over, the other processes)."""
  try:
    sys.stdout.flush()
  except (OSError, ValueError):
    pass
  os.write(2, ('\n' + line + '\n').encode())  # On its own line after a progress bar.
  os._exit(code)  # pylint: disable=protected-access


# ------------------------------------------------------------------------ supervisor

# JAX's distributed client stops the process from a C++ thread (LOG(FATAL), a stack
# trace, SIGABRT) when the coordinator dies or heartbeats are missed; no Python code can
# catch that. The parent process forwards the child's stderr and turns it into one line.
_NATIVE_LOG = re.compile(rb'^[IWEF]\d{4} \d\d:\d\d:\d\d\.\d+\s+\d+ [^\]]+\] ')
_FATAL = re.compile(rb'^F\d{4} .*?\] (.*)$')


class StderrFilter:
  """Forwards a child's stderr, holding back native (C++) error logs.

  Lines in the native log format at levels E and F, and everything after an F line
  (its stack trace), are held; lines starting with 'error: ' are counted. `held` is
  shown by the supervisor only when the child fails for another reason.
  """

  def __init__(self, write: Callable[[bytes], None]):
    self.write, self.buf, self.held = write, b'', []
    self.fatal: Optional[str] = None
    self.error_lines = 0

  def feed(self, data: bytes):
    """Takes a chunk of the child's stderr; forwards what can be forwarded."""
    self.buf += data
    *lines, self.buf = self.buf.split(b'\n')
    for line in lines:
      self._line(line + b'\n')
    if b'\r' in self.buf and not self.fatal:  # Progress bars: forward as they come.
      self.write(self.buf)
      self.buf = b''

  def close(self):
    if self.buf:
      self._line(self.buf)
      self.buf = b''

  def _line(self, line: bytes):
    if line.lstrip(b'\r').startswith(b'error: '):
      self.error_lines += 1
      if self.error_lines == 1:
        self.write(line)
      return
    if self.fatal is not None:
      self.held.append(line)
      return
    m = _FATAL.match(line)
    if m:
      self.fatal = m.group(1).decode(errors='replace')
      self.held.append(line)
    elif _NATIVE_LOG.match(line) and line[:1] in (b'E', b'F'):
      self.held.append(line)
    else:
      self.write(line)


def fatal_reason(message: str) -> str:
  """A short reason out of JAX's fatal message (its absl::Status, if named)."""
  m = re.search(r'absl::Status: ([A-Z_]+: [^.\n]*)', message)
  return (m.group(1) if m else message)[:160]


def supervise(failure_line: Callable[[str], str]):
  """Forks: the child returns and runs the program, its stderr through a pipe; the
  parent forwards it (StderrFilter), passes on SIGINT / SIGTERM / SIGHUP, and ends like
  the child, with one error line where JAX stopped the child over a lost process.

  Args:
    failure_line: reason -> the one error line naming the run (distributed's
      peer_failure_line for this process's cluster).
  """
  r, w = os.pipe()
  sys.stdout.flush()
  sys.stderr.flush()
  pid = os.fork()
  if pid == 0:
    os.close(r)
    os.dup2(w, 2)
    os.close(w)
    _die_with_parent()
    return
  os.close(w)
  for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
    signal.signal(sig, lambda s, _, pid=pid: os.kill(pid, s))
  filt = StderrFilter(lambda b: os.write(2, b))
  while True:
    try:
      data = os.read(r, 65536)
    except InterruptedError:
      continue
    if not data:
      break
    filt.feed(data)
  filt.close()
  while True:
    try:
      _, status = os.waitpid(pid, 0)
      break
    except InterruptedError:
      continue
  if filt.fatal is not None:
    if not filt.error_lines:
      os.write(2, (failure_line('the JAX distributed service stopped it: ' +
                                fatal_reason(filt.fatal)) + '\n').encode())
    os._exit(2)  # pylint: disable=protected-access
  if os.WIFEXITED(status):
    if os.WEXITSTATUS(status) and not filt.error_lines:
      os.write(2, b''.join(filt.held))
    os._exit(os.WEXITSTATUS(status))  # pylint: disable=protected-access
  os.write(2, b''.join(filt.held))
  sig = os.WTERMSIG(status)
  if sig not in (signal.SIGKILL, signal.SIGSTOP):
    signal.signal(sig, signal.SIG_DFL)
  os.kill(os.getpid(), sig)  # End as the child ended (e.g. killed by SIGKILL).
  os._exit(128 + sig)  # pylint: disable=protected-access


def _die_with_parent():
  """Linux: the child gets SIGKILL when the supervising parent dies."""
  try:
    import ctypes  # pylint: disable=g-import-not-at-top
    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
  except (OSError, AttributeError):
    return
  if os.getppid() == 1:
    os._exit(1)  # pylint: disable=protected-access
