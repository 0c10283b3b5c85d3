"""Training one NeRF: TrainState, RegNeRF's lr schedule, the jitted step; fit.fit loops.

The step is a pure function `train_step(config, cam, pseudo_on, state, pools, key)`
jitted with (config, cam, pseudo_on) static: regularisers a config switches off, and the
pseudo-view pool once it is dropped, are not traced at all.
"""
import dataclasses
import functools
from typing import Any

import flax
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from renerf_jax import cameras, distributed, fit, metrics, schedules
from renerf_jax.nerf import regularizers
from renerf_jax.nerf.fields import frequency_mask, init_field_params
from renerf_jax.nerf.fields.proposal import interlevel_loss
from renerf_jax.nerf.model import colour_levels, render_rays


@flax.struct.dataclass
class TrainState:
  step: jnp.ndarray  # int32 scalar: optimisation steps taken.
  params: Any
  opt_state: Any
  nan_skips: jnp.ndarray  # int32 scalar: steps skipped for a non-finite loss/gradient.


@dataclasses.dataclass(frozen=True)
class Camera:
  """Static pinhole camera of a scene (shared by all its views)."""
  h: int
  w: int
  focal: float
  use_ndc: bool
  near: float
  far: float

  @classmethod
  def of(cls, scene):
    return cls(scene.height, scene.width, float(scene.focal), bool(scene.use_ndc),
               float(scene.near), float(scene.far))


def learning_rate(step, config):
  """RegNeRF / mip-NeRF schedule: log-linear lr_init -> lr_final over max_steps, times a
  delayed warm-up lr_delay_mult + (1 - lr_delay_mult) sin(pi/2 clip(step / delay, 0, 1)).

  With Config.lr_decay_start_frac = f > 0 the lr stays at lr_init until step f max_steps
  and the log-linear decay runs over the remaining steps (a cool-down).
  """
  if config.lr_delay_steps > 0:
    delay = config.lr_delay_mult + (1. - config.lr_delay_mult) * jnp.sin(
        0.5 * jnp.pi * jnp.clip(step / config.lr_delay_steps, 0., 1.))
  else:
    delay = 1.
  if config.lr_decay_start_frac > 0:  # Static: the default traces the plain schedule.
    start = config.lr_decay_start_frac * config.max_steps
    return delay * schedules.log_lerp(jnp.maximum(step - start, 0.), config.lr_init,
                                         config.lr_final, config.max_steps - start)
  return delay * schedules.log_lerp(step, config.lr_init, config.lr_final,
                                       config.max_steps)


def make_optimizer(config):
  """Clip by value, clip by global norm, Adam, RegNeRF's schedule.

  With the proposal sampler the clipping acts on the scene field's gradient only: the
  proposal's (from the interlevel loss alone) neither enters the global norm nor is
  clipped, so its scale cannot shrink the scene field's steps.
  """
  parts = []
  if config.grad_max_val > 0:
    parts.append(optax.clip(config.grad_max_val))
  if config.grad_max_norm > 0:
    parts.append(optax.clip_by_global_norm(config.grad_max_norm))
  if parts and config.sampler == 'proposal':
    parts = [optax.masked(optax.chain(*parts),
                          lambda params: {k: k == 'params' for k in params})]
  parts.append(optax.adam(functools.partial(learning_rate, config=config),
                          eps=config.adam_eps))
  return optax.chain(*parts)


def init_state(config, key, params=None) -> TrainState:
  """A fresh TrainState (new parameters unless `params` is given)."""
  if params is None:
    params = init_field_params(config, key)
  opt_state = make_optimizer(config).init(params)
  return TrainState(step=jnp.zeros((), jnp.int32), params=params, opt_state=opt_state,
                    nan_skips=jnp.zeros((), jnp.int32))


def data_sharding():
  """Batch sharding over all devices (data parallel; one device works too). With several
  processes (renerf_jax.distributed) jax.devices() holds every process's devices: one
  global mesh."""
  mesh = Mesh(np.array(jax.devices()), ('data',))
  return NamedSharding(mesh, PartitionSpec('data'))


def replicated_sharding():
  """Sharding of the train state: replicated on all devices (as train_step returns
  it, so the first step compiles the same executable as every later step)."""
  return NamedSharding(Mesh(np.array(jax.devices()), ('data',)), PartitionSpec())


