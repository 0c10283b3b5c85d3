# Copyright 2024 renerf-jax authors.
"""Writing results: JSON and Markdown tables, atomically; the tables' arithmetic.

Every writer goes through `atomic_open`: data is written to a temporary file in
the destination directory, flushed and fsync'ed, then moved over the target
with `os.replace`. A writer that raises part-way leaves the previous file (if
any) untouched and no temporary file behind.

This module depends on numpy only (no renerf_jax imports); plots and images are
figures.py's.
"""

import contextlib
import json
import math
import numbers
import os
import tempfile
from typing import Any, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

# Default float formats, matched against column keys by substring (first hit).
DEFAULT_FLOAT_FORMATS = (
    ('psnr', '.2f'),
    ('ssim', '.3f'),
    ('lpips', '.3f'),
    ('avg_err', '.3f'),
    ('time', '.1f'),
    ('sec', '.1f'),
)
FALLBACK_FLOAT_FORMAT = '.4f'



def _default_file_mode():
  """Permission bits of a newly created file under the current umask."""
  umask = os.umask(0)
  os.umask(umask)
  return 0o666 & ~umask


@contextlib.contextmanager
def atomic_open(path, mode='w'):
  """Opens a temporary file that atomically replaces `path` on success.

  Args:
    path: str or os.PathLike, destination file; its directory is created.
    mode: 'w' (text, utf-8) or 'wb' (binary).

  Yields:
    A writable file object. If the body raises, the temporary file is deleted,
    `path` keeps its previous content and the exception propagates.
  """
  if mode not in ('w', 'wb'):
    raise ValueError(f'mode must be "w" or "wb", got {mode!r}')
  path = os.fspath(path)
  directory = os.path.dirname(os.path.abspath(path))
  os.makedirs(directory, exist_ok=True)
  fd, tmp = tempfile.mkstemp(
      dir=directory, prefix='.' + os.path.basename(path) + '.', suffix='.tmp')
  try:
    kwargs = {'encoding': 'utf-8', 'newline': ''} if mode == 'w' else {}
    with os.fdopen(fd, mode, **kwargs) as f:
      yield f
      f.flush()
      os.fsync(f.fileno())
    # mkstemp creates 0600 files; give the result ordinary permissions.
    os.chmod(tmp, _default_file_mode())
    os.replace(tmp, path)
  except BaseException:
    with contextlib.suppress(FileNotFoundError):
      os.unlink(tmp)
    raise


def to_jsonable(obj):
  """Recursively converts numpy/JAX values to plain python JSON types.

  Args:
    obj: nested dicts/lists/tuples of python scalars, strings, None,
      numpy scalars/arrays, JAX arrays (anything with `__array__`) or paths.

  Returns:
    The same structure with only dict/list/str/int/float/bool/None. Dict keys
    become strings; tuples become lists; arrays become (nested) lists.

  Raises:
    TypeError: for objects with no JSON representation.
  """
  if obj is None or isinstance(obj, (str, bool)):
    return obj
  if isinstance(obj, (np.generic, np.ndarray)):
    return obj.tolist()
  if isinstance(obj, numbers.Integral):
    return int(obj)
  if isinstance(obj, numbers.Real):
    return float(obj)
  if isinstance(obj, Mapping):
    return {_json_key(k): to_jsonable(v) for k, v in obj.items()}
  if isinstance(obj, (list, tuple)):
    return [to_jsonable(v) for v in obj]
  if isinstance(obj, os.PathLike):
    return os.fspath(obj)
  if hasattr(obj, '__array__'):  # JAX arrays and friends.
    return np.asarray(obj).tolist()
  raise TypeError(f'Object of type {type(obj).__name__} is not JSON '
                  'serialisable')


def _json_key(key):
  """Converts a dict key (str, number, numpy scalar) to a JSON object key."""
  if isinstance(key, str):
    return key
  if isinstance(key, np.generic):
    key = key.item()
  if isinstance(key, (bool, int, float)) or key is None:
    return json.dumps(key)
  return str(key)


def write_json(path, obj, indent=2):
  """Atomically writes `obj` as pretty-printed JSON.

  The object is fully serialised in memory before the file is touched, so a
  serialisation error never affects an existing file. Non-finite floats are
  written as NaN/Infinity (python's json extension, readable by `json.load`).

  Args:
    path: destination file.
    obj: JSON-like structure, may contain numpy/JAX scalars and arrays.
    indent: int, indentation of the output.
  """
  text = json.dumps(to_jsonable(obj), indent=indent) + '\n'
  with atomic_open(path, 'w') as f:
    f.write(text)


