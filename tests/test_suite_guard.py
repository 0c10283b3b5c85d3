"""The suite's own guard (issue 38): a test that crashes its worker or hangs in compiled
code fails the README's test command fast, with its summary line, instead of hanging it.

A scratch suite with a segfaulting test and a test stuck in C (outside Python, where a
signal handler never runs) is run with the repository's pytest.ini and conftest hook, as
the README's command runs the real suite (two xdist workers, one file each).
"""
import os
import re
import subprocess
import sys
import textwrap
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_a_crashed_or_stuck_worker_ends_the_run_with_a_summary(tmp_path):
  tests = tmp_path / 'tests'
  tests.mkdir()
  (tests / 'conftest.py').write_text(textwrap.dedent(f'''
      import importlib.util
      spec = importlib.util.spec_from_file_location(
          'repo_conftest', {str(REPO / 'tests' / 'conftest.py')!r})
      repo_conftest = importlib.util.module_from_spec(spec)
      spec.loader.exec_module(repo_conftest)
      pytest_configure = repo_conftest.pytest_configure  # the repository's hook, as it is
      '''))
  (tests / 'test_crash.py').write_text(textwrap.dedent('''
      import ctypes
      def test_before():
        pass
      def test_segfault():
        ctypes.string_at(0)  # SIGSEGV in C, as an XLA fault would be
      def test_after():
        pass
      '''))
  (tests / 'test_stuck.py').write_text(textwrap.dedent('''
      import ctypes
      def test_stuck_in_c():
        ctypes.CDLL(None).pause()  # never returns, never runs Python code
      def test_next():
        pass
      '''))
  start = time.monotonic()
  proc = subprocess.run(
      [sys.executable, '-m', 'pytest', '-n', '2', '--dist', 'loadfile',
       '-c', str(REPO / 'pytest.ini'), '--rootdir', str(tmp_path), '-o', 'timeout=15',
       '-p', 'no:cacheprovider', 'tests'],
      cwd=tmp_path, capture_output=True, text=True, timeout=240,
      env=dict(os.environ, PYTHONPATH=str(REPO)))
  elapsed = time.monotonic() - start
  out = proc.stdout + proc.stderr
  assert proc.returncode == 1, out
  assert "crashed while running 'tests/test_crash.py::test_segfault'" in out, out
  assert "crashed while running 'tests/test_stuck.py::test_stuck_in_c'" in out, out
  # Default verbosity: xdist would say 'replacing crashed worker' here if it restarted.
  assert 'worker restarting disabled' in out, out
  assert 'replacing crashed worker' not in out, out
  assert re.search(r'=+ 2 failed, 1 passed in [0-9.]+s', out), out  # The summary line.
  assert elapsed < 200, elapsed  # The 15 s limit ended the stuck test: no hang.
