"""Re-Nerfing rounds on immutable state: RoundState -> RoundState (the paper's Figure 2).

  round 0: train B on the real views                         (the baseline)
  round r: render pseudo-views with B at interpolated poses
           [Laplace uncertainty of B -> masks]               (only with Config.use_masks)
           train D from scratch on real + masked pseudo-views (pseudo rays until step K)
           D becomes the next round's B

Each round writes round_<r>/ in the run directory and marks it DONE; a rerun of the same
command reloads finished rounds (never rewriting them) and resumes the interrupted one
from its last atomic checkpoint.
"""
import dataclasses
import os
import shutil
import time
from typing import Any, Optional, Tuple

import flax
import jax
import jax.numpy as jnp
import numpy as np
from flax import serialization

from renerf_jax import poses as pose_lib
from renerf_jax import report, rundir, training
from renerf_jax.datasets import camera_rays, ray_pool
from renerf_jax.errors import RunDirError
from renerf_jax.evaluation import cheap_eval_fn, evaluate_test_views
from renerf_jax.pseudo_views import (PseudoViews, load_pseudo_views, pseudo_view_poses,
                                     render_pseudo_views, save_pseudo_views)


@flax.struct.dataclass
class RoundState:
  """Everything one round hands to the next (a pytree)."""
  round_index: jnp.ndarray  # int32 scalar: round that produced `params` (-1: none yet).
  params: Any  # Field parameters of the current model (B for the next round).
  pseudo: Optional[PseudoViews]  # Pseudo-views the current model was trained with.
  metrics: Tuple[dict, ...]  # Test metrics of every finished round, in order.
  seconds: jnp.ndarray  # Cumulative wall-clock seconds (training + synthesis + masks).
  rng: jnp.ndarray  # PRNG key for the next round.


def initial_state(config) -> RoundState:
  return RoundState(round_index=jnp.asarray(-1, jnp.int32), params=None, pseudo=None,
                    metrics=(), seconds=jnp.asarray(0., jnp.float32),
                    rng=jax.random.PRNGKey(config.seed))


def round_dir(run_dir, r):
  return os.path.join(run_dir, f'round_{r}')


def regularizer_poses(config, scene):
  """Random unobserved poses for depth TV ([n_random_poses, 3, 4]), or None when off."""
  if config.depth_tv_loss_mult <= 0:
    return None
  rng = np.random.default_rng(config.seed)
  train = np.asarray(scene.poses[scene.train_idx], np.float64)
  if scene.forward_facing:
    poses = pose_lib.random_poses_forward_facing(train, config.n_random_poses, rng,
                                                 focus_depth=scene.focus_depth,
                                                 spread=config.random_pose_spread)
  else:
    poses = pose_lib.random_poses_sphere(train, config.n_random_poses, rng)
  return jnp.asarray(poses, jnp.float32)


def make_pools(config, scene, pseudo: Optional[PseudoViews]):
  """Training pools: real views, pseudo-views (if any), random poses (if depth TV)."""
  pools = {'real': ray_pool(scene, scene.train_idx)}
  if pseudo is not None:
    pools['pseudo'] = ray_pool(scene, None, images=pseudo.images, masks=pseudo.masks,
                               poses=pseudo.poses)
  random_poses = regularizer_poses(config, scene)
  if random_poses is not None:
    pools['random_poses'] = random_poses
  return pools


def synthesize(config, scene, params, out_dir, show_progress=True):
  """Pseudo-views of model `params` (with uncertainty masks if config.use_masks).

  With masks, the Hessian pass runs first and the colours and the uncertainty of the
  pseudo-views come out of one render pass. timing.json records render_seconds (the
  render pass, with masks including U and the threshold) and, with masks,
  hessian_seconds (the extra work of the masks), mu and kept_fraction. A Hessian pass
  taken from uncertainty.cached_vertex_sigma (another variant with the same baseline)
  is marked hessian_cached and its seconds still count in `seconds`. Without masks,
  views taken from pseudo_views' in-process view cache are counted in cached_views and
  their render seconds (cached_seconds) count in `seconds` too.
  Cached in out_dir (views.npz written atomically), so a resumed round reuses them.

  Returns:
    (PseudoViews, seconds spent).
  """
  cached = load_pseudo_views(out_dir)
  info_path = os.path.join(out_dir, 'timing.json')
  if cached is not None and os.path.isfile(info_path):
    return cached, float(report.read_json(info_path)['seconds'])
  t0 = time.perf_counter()
  poses, meta = pseudo_view_poses(config, scene)
  if config.use_masks:
    pv, timing = masked_pseudo_views(config, scene, params, poses, show_progress)
  else:
    pv, timing = render_pseudo_views(config, scene, params, poses, show_progress)
    timing['render_seconds'] = time.perf_counter() - t0
  timing['seconds'] = time.perf_counter() - t0
  # Shared work still counts, as if done here.
  if timing.get('hessian_cached'):
    timing['seconds'] += timing['hessian_seconds']
  timing['seconds'] += timing.get('cached_seconds', 0.)
  save_pseudo_views(out_dir, pv, meta)
  report.write_json(info_path, timing)
  return pv, timing['seconds']