def sample_from_pool(pool, key, n):
  """n rays drawn uniformly with replacement from a pool {'rays', 'rgb', 'lossmult'}."""
  n_pool = pool['rgb'].shape[0]
  idx = jax.random.randint(key, (n,), 0, n_pool)
  return jax.tree_util.tree_map(lambda x: x[idx], pool)


def random_patch_rays(poses, key, n_patches, patch, cam: Camera) -> cameras.Rays:
  """Rays of n_patches patch x patch pixel patches at random pixels of random poses.

  Args:
    poses: [P, 3, 4] candidate camera poses. key: PRNG key.
    n_patches, patch: static sizes. cam: static camera.

  Returns:
    Rays with leading shape [n_patches, patch, patch].
  """
  k_pose, k_x, k_y = jax.random.split(key, 3)
  pose_idx = jax.random.randint(k_pose, (n_patches,), 0, poses.shape[0])
  x0 = jax.random.randint(k_x, (n_patches, 1, 1), 0, cam.w - patch + 1)
  y0 = jax.random.randint(k_y, (n_patches, 1, 1), 0, cam.h - patch + 1)
  grid_y, grid_x = jnp.meshgrid(jnp.arange(patch), jnp.arange(patch), indexing='ij')
  pix_x = (x0 + grid_x).astype(jnp.float32)
  pix_y = (y0 + grid_y).astype(jnp.float32)
  c2w = poses[pose_idx][:, None, None]
  return cameras.pixel_rays(c2w, pix_x, pix_y, cam.focal, cam.h, cam.w, cam.use_ndc,
                            cam.near, cam.far)


def mixed_pool(real, pseudo):
  """One pool of the real rays and the usable pseudo-view rays (Config.pseudo_mix='pixels').

  Drawing uniformly from it draws every usable pixel of the real and the pseudo-views
  with the same probability (the paper uses the pseudo-views "as part of the training
  images"); pseudo pixels with a zero mask are left out, so they are never drawn.

  Args:
    real, pseudo: pools {'rays', 'rgb', 'lossmult'} (see datasets.ray_pool).

  Returns:
    The pool with an extra 'is_pseudo' [P, 1] (1 for a pseudo-view ray).
  """
  keep = np.flatnonzero(np.asarray(pseudo['lossmult'])[:, 0] > 0)
  kept = jax.tree_util.tree_map(lambda x: jnp.asarray(x)[keep], pseudo)
  pool = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), real, kept)
  pool['is_pseudo'] = jnp.concatenate([jnp.zeros((real['rgb'].shape[0], 1), jnp.float32),
                                       jnp.ones((keep.size, 1), jnp.float32)])
  return pool


def pseudo_rays_per_batch(config) -> int:
  """Pseudo rays in a batch with Config.pseudo_mix='fraction' (a multiple of the devices
  of all processes)."""
  n = int(round(config.pseudo_frac * config.batch_size))
  return n - n % jax.device_count()


def draw_batch(config, pools, pseudo_on: bool, k_real, k_pseudo):
  """The rays of one step and how many of them come from pseudo-views.

  Args:
    config: static Config. pools: see train_step.
    pseudo_on: static; whether the pseudo-views are on at this step.
    k_real, k_pseudo: PRNG keys of the real (or mixed) and the pseudo-view draws.

  Returns:
    (batch {'rays', 'rgb', 'lossmult'} of config.batch_size rays, pseudo ray count).
  """
  if pseudo_on and config.pseudo_mix == 'pixels':
    batch = sample_from_pool(pools['mixed'], k_real, config.batch_size)
    return batch, jnp.sum(batch.pop('is_pseudo'))
  n_pseudo = pseudo_rays_per_batch(config) if pseudo_on else 0
  batch = sample_from_pool(pools['real'], k_real, config.batch_size - n_pseudo)
  if n_pseudo > 0:
    pseudo = sample_from_pool(pools['pseudo'], k_pseudo, n_pseudo)
    batch = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), batch, pseudo)
  return batch, jnp.asarray(n_pseudo, jnp.float32)


def masked_mse(rgb, gt, lossmult):
  """sum(m (rgb - gt)^2) / (3 sum(m)); an all-masked batch gives 0 (finite), not NaN."""
  num = jnp.sum(lossmult * (rgb - gt)**2)
  den = 3. * jnp.sum(lossmult)
  return num / jnp.maximum(den, 1e-8)


