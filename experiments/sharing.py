"""Work shared between the variants of a paper table (table plumbing, not the method).

The variants of an ablation table share one baseline per seed. What they would otherwise
compute again is shared here, always as the result of the same computation on the same
inputs (so sharing changes no number), and always with the seconds it took when it was
computed (so sharing never makes a variant look cheaper):

  * a finished baseline (copy_baseline) or whole finished rounds (copy_finished_rounds)
    of another run made with the same config;
  * round 1's pseudo-views of another variant that renders the same ones
    (share_pseudo_views);
  * in-process memos: the Hessian pass of one baseline (HessianCache) and views
    rendered by an earlier variant (ViewCache), through `memo_synthesize`.

Which Config fields may differ for each kind of sharing is derived from the fields'
`affects` categories (renerf_jax.configs.fields_where), declared once on the Config.
"""
import collections
import dataclasses
import hashlib
import os
import shutil

import jax
import numpy as np

from renerf_jax import report, rundir
from renerf_jax.backbones import get_backbone
from renerf_jax.configs import config_differences, fields_where
from renerf_jax.uncertainty import laplace
from renerf_jax.nerf import synthesis


# --------------------------------------------------------------- memo keys and caches


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


# Fields that cannot change the Hessian pass. The seed acts only through the subsampled
# training rays, which are part of the key.
HESSIAN_IRRELEVANT = fields_where('hessian', present=False) + ('seed',)
# Fields that cannot change a rendered view's pixels. The seed is not used by rendering.
RENDER_IRRELEVANT = fields_where('render', present=False) + ('seed',)
HESSIAN_CACHE_SIZE = 4  # A (2^8 + 1)^3 grid is 68 MB.
VIEW_CACHE_BYTES = 1 << 30  # About 2000 views at 252x189, 470 at 504x378.


class ViewCache:
  """Rendered pseudo-views keyed on (config without RENDER_IRRELEVANT, params, rays).

  Called as synthesis.render_pseudo_views' render_fn: a view rendered before in this
  process comes back bit for bit with the seconds its render took; `hits` and `misses`
  count the calls of each kind.
  """

  def __init__(self, max_bytes=VIEW_CACHE_BYTES):
    self.cache = LruCache(max_bytes=max_bytes)
    self.hits = self.misses = 0

  @staticmethod
  def key(config, params, rays):
    return digest(config_key(config, RENDER_IRRELEVANT), params, rays)

  def __call__(self, config, params, rays):
    """(rgb [H * W, 3], seconds of the render that made it)."""
    key = self.key(config, params, rays)
    hit = self.cache.get(key)
    if hit is not None:
      self.hits += 1
      return hit[0].copy(), hit[1]
    self.misses += 1
    rgb, seconds = synthesis.render_view(config, params, rays)
    self.cache.put(key, (rgb.copy(), seconds))
    return rgb, seconds


class HessianCache:
  """Per-vertex sigma of the Hessian pass of the last HESSIAN_CACHE_SIZE baselines.

  Called as uncertainty.masks.compute_masks' sigma_fn; `hits` and `misses` count the calls.
  """

  def __init__(self, max_items=HESSIAN_CACHE_SIZE):
    self.cache = LruCache(max_items=max_items)
    self.hits = self.misses = 0

  def __call__(self, config, params, train, lo, hi, chunk, show_progress=False):
    """(sigma [V], seconds of the pass that computed it)."""
    key = digest(config_key(config, HESSIAN_IRRELEVANT), np.int64(chunk), params, train,
                 lo, hi)
    hit = self.cache.get(key)
    if hit is not None:
      self.hits += 1
      return hit
    self.misses += 1
    sigma, seconds = laplace.vertex_sigma_pass(config, params, train, lo, hi, chunk,
                                               show_progress)
    self.cache.put(key, (sigma, seconds))
    return sigma, seconds


VIEW_CACHE = ViewCache()
HESSIAN_CACHE = HessianCache()


def memo_synthesize(config, scene, params, show_progress=False):
  """synthesis.synthesize with the process's Hessian and view memos (NeRF backbones; any
  other backbone synthesises through its own Backbone.synthesize, unmemoised)."""
  if config.backbone != 'nerf':
    return get_backbone(config).synthesize(config, scene, params, show_progress)
  return synthesis.synthesize(config, scene, params, show_progress, sigma_fn=HESSIAN_CACHE,
                           render_fn=VIEW_CACHE)


# --------------------------------------------------------------- copies between runs

# Fields that only act from round 1 on (or change no result): two configs that differ
# only in these train the same baseline, bit for bit.
ROUND_FIELDS = fields_where('baseline', present=False)
# Fields that cannot change round 1's pseudo-views given the same baseline.
NOT_PSEUDO_VIEW_FIELDS = tuple(k for k in ROUND_FIELDS
                               if k in fields_where('pseudo', present=False))