def masked_pseudo_views(config, scene, params, poses, show_progress=False):
  """Pseudo-views at `poses` with Laplace-uncertainty masks (pixels with U > mu masked).

  Returns:
    (PseudoViews with masks and uncertainty, timing dict).
  """
  from renerf_jax import uncertainty  # pylint: disable=g-import-not-at-top
  t0 = time.perf_counter()
  lo, hi = scene.bbox
  rays = camera_rays(scene, None, poses)
  res = uncertainty.compute_masks(config, params, ray_pool(scene, scene.train_idx)['rays'],
                                  rays, np.asarray(lo), np.asarray(hi),
                                  show_progress=show_progress)
  total = time.perf_counter() - t0
  pv = PseudoViews(images=np.clip(res.rgb, 0., 1.), poses=np.asarray(poses),
                   masks=np.asarray(res.mask, np.float32),
                   uncertainty=np.asarray(res.uncertainty, np.float32))
  render_seconds = total - (0. if res.hessian_cached else res.hessian_seconds)
  return pv, {'render_seconds': render_seconds, 'hessian_seconds': res.hessian_seconds,
              'hessian_cached': res.hessian_cached,
              'mu': float(res.mu), 'kept_fraction': float(np.mean(pv.masks))}


def round_config(config, r):
  """The Config of round r's training: a fresh seed per round (D starts from scratch)."""
  return dataclasses.replace(config, seed=config.seed + 1000 * r)


def round_step(config, scene, state: RoundState, run_dir, show_progress=True) -> RoundState:
  """Runs the next round and returns the next RoundState (a finished round is loaded)."""
  r = int(state.round_index) + 1
  rdir = round_dir(run_dir, r)
  if rundir.is_done(rdir):
    return load_round(config, rdir, state)
  rundir.remove_stale_temp_files(rdir)  # Left by a run killed mid-write.
  cfg = round_config(config, r)
  pseudo, synth_seconds = None, 0.
  if r > 0:
    pseudo, synth_seconds = synthesize(config, scene, state.params,
                                       os.path.join(rdir, 'pseudo_views'), show_progress)
  start = float(state.seconds) + synth_seconds
  result = training.train_model(
      cfg, scene, os.path.join(rdir, 'train'), make_pools(cfg, scene, pseudo),
      window=training.pseudo_window(cfg) if pseudo is not None else (0, 0),
      init_params=state.params if r > 0 and config.renerf_init == 'continue' else None,
      eval_fn=cheap_eval_fn(cfg, scene), time_offset=start,
      desc=f'round {r}' if r else 'baseline', show_progress=show_progress)
  seconds = start + result.train_seconds
  ev = evaluate_test_views(cfg, scene, result.state.params, os.path.join(rdir, 'eval'),
                           show_progress=False)
  metrics = dict(ev['mean'], round=r, round_seconds=synth_seconds + result.train_seconds,
                 cumulative_seconds=seconds, nan_skips=int(result.state.nan_skips))
  with report.atomic_open(os.path.join(rdir, 'params.msgpack'), 'wb') as f:
    f.write(serialization.to_bytes(result.state.params))
  report.write_json(os.path.join(rdir, 'result.json'), {'metrics': metrics,
                                                        'curve': result.curve})
  rundir.mark_done(rdir, {'round': r})
  return RoundState(round_index=jnp.asarray(r, jnp.int32), params=result.state.params,
                    pseudo=pseudo, metrics=state.metrics + (metrics,),
                    seconds=jnp.asarray(seconds, jnp.float32),
                    rng=jax.random.fold_in(state.rng, r))


def load_round(config, rdir, state: RoundState) -> RoundState:
  """The RoundState after the finished round in rdir (read-only)."""
  r = int(state.round_index) + 1
  template = training.init_state(round_config(config, r), jax.random.PRNGKey(0)).params
  with open(os.path.join(rdir, 'params.msgpack'), 'rb') as f:
    params = serialization.from_bytes(template, f.read())
  metrics = report.read_json(os.path.join(rdir, 'result.json'))['metrics']
  return RoundState(round_index=jnp.asarray(r, jnp.int32), params=params,
                    pseudo=load_pseudo_views(os.path.join(rdir, 'pseudo_views')),
                    metrics=state.metrics + (metrics,),
                    seconds=jnp.asarray(metrics['cumulative_seconds'], jnp.float32),
                    rng=jax.random.fold_in(state.rng, r))