def _anneal(rays, step, config):
  near, far = regularizers.annealed_near_far(step, rays.near, rays.far,
                                             config.anneal_nearfar_steps,
                                             config.anneal_nearfar_perc,
                                             config.anneal_mid_perc)
  return rays.replace(near=near, far=far)


def _feature_mask(step, config):
  if not config.freq_reg:
    return None
  return frequency_mask(config, step / (config.freq_reg_end * config.max_steps))


def loss_fn(params, config, cam, batch, patches, step, key, centres=None):
  """Total loss and statistics for one batch.

  Args:
    params: field parameters (fields.init_field_params). config, cam: static.
    batch: {'rays' Rays [B], 'rgb' [B, 3], 'lossmult' [B, 1]}.
    patches: Rays [P, ps, ps] from random poses, or None (depth TV off).
    step: scalar step. key: PRNG key.
    centres: [C, 3] training camera centres (the near-camera penalty), or None.

  Returns:
    (loss, stats dict).
  """
  k_main, k_patch = jax.random.split(key)
  feature_mask = _feature_mask(step, config)
  rays = _anneal(batch['rays'], step, config) if config.anneal_nearfar else batch['rays']
  levels = render_rays(config, params, rays, k_main, train=True, feature_mask=feature_mask)
  mses = [masked_mse(lv['rgb'], batch['rgb'], batch['lossmult'])
          for lv in levels[-colour_levels(config):]]
  loss = mses[-1] + config.coarse_loss_mult * sum(mses[:-1])
  stats = {'mse': mses[-1], 'psnr': metrics.mse_to_psnr(mses[-1])}
  if config.sampler == 'proposal':
    fine = levels[-1]
    inter = interlevel_loss(fine['t_vals'], fine['weights'], levels[0]['t_vals'],
                            levels[0]['weights'])
    loss = loss + config.interlevel_loss_mult * inter
    stats['interlevel'] = inter
  if patches is not None:
    flat = jax.tree_util.tree_map(lambda x: x.reshape((-1,) + x.shape[3:]), patches)
    if config.anneal_nearfar:
      flat = _anneal(flat, step, config)
    p_levels = render_rays(config, params, flat, k_patch, train=True,
                           feature_mask=feature_mask)
    depth = p_levels[-1]['distance'].reshape(patches.origins.shape[:3])
    tv = regularizers.depth_tv(depth)
    if config.depth_tv_decay:
      weight = regularizers.depth_tv_weight(step, config.depth_tv_mult_start,
                                            config.depth_tv_mult_end,
                                            config.depth_tv_maxstep)
    else:
      weight = config.depth_tv_loss_mult
    loss = loss + weight * tv
    stats.update(depth_tv=tv, depth_tv_weight=weight)
  if config.distortion_loss_mult > 0:
    parts = [(levels[-1], rays)] + ([(p_levels[-1], flat)] if patches is not None else [])
    counts = [r.near.size for _, r in parts]
    dist = sum(n * regularizers.ray_distortion(lv['t_vals'], lv['weights'], r.near, r.far)
               for n, (lv, r) in zip(counts, parts)) / sum(counts)
    loss = loss + config.distortion_loss_mult * dist
    stats['distortion'] = dist
  if config.near_camera_loss_mult > 0:
    fine = levels[-1]
    near = regularizers.near_camera_weight(rays.origins, rays.directions, fine['t_vals'],
                                           fine['weights'], centres,
                                           config.near_camera_radius)
    loss = loss + config.near_camera_loss_mult * near
    stats['near_camera'] = near
  if config.occ_reg_mult > 0:
    occ = sum(regularizers.occlusion_loss(lv['density'], config.occ_reg_range)
              for lv in levels[-colour_levels(config):])
    loss = loss + config.occ_reg_mult * occ
    stats['occ'] = occ
  stats['loss'] = loss
  return loss, stats