def baseline_differences(config, saved_config: dict):
  """Names of the fields in which two configs' baselines differ."""
  return config_differences(config, saved_config, ROUND_FIELDS)


def _same_bytes(path_a, path_b):
  if not (os.path.isfile(path_a) and os.path.isfile(path_b)):
    return False
  with open(path_a, 'rb') as a, open(path_b, 'rb') as b:
    return a.read() == b.read()


def _copy_tree(src, dst, copied_from=None):
  """Copies src to dst through a temp directory renamed into place (no half copies)."""
  parent = os.path.dirname(dst)
  os.makedirs(parent, exist_ok=True)
  tmp = os.path.join(parent, f'.{os.path.basename(dst)}.{os.getpid()}.tmp')
  shutil.rmtree(tmp, ignore_errors=True)
  shutil.copytree(src, tmp)
  if copied_from:
    report.write_json(rundir.copied_from_path(tmp), {'from': copied_from})
  os.replace(tmp, dst)


def copy_baseline(config, src_run_dir, dst_run_dir):
  """Copies a finished round_0 of another run instead of training the same baseline again.

  src_run_dir must hold config.json whose baseline fields equal config's and a finished
  round_0; dst_run_dir must not have a round_0 yet.

  Raises:
    RunDirError: the source is unfinished or was made with another baseline config, or
      the destination already has a round_0.
  """
  from renerf_jax.errors import RunDirError  # pylint: disable=g-import-not-at-top
  src, dst = rundir.round_dir(src_run_dir, 0), rundir.round_dir(dst_run_dir, 0)
  if not rundir.is_done(src):
    raise RunDirError(f'{src} is not a finished round (no DONE): nothing to copy')
  cfg_path = rundir.config_json_path(src_run_dir)
  if not os.path.isfile(cfg_path):
    raise RunDirError(f'{cfg_path} missing: cannot tell which config trained {src}')
  diff = baseline_differences(config, report.read_json(cfg_path))
  if diff:
    raise RunDirError(f'{src} was trained with another baseline config (differs in '
                      f'{", ".join(diff)}); it cannot stand in for {dst}')
  if os.path.exists(dst):
    raise RunDirError(f'{dst} exists; refusing to overwrite it with a copy of {src}')
  _copy_tree(src, dst)


def copy_finished_rounds(config, src_run_dir, dst_run_dir):
  """Copies rounds 1..config.num_rounds that another run finished with the same config.

  Round r is copied when src's config.json equals config in every field but num_rounds,
  src has finished round r, dst has not started it, and both runs' round r - 1 params are
  byte-identical. A round is a deterministic function of its config and B, so the copy is
  what training it again would give; it keeps its timing and records copied_from.json.

  Returns:
    The rounds copied (a list of ints; empty when src does not qualify).
  """
  cfg_path = rundir.config_json_path(src_run_dir)
  if (os.path.abspath(src_run_dir) == os.path.abspath(dst_run_dir)
      or not os.path.isfile(cfg_path)
      or config_differences(config, report.read_json(cfg_path), ('num_rounds',))):
    return []
  copied = []
  for r in range(1, config.num_rounds + 1):
    src, dst = rundir.round_dir(src_run_dir, r), rundir.round_dir(dst_run_dir, r)
    if os.path.exists(dst):
      continue
    if not rundir.is_done(src) or not _same_bytes(
        *(rundir.params_path(rundir.round_dir(d, r - 1))
          for d in (src_run_dir, dst_run_dir))):
      break
    _copy_tree(src, dst, copied_from=os.path.abspath(src))
    copied.append(r)
  return copied


def share_pseudo_views(config, src_run_dir, dst_run_dir):
  """Copies round 1's pseudo-views from another run that renders the same ones.

  They are copied when both runs have byte-identical round_0 params, configs equal in
  every field but NOT_PSEUDO_VIEW_FIELDS, src has finished its round-1 pseudo-views and
  dst has not started its own. The copy keeps timing.json (the synthesis seconds still
  count) and names src in copied_from.json.

  Returns:
    True if copied, False if src does not qualify (nothing is written then).
  """
  src = rundir.pseudo_views_dir(rundir.round_dir(src_run_dir, 1))
  dst = rundir.pseudo_views_dir(rundir.round_dir(dst_run_dir, 1))
  cfg_path = rundir.config_json_path(src_run_dir)
  if (os.path.abspath(src_run_dir) == os.path.abspath(dst_run_dir) or os.path.exists(dst)
      or not all(os.path.isfile(f(src)) for f in (rundir.views_npz_path, rundir.timing_path))
      or not os.path.isfile(cfg_path)):
    return False
  if config_differences(config, report.read_json(cfg_path),
                        NOT_PSEUDO_VIEW_FIELDS) or not _same_bytes(
      *(rundir.params_path(rundir.round_dir(d, 0)) for d in (src_run_dir, dst_run_dir))):
    return False
  _copy_tree(src, dst, copied_from=os.path.abspath(src))
  return True

