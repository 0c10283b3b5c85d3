"""Shared test fixtures: paths of the real scenes in ../shared/data (read-only).

The suite compiles the same small steps in many tests and in the subprocesses of the CLI,
notebook and crash tests: they share one persistent compilation cache in a fresh
temporary directory (never the user's ~/.cache), so no test depends on an earlier run.
"""
import atexit
import os
import shutil
import tempfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / 'shared' / 'data'
LLFF_DIR = DATA / 'nerf_llff_data'
BLENDER_DIR = DATA / 'nerf_synthetic_200'


@pytest.fixture(scope='session')
def fern_dir():
  assert (LLFF_DIR / 'fern' / 'poses_bounds.npy').is_file(), f'missing {LLFF_DIR}/fern'
  return str(LLFF_DIR)


@pytest.fixture(scope='session')
def blender_dir():
  assert (BLENDER_DIR / 'lego' / 'transforms_train.json').is_file()
  return str(BLENDER_DIR)


def tree_files(directory, digest=False):
  """{path relative to directory: file bytes (or their SHA-256 with digest=True)}."""
  import hashlib  # pylint: disable=g-import-not-at-top
  out = {}
  for root, _, files in os.walk(directory):
    for f in files:
      path = os.path.join(root, f)
      with open(path, 'rb') as fh:
        data = fh.read()
      out[os.path.relpath(path, directory)] = (hashlib.sha256(data).hexdigest() if digest
                                               else data)
  return out


def tiny_config(**kw):
  """A small, fast Config on the embedded procedural scene."""
  from renerf_jax.configs import Config  # pylint: disable=g-import-not-at-top
  base = dict(dataset_loader='procedural', procedural_size=(32, 40), max_steps=20,
              batch_size=64, num_samples=8, net_depth=2, net_width=32, skip_layer=1,
              net_width_viewdirs=16, max_deg_point=4, deg_view=2, lr_delay_steps=5,
              depth_tv_maxstep=5, anneal_nearfar_steps=5, n_random_poses=50,
              batch_size_random=64, patch_size=4, print_every=10, eval_every=10,
              checkpoint_every=10, render_chunk=512, pseudo_until_frac=0.5,
              lpips_nets=('alex',), mask_signal='laplace')  # masks in tests: the Laplace path
  if kw.get('backbone') == 'gaussians':  # the NeRF's sizes: settings the Gaussians refuse
    from renerf_jax.config_fields import ignored_by  # pylint: disable=g-import-not-at-top
    base = {k: v for k, v in base.items() if k not in ignored_by(Config, 'gaussians')}
  base.update(kw)
  return Config(**base)


os.environ.setdefault('TF_CPP_MIN_LOG_LEVEL', '2')
_CACHE_DIR = tempfile.mkdtemp(prefix='renerf-test-xla-')
os.environ['RENERF_JAX_CACHE_DIR'] = _CACHE_DIR
atexit.register(shutil.rmtree, _CACHE_DIR, True)  # whichever process imported this


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config):
  """Turns on the shared compilation cache, and xdist's worker restarts off.

  A worker that dies (a segfault in compiled code, or pytest-timeout ending a stuck
  test) then ends the run with its crashed test reported and the summary line printed;
  a replacement worker would re-run compiled code on the same CPU and once hung the
  suite with no summary (issue 38). `--max-worker-restart N` on the command line still
  wins.
  """
  if getattr(config.option, 'maxworkerrestart', 'absent') is None:
    config.option.maxworkerrestart = '0'
  from renerf_jax import jit_cache  # pylint: disable=g-import-not-at-top
  jit_cache.enable_compilation_cache()



@pytest.fixture(autouse=True, scope='module')
def _release_compiled_after_module():
  """Frees each test file's compiled executables when the file ends (jit_cache.
  release_compiled).

  Every executable XLA's CPU backend keeps holds memory mappings of its own. One xdist
  worker runs about half the files, and without this its count climbed past 62,000 of
  Linux's 65,530 per process by the last files (measured per file with
  jit_cache.mapped_regions()); the next compile then died inside XLA (a segfault while
  serialising the executable for the persistent cache, in test_viewer's fixture). Later
  files recompile what they use, mostly as persistent-cache hits.
  """
  yield
  from renerf_jax import jit_cache  # pylint: disable=g-import-not-at-top
  jit_cache.release_compiled()