@functools.partial(jax.jit, static_argnums=(0, 1, 2), donate_argnums=(3,))
def train_step(config, cam: Camera, pseudo_on: bool, state: TrainState, pools, key):
  """One optimisation step.

  Args:
    config: static Config. cam: static Camera.
    pseudo_on: static; draw pseudo-view rays at this step (Config.pseudo_mix says how).
    state: TrainState.
    pools: {'real': pool, 'random_poses': [P, 3, 4] (depth TV), 'camera_centres' [C, 3]
      (the near-camera penalty), and while pseudo-views
      are used 'mixed' (mixed_pool, pseudo_mix='pixels') or 'pseudo' ('fraction')}.
    key: PRNG key of this step.

  Returns:
    (new state, stats). A non-finite loss or gradient leaves params and optimizer state
    unchanged and increments state.nan_skips.
  """
  k_real, k_pseudo, k_patch, k_render = jax.random.split(key, 4)
  batch, n_pseudo = draw_batch(config, pools, pseudo_on, k_real, k_pseudo)
  batch = jax.lax.with_sharding_constraint(batch, data_sharding())
  patches = None
  if config.depth_tv_loss_mult > 0:
    n_patches = max(config.batch_size_random // config.patch_size**2, 1)
    patches = random_patch_rays(pools['random_poses'], k_patch, n_patches,
                                config.patch_size, cam)
  step = state.step.astype(jnp.float32)
  (_, stats), grads = jax.value_and_grad(loss_fn, has_aux=True)(
      state.params, config, cam, batch, patches, step, k_render,
      pools.get('camera_centres'))
  finite = jnp.isfinite(stats['loss']) & jnp.all(jnp.array(
      [jnp.all(jnp.isfinite(g)) for g in jax.tree_util.tree_leaves(grads)]))
  updates, new_opt = make_optimizer(config).update(grads, state.opt_state, state.params)
  new_params = optax.apply_updates(state.params, updates)
  keep = lambda new, old: jnp.where(finite, new, old)
  stats.update(lr=learning_rate(step, config), finite=finite, pseudo_rays=n_pseudo,
               grad_norm=jnp.sqrt(sum(jnp.sum(g**2) for g in jax.tree_util.tree_leaves(grads))))
  return TrainState(step=state.step + 1,
                    params=jax.tree_util.tree_map(keep, new_params, state.params),
                    opt_state=jax.tree_util.tree_map(keep, new_opt, state.opt_state),
                    nan_skips=state.nan_skips + jnp.where(finite, 0, 1)), stats


def _log_fields(state, stats):
  """The fields of a logged step's record (stats on the host); no progress-bar extras."""
  fields = {'loss': float(stats['loss']), 'psnr': float(stats['psnr']),
            'lr': float(stats['lr']), 'nan_skips': int(state.nan_skips),
            'pseudo_rays': int(stats['pseudo_rays'])}
  for k in ('depth_tv', 'depth_tv_weight', 'occ', 'interlevel', 'distortion',
            'near_camera'):
    if k in stats:
      fields[k] = float(stats[k])
  return fields, None


def train_model(config, scene, out_dir, pools, window=(0, 0), init_params=None,
                eval_fn=None, time_offset: float = 0., desc: str = 'train',
                show_progress: bool = True) -> fit.TrainResult:
  """Trains a fresh model (or resumes the one in out_dir) for config.max_steps steps
  with fit.fit (keys, resume, log and checkpoints are the loop's).

  Args:
    config: Config. scene: Scene (for its camera).
    out_dir: directory of checkpoints and log.jsonl (resumed when checkpoints exist);
      None trains in memory (no checkpoints, no log).
    pools: {'real', optionally 'pseudo', 'random_poses'} (see train_step).
    window: (start, end): pseudo-view rays are sampled for start <= step < end only.
    init_params: start from these parameters instead of a fresh initialisation.
    eval_fn: optional params -> test PSNR (cheap), called every config.eval_every steps.
    time_offset: seconds added to logged times (cumulative time over rounds).
    desc: progress-bar label. show_progress: draw the bar.

  Returns:
    fit.TrainResult.
  """
  cam = Camera.of(scene)
  n_dev = jax.device_count()
  if config.batch_size % n_dev:
    raise ValueError(f'Config.batch_size={config.batch_size} is not divisible by the '
                     f'{n_dev} devices')
  has_pseudo = ('pseudo' in pools or 'mixed' in pools) and window[1] > window[0]
  # Several processes: the pools and keys as global (replicated) arrays; every process
  # draws the same global batch and trains on its shard of it.
  pools = distributed.replicate(pools, replicated_sharding())

  def step_fn(state, pseudo_on, key):
    key = distributed.replicate(key, replicated_sharding())
    return train_step(config, cam, pseudo_on, state, pools, key)

  return fit.fit(config, out_dir, lambda k_init: init_state(config, k_init, init_params),
                 step_fn, _log_fields, window=window if has_pseudo else (0, 0),
                 place=lambda state: jax.device_put(state, replicated_sharding()),
                 eval_fn=eval_fn, time_offset=time_offset, desc=desc,
                 show_progress=show_progress)