def check_rounds_config(config, scene):
  """Raises ConfigError now for pseudo-view settings that round 1 could not use.

  Without this, a single training view with interpolated pseudo-views (no neighbouring
  pair to interpolate), a bad Config.interp_factors or Config.pseudo_targets would only
  fail after the baseline had trained. With num_rounds = 0 nothing is checked (the
  baseline alone needs no pseudo-views).
  """
  if config.num_rounds > 0:
    pseudo_view_poses(config, scene)


# Config fields that only act from round 1 on (plus knobs that change no result): two
# configs that differ only in these train the same baseline, bit for bit.
ROUND_FIELDS = ('num_rounds', 'pseudo_frac', 'pseudo_until', 'pseudo_schedule',
                'renerf_init', 'interp_factors', 'sequencing', 'pseudo_targets',
                'pseudo_n_random', 'use_masks', 'deform_log2_res', 'hessian_rays',
                'hessian_lambda', 'hessian_chunk', 'mask_keep_frac', 'mask_threshold',
                'checkpoint_every', 'render_chunk')


def config_differences(config, saved_config: dict, ignore=()):
  """Names of the fields outside `ignore` in which config and a saved config.json differ
  (a field missing from the saved one, added to Config later, counts as its default)."""
  current = report.to_jsonable(dataclasses.asdict(config))
  defaults = report.to_jsonable(dataclasses.asdict(type(config)()))
  saved = dict({k: v for k, v in defaults.items() if k not in saved_config}, **saved_config)
  return sorted(k for k in set(saved) | set(current)
                if k not in ignore and saved.get(k) != current.get(k))


def baseline_differences(config, saved_config: dict):
  """Names of the fields (outside ROUND_FIELDS) in which two configs' baselines differ."""
  return config_differences(config, saved_config, ROUND_FIELDS)


def _same_bytes(path_a, path_b):
  if not (os.path.isfile(path_a) and os.path.isfile(path_b)):
    return False
  with open(path_a, 'rb') as a, open(path_b, 'rb') as b:
    return a.read() == b.read()


def copy_finished_rounds(config, src_run_dir, dst_run_dir):
  """Copies rounds 1..config.num_rounds that another run finished with the same config.

  A variant of one table can be a run of another (the masks table's '+ masks' is the
  rounds table's R1 when both use the same config). Round r is copied when src's
  config.json equals config in every field but num_rounds, src has finished round r,
  dst has not started it, and both runs' round r - 1 params are byte-identical (dst's
  model B is src's, e.g. a copied baseline). A round is a deterministic function of its
  config and B, so the copy is what training it again would give; it keeps its timing
  (cumulative seconds) and records copied_from.json. Each copy is made in a temp
  directory and renamed into place.

  Returns:
    The rounds copied (a list of ints; empty when src does not qualify).
  """
  cfg_path = os.path.join(src_run_dir, 'config.json')
  if (os.path.abspath(src_run_dir) == os.path.abspath(dst_run_dir)
      or not os.path.isfile(cfg_path)
      or config_differences(config, report.read_json(cfg_path), ('num_rounds',))):
    return []
  copied = []
  for r in range(1, config.num_rounds + 1):
    src, dst = round_dir(src_run_dir, r), round_dir(dst_run_dir, r)
    if os.path.exists(dst):
      continue
    if not rundir.is_done(src) or not _same_bytes(
        *(os.path.join(round_dir(d, r - 1), 'params.msgpack')
          for d in (src_run_dir, dst_run_dir))):
      break
    tmp = os.path.join(dst_run_dir, f'.round_{r}.{os.getpid()}.tmp')
    shutil.rmtree(tmp, ignore_errors=True)
    shutil.copytree(src, tmp)
    report.write_json(os.path.join(tmp, 'copied_from.json'), {'from': os.path.abspath(src)})
    os.replace(tmp, dst)
    copied.append(r)
  return copied