def read_json(path):
  """Reads a JSON file written by `write_json`.

  Args:
    path: source file.

  Returns:
    The decoded python object.
  """
  with open(path, 'r', encoding='utf-8') as f:
    return json.load(f)


def write_markdown(path, text):
  """Atomically writes a text/Markdown file (a trailing newline is ensured).

  Args:
    path: destination file.
    text: str, file content.
  """
  if not isinstance(text, str):
    raise TypeError(f'text must be str, got {type(text).__name__}')
  if not text.endswith('\n'):
    text += '\n'
  with atomic_open(path, 'w') as f:
    f.write(text)


def _float_format(key, floatfmt):
  """Format spec for column `key` given a str or a per-key mapping."""
  if isinstance(floatfmt, str):
    return floatfmt
  if floatfmt is not None and key in floatfmt:
    return floatfmt[key]
  lowered = str(key).lower()
  for pattern, fmt in DEFAULT_FLOAT_FORMATS:
    if pattern in lowered:
      return fmt
  return FALLBACK_FLOAT_FORMAT


def _format_cell(value, fmt):
  """Formats one table cell: floats with `fmt`, None as '-', '|' escaped."""
  if value is None:
    return '-'
  if isinstance(value, np.generic):
    value = value.item()
  if isinstance(value, float):
    return format(value, fmt) if math.isfinite(value) else str(value)
  return str(value).replace('|', '\\|').replace('\n', ' ')


def markdown_table(rows: Sequence[Mapping[str, Any]],
                   columns: Optional[Sequence[Union[str, Tuple[str, str]]]] = None,
                   floatfmt: Union[None, str, Mapping[str, str]] = None) -> str:
  """Renders a list of dicts as a GitHub-flavoured Markdown table.

  Args:
    rows: list of dicts, one per table row; missing keys render as '-'.
    columns: list of keys or (key, header) pairs; default: keys of all rows in
      order of first appearance, headers equal to keys.
    floatfmt: None (per-column defaults: PSNR '.2f', SSIM/LPIPS/avg_err '.3f',
      others '.4f'), a format spec for all float columns, or a dict key -> spec
      (keys not in it fall back to the defaults).

  Returns:
    str, the table, lines joined by '\\n' with a trailing newline.
  """
  if columns is None:
    columns = list(dict.fromkeys(k for row in rows for k in row))
  cols = [c if isinstance(c, tuple) else (c, str(c)) for c in columns]
  lines = [
      '| ' + ' | '.join(header for _, header in cols) + ' |',
      '|' + '|'.join('---' for _ in cols) + '|',
  ]
  for row in rows:
    cells = [_format_cell(row.get(k), _float_format(k, floatfmt)) for k, _ in cols]
    lines.append('| ' + ' | '.join(cells) + ' |')
  return '\n'.join(lines) + '\n'


def _is_number(value):
  """True for real numbers (python or numpy) that are not bools."""
  return isinstance(value, (numbers.Real, np.number)) and not isinstance(
      value, (bool, np.bool_))


def per_image_table(per_image: Sequence[Mapping[str, Any]],
                    name_key='name',
                    mean_name='mean') -> list:
  """Per-image metric rows followed by a row of their means.

  Args:
    per_image: list of dicts, each with `name_key` and numeric metrics, e.g.
      {'name': 'r_0', 'psnr': 20.1, 'ssim': 0.71, 'lpips_alex': 0.2}.
    name_key: key of the image name.
    mean_name: name of the appended mean row.

  Returns:
    list of dicts: copies of the input rows (numpy scalars as python floats)
    plus {name_key: mean_name, metric: arithmetic mean over the images that
    have it} for every numeric metric. Note that the 'avg_err' column, if
    present, is averaged like the others (not recomputed from mean metrics).
  """
  rows = [{k: (float(v) if _is_number(v) and not isinstance(v, int) else v)
           for k, v in r.items()} for r in per_image]
  keys = list(dict.fromkeys(
      k for r in rows for k, v in r.items() if k != name_key and _is_number(v)))
  mean_row = {name_key: mean_name}
  for k in keys:
    vals = [float(r[k]) for r in rows if k in r and _is_number(r[k])]
    mean_row[k] = float(np.mean(vals))
  return rows + [mean_row]
