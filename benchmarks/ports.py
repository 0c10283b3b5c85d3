"""Loopback ports for the local servers of benchmarks and tests (the viewer, the
coordinator of a multi-process run)."""
import socket


def free_port():
  """A TCP port on 127.0.0.1 that is free now."""
  with socket.socket() as s:
    s.bind(('127.0.0.1', 0))
    return s.getsockname()[1]