def copy_baseline(config, src_run_dir, dst_run_dir):
  """Copies a finished round_0 of another run instead of training the same baseline again.

  Ablations (the tables "why", view selection, masks) vary only what happens from round
  1 on, so every variant of one seed has the same baseline. src_run_dir must hold
  config.json (written by cli.check_run_dir) whose baseline fields equal config's, and a
  finished round_0; dst_run_dir must not have a round_0 yet. The copy is made in a temp
  directory and renamed into place, so a killed copy leaves no half round_0 behind.

  Raises:
    RunDirError: the source is unfinished or was made with another baseline config, or
      the destination already has a round_0.
  """
  src, dst = round_dir(src_run_dir, 0), round_dir(dst_run_dir, 0)
  if not rundir.is_done(src):
    raise RunDirError(f'{src} is not a finished round (no DONE): nothing to copy')
  cfg_path = os.path.join(src_run_dir, 'config.json')
  if not os.path.isfile(cfg_path):
    raise RunDirError(f'{cfg_path} missing: cannot tell which config trained {src}')
  diff = baseline_differences(config, report.read_json(cfg_path))
  if diff:
    raise RunDirError(f'{src} was trained with another baseline config (differs in '
                      f'{", ".join(diff)}); it cannot stand in for {dst}')
  if os.path.exists(dst):
    raise RunDirError(f'{dst} exists; refusing to overwrite it with a copy of {src}')
  os.makedirs(dst_run_dir, exist_ok=True)
  tmp = os.path.join(dst_run_dir, f'.round_0.{os.getpid()}.tmp')
  shutil.rmtree(tmp, ignore_errors=True)
  shutil.copytree(src, tmp)
  os.replace(tmp, dst)


# Config fields (beside the baseline's) that decide round 1's pseudo-views and masks.
PSEUDO_VIEW_FIELDS = ('interp_factors', 'sequencing', 'pseudo_targets', 'pseudo_n_random',
                      'use_masks', 'deform_log2_res', 'hessian_rays', 'hessian_lambda',
                      'hessian_chunk', 'mask_keep_frac', 'mask_threshold')


def share_pseudo_views(config, src_run_dir, dst_run_dir):
  """Copies round 1's pseudo-views from another run that renders the same ones.

  Variants of an ablation that differ only in how D is trained (Config.pseudo_schedule,
  renerf_init, pseudo_frac, pseudo_until) render the same round-1 pseudo-views from the
  same baseline. They are copied when both runs have byte-identical round_0 params, the
  same baseline config and the same PSEUDO_VIEW_FIELDS, src has finished its round-1
  pseudo-views and dst has not started its own. The copy keeps timing.json, so the
  cumulative seconds of dst still count the synthesis; copied_from.json names src. It
  is made in a temp directory and renamed into place.

  Returns:
    True if copied, False if src does not qualify (nothing is written then).
  """
  src = os.path.join(round_dir(src_run_dir, 1), 'pseudo_views')
  dst_round = round_dir(dst_run_dir, 1)
  dst = os.path.join(dst_round, 'pseudo_views')
  cfg_path = os.path.join(src_run_dir, 'config.json')
  if (os.path.abspath(src_run_dir) == os.path.abspath(dst_run_dir) or os.path.exists(dst)
      or not all(os.path.isfile(os.path.join(src, f)) for f in ('views.npz', 'timing.json'))
      or not os.path.isfile(cfg_path)):
    return False
  ignore = tuple(k for k in ROUND_FIELDS if k not in PSEUDO_VIEW_FIELDS)
  if config_differences(config, report.read_json(cfg_path), ignore) or not _same_bytes(
      *(os.path.join(round_dir(d, 0), 'params.msgpack') for d in (src_run_dir, dst_run_dir))):
    return False
  os.makedirs(dst_round, exist_ok=True)
  tmp = os.path.join(dst_round, f'.pseudo_views.{os.getpid()}.tmp')
  shutil.rmtree(tmp, ignore_errors=True)
  shutil.copytree(src, tmp)
  report.write_json(os.path.join(tmp, 'copied_from.json'), {'from': os.path.abspath(src)})
  os.replace(tmp, dst)
  return True


def run_rounds(config, scene, run_dir, show_progress=True) -> RoundState:
  """Baseline plus config.num_rounds Re-Nerfing rounds: the loop of Figure 2."""
  check_rounds_config(config, scene)
  state = initial_state(config)
  for _ in range(config.num_rounds + 1):
    state = round_step(config, scene, state, run_dir, show_progress)
  return state


def rounds_table(metrics):
  """Markdown table of per-round test metrics in the shape of the paper's 3-view table."""
  rows = [dict(m, name='baseline' if m['round'] == 0 else f"Re-Nerfing R{m['round']}")
          for m in metrics]
  cols = [('name', 'round'), ('psnr', 'PSNR'), ('ssim', 'SSIM'),
          ('lpips_alex', 'LPIPS-alex'), ('lpips_vgg', 'LPIPS-vgg'), ('avg_err', 'avg err'),
          ('cumulative_seconds', 'cum. time [s]')]
  return report.markdown_table(rows, [c for c in cols if c[0] == 'name' or
                                      any(c[0] in m for m in metrics)])
