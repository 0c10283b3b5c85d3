"""Where gin files are found: bare --gin_configs names and `include` statements.

A name not found as given is looked up in the repository's gin_configs/; an `include`
searches the including file's folder, then gin_configs/ (configs.load_config sets it up).
"""
import logging
import os
from typing import Sequence

import gin

from renerf_jax.errors import ConfigError


class _DropGinPathProbe(logging.Filter):
  """gin probes `include` paths as Python packages first and logs a spurious ERROR."""

  def filter(self, record):
    return not record.getMessage().startswith('Path not found:')


logging.getLogger().addFilter(_DropGinPathProbe())


# The repository's gin_configs/ folder: bare --gin_configs names (llff3.gin, llff3) are
# looked up there, and `include` statements search it after the including file's folder.
GIN_CONFIGS_DIR = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                                '..', 'gin_configs'))


def resolve_gin_config(path: str) -> str:
  """The gin file that --gin_configs=path names.

  path as given (relative to the working directory) if it is a file, else path in
  GIN_CONFIGS_DIR; either with '.gin' appended when path lacks it.

  Raises:
    ConfigError: one line naming path and where it was looked for.
  """
  names = [path] if path.endswith('.gin') else [path, path + '.gin']
  candidates = names + ([os.path.join(GIN_CONFIGS_DIR, n) for n in names]
                        if not os.path.isabs(path) else [])
  for candidate in candidates:
    if os.path.isfile(candidate):
      return candidate
  where = f'{os.getcwd()}' + ('' if os.path.isabs(path) else f' and {GIN_CONFIGS_DIR}')
  raise ConfigError(f'gin config file not found: {path} (looked in {where})')


def set_gin_search_path(folders: Sequence[str]):
  """gin's `include` searches the working directory, then `folders` in this order (and
  nothing an earlier load_config added)."""
  folders = list(dict.fromkeys(folders))
  prefixes = getattr(gin.config, '_LOCATION_PREFIXES', None)
  if isinstance(prefixes, list):
    prefixes[:] = [''] + folders
  else:  # A gin without the list: add what is missing.
    for folder in folders:
      gin.add_config_file_search_path(folder)
