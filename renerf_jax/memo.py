"""In-process memoisation of expensive passes, keyed on a digest of what they depend on.

The variants of an ablation table share one baseline per seed; they run in one process
and would otherwise repeat the same Hessian pass (uncertainty.cached_vertex_sigma) or
render the same pseudo-view (pseudo_views.render_pseudo_views). A cached result is the
result of the same computation on the same inputs; callers still count the seconds it
took when it was computed, so sharing never makes a variant look cheaper.
"""
import collections
import dataclasses
import hashlib

import jax
import numpy as np


def digest(*trees) -> str:
  """SHA-1 over the dtypes, shapes and bytes of every leaf (strings hashed as text)."""
  h = hashlib.sha1()
  for leaf in jax.tree_util.tree_leaves(trees):
    if isinstance(leaf, str):
      h.update(repr(('str', leaf)).encode())
      continue
    a = np.ascontiguousarray(np.asarray(leaf))
    h.update(repr((a.dtype.str, a.shape)).encode())
    h.update(a.tobytes())
  return h.hexdigest()


def config_key(config, irrelevant_fields) -> str:
  """The config's repr with `irrelevant_fields` set to their defaults."""
  defaults = type(config)()
  base = dataclasses.replace(config, **{k: getattr(defaults, k) for k in irrelevant_fields})
  return repr(base)


def nbytes(tree) -> int:
  return sum(np.asarray(x).nbytes for x in jax.tree_util.tree_leaves(tree))


class LruCache:
  """A dict keeping the most recently used entries within an item and a byte budget."""

  def __init__(self, max_items=None, max_bytes=None):
    self.max_items, self.max_bytes = max_items, max_bytes
    self._data = collections.OrderedDict()
    self._bytes = 0

  def __len__(self):
    return len(self._data)

  def __contains__(self, key):
    return key in self._data

  def get(self, key):
    """The entry (marked as just used), or None."""
    if key not in self._data:
      return None
    self._data.move_to_end(key)
    return self._data[key][0]

  def put(self, key, value):
    """Stores value; evicts the least recently used entries beyond the budgets.

    An entry larger than max_bytes on its own is not stored.
    """
    size = nbytes(value)
    if self.max_bytes is not None and size > self.max_bytes:
      return
    if key in self._data:
      self._bytes -= self._data.pop(key)[1]
    self._data[key] = (value, size)
    self._bytes += size
    while ((self.max_items is not None and len(self._data) > self.max_items)
           or (self.max_bytes is not None and self._bytes > self.max_bytes)):
      self._bytes -= self._data.popitem(last=False)[1][1]
