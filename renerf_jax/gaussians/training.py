"""Training a Gaussian scene as 3DGS does (Kerbl et al. 2023), at static shapes.

One whole image per step, drawn uniformly from the real training views and, inside the
pseudo-view window, from the real and the pseudo-views together (the pseudo-views "join
the real views as images drawn uniformly"); the loss is (1 - l) L1 + l (1 - SSIM) with
per-pixel masks; per-parameter Adam learning rates (the position's decayed exponentially
and scaled by the scene extent); the SH degree raised every `gs_sh_interval_frac` of the
run (schedule.py); adaptive density control by the densification strategy
(strategy.py: statistics inside the step, growing, pruning and opacity resets between
steps); the loss is loss.py's. `train_gaussians` runs renerf_jax.fit.fit, the loop of
both backbones: atomic checkpoints, bit-for-bit resume, the JSONL log, the evaluation
curve and the progress bar. With several processes
(renerf_jax.distributed) every process runs the same step on the same image (one image
a step has no batch to split; the state stays on each process's own device), and the
renders of whole views are split across processes (render_views).

The jitted step is `train_step(config, cam, pseudo_on, state, data, key)` with (config,
cam, pseudo_on) static: two compiled variants, with and without the pseudo-views. The SH
degree is traced (coefficients above it are multiplied by 0, so they get zero gradients
and stay 0 under Adam, as in the reference), so raising it does not recompile.
"""
import dataclasses
import functools
from typing import Any

import flax
import jax
import jax.numpy as jnp
import numpy as np
import optax

from renerf_jax import distributed, fit, metrics
from renerf_jax.errors import DataError
from renerf_jax.gaussians import density
from renerf_jax.gaussians import dropout
from renerf_jax.gaussians import params as params_lib
from renerf_jax.gaussians import render as render_lib
from renerf_jax.gaussians.loss import image_loss
from renerf_jax.gaussians.schedule import make_optimizer, means_lr, set_means_lr, sh_degree_at
from renerf_jax.gaussians.start import init_gaussians
from renerf_jax.gaussians.strategy import DensityStrategy
from renerf_jax.progress import progress_bar

NEAR = 0.2  # Gaussians nearer than this depth are culled (the reference's frustum test).
TILE = 16


@flax.struct.dataclass
class GaussianTrainState:
  step: jnp.ndarray  # int32 scalar: optimisation steps taken.
  params: params_lib.Gaussians
  opt_state: Any  # optax state of the schedule.FIELDS dict (see to_fields).
  nan_skips: jnp.ndarray  # int32 scalar: steps skipped for a non-finite loss/gradient.
  stats: density.DensityStats  # The densification strategy's state (its statistics).
  dropped: jnp.ndarray  # int32 scalar: densification candidates that found no free slot.
  pseudo_images: jnp.ndarray  # int32 scalar: steps that drew a pseudo-view.


@dataclasses.dataclass(frozen=True)
class Camera:
  """Static pinhole camera of a scene (shared by all its views)."""
  h: int
  w: int
  focal: float

  @classmethod
  def of(cls, scene):
    """The scene's camera; DataError for cameras other than the centred pinhole."""
    if getattr(scene, 'intrinsics', None) is not None:
      raise DataError(f'scene {scene.name!r}: the Gaussians render centred pinhole '
                      f'cameras; its cameras have intrinsics (fx, fy, cx, cy, k1, k2, '
                      f'p1, p2) = {tuple(round(float(v), 4) for v in scene.intrinsics)}')
    return cls(scene.height, scene.width, float(scene.focal))


# ------------------------------------------------------------------------- parameters


def to_fields(gaussians):
  """The optimised fields of Gaussians as a dict (sh split into sh_dc and sh_rest)."""
  g = gaussians
  return {'means': g.means, 'log_scales': g.log_scales, 'quats': g.quats,
          'opacity_logits': g.opacity_logits, 'sh_dc': g.sh[:, :1], 'sh_rest': g.sh[:, 1:]}


def from_fields(fields, active):
  """Inverse of to_fields."""
  return params_lib.Gaussians(
      means=fields['means'], log_scales=fields['log_scales'], quats=fields['quats'],
      opacity_logits=fields['opacity_logits'],
      sh=jnp.concatenate([fields['sh_dc'], fields['sh_rest']], axis=1), active=active)


def init_params(config):
  """A zero template of config.gs_capacity slots (all inactive): deserialising a round."""
  n = config.gs_capacity
  return params_lib.Gaussians(
      means=jnp.zeros((n, 3), jnp.float32), log_scales=jnp.zeros((n, 3), jnp.float32),
      quats=jnp.zeros((n, 4), jnp.float32), opacity_logits=jnp.zeros((n,), jnp.float32),
      sh=jnp.zeros((n, params_lib.NUM_SH, 3), jnp.float32), active=jnp.zeros((n,), bool))


def scene_extent(config, scene):
  """The scene extent of the learning rates and the densification sizes.

  Config.gs_extent when > 0, else 3DGS's: 1.1 x the largest distance of a training
  camera centre from their mean (1.0 with a single training view).
  """
  if config.gs_extent > 0:
    return float(config.gs_extent)
  centres = np.asarray(scene.poses, np.float64)[np.asarray(scene.train_idx), :3, 3]
  radius = 1.1 * float(np.max(np.linalg.norm(centres - centres.mean(0), axis=-1)))
  return radius if radius > 0 else 1.


def strong_types(tree):
  """Copies of a pytree's arrays without weak types (params.random_init's opacities
  are weakly typed; a step's outputs are not, and a change would recompile the step)."""
  return jax.tree_util.tree_map(lambda x: jnp.array(x, dtype=jnp.asarray(x).dtype), tree)


def init_state(config, params, extent) -> GaussianTrainState:
  """A fresh train state of the given Gaussians (own, strongly typed copies)."""
  params = strong_types(params)
  opt_state = make_optimizer(config, extent).init(to_fields(params))
  zero = lambda: jnp.zeros((), jnp.int32)  # Distinct buffers: the steps donate them.
  return GaussianTrainState(step=zero(), params=params, opt_state=opt_state,
                            nan_skips=zero(),
                            stats=DensityStrategy.of(config).initialize_state(
                                params.means.shape[0]),
                            dropped=zero(), pseudo_images=zero())


# ------------------------------------------------------------------------- loss, step


def sh_mask(degree):
  """[16, 1] float: 1 for the coefficients of SH degree <= `degree` (traced int)."""
  return (jnp.arange(params_lib.NUM_SH) < (degree + 1)**2).astype(jnp.float32)[:, None]


def background(config):
  """[3] render background: white where the images are composited on white
  (Config.white_bkgd, Blender), else Config.gs_background."""
  if config.white_bkgd:
    return jnp.ones(3, jnp.float32)
  return jnp.asarray(config.gs_background, jnp.float32)


def render_for_loss(config, cam, params, fields, offset, pose, degree, opacity_scale=None):
  """Render of the Gaussians `fields` (active as params) at pose with SH degree `degree`
  (opacities x opacity_scale where given: DropGaussian's factors)."""
  g = from_fields(fields, params.active)
  g = g.replace(sh=g.sh * sh_mask(degree))
  return render_lib.render(g, pose, cam.focal, cam.h, cam.w, 3, background(config),
                           config.gs_tile_cap, NEAR, TILE, means2d_offset=offset,
                           capacity=config.gs_list_capacity, opacity_scale=opacity_scale)


def loss_and_grads(config, cam, params, image, pose, mask, degree, opacity_scale=None):
  """Loss, its gradients and the screen-space gradients of one image.

  Args:
    config, cam: static. params: Gaussians. image: [H, W, 3]. pose: [3, 4].
    mask: [H, W] pixel weights. degree: SH degree (traced int).
    opacity_scale: optional [N] opacity factors (dropout.opacity_scale); None: none.

  Returns:
    (loss, mse, render dict, grads {field: array} (to_fields layout), grad2d [N, 2]).
  """
  fields = to_fields(params)
  offset = jnp.zeros((params.means.shape[0], 2), params.means.dtype)

  def fn(fields, offset):
    out = render_for_loss(config, cam, params, fields, offset, pose, degree,
                          opacity_scale)
    loss, mse = image_loss(out['rgb'], image, mask, config.gs_lambda_dssim)
    return loss, (mse, out)

  (loss, (mse, out)), (grads, grad2d) = jax.value_and_grad(fn, argnums=(0, 1),
                                                           has_aux=True)(fields, offset)
  return loss, mse, out, grads, grad2d


@functools.partial(jax.jit, static_argnums=(0, 1, 2), donate_argnums=(3,))
def train_step(config, cam: Camera, pseudo_on: bool, state: GaussianTrainState, data,
               extent, key):
  """One optimisation step on one image.

  Args:
    config: static Config. cam: static Camera.
    pseudo_on: static; `data` holds the pseudo-views after the real views (only a flag
      for the compiled variant: the draw is uniform over data's images either way).
    state: GaussianTrainState.
    data: {'images' [V, H, W, 3], 'poses' [V, 3, 4], 'masks' [V, H, W],
      'is_pseudo' [V] bool}.
    extent: scene extent (scalar).
    key: PRNG key of this step.

  Returns:
    (new state, stats). A non-finite loss or gradient leaves params and optimizer state
    unchanged and increments state.nan_skips; an image with no pixel weight (an all-zero
    mask) leaves them unchanged too (nothing to learn from it). With Config.gs_drop_rate
    > 0 the render drops Gaussians (dropout.py) with a key split from `key`; at 0 the
    key is used as is and nothing of the dropout is traced.
  """
  del pseudo_on  # The variants differ in data's shapes.
  iteration = state.step + 1
  params = state.params
  scale = None
  if config.gs_drop_rate > 0.:
    key, key_drop = jax.random.split(key)
    scale = dropout.opacity_scale(key_drop, params.means.shape[0],
                                  dropout.drop_rate_at(iteration, config))
  n_views = data['images'].shape[0]
  idx = jax.random.randint(key, (), 0, n_views)
  image, pose, mask = data['images'][idx], data['poses'][idx], data['masks'][idx]
  degree = sh_degree_at(iteration, config)
  loss, mse, out, grads, grad2d = loss_and_grads(config, cam, params, image, pose, mask,
                                                 degree, scale)
  finite = (jnp.isfinite(loss) & jnp.all(jnp.isfinite(grad2d)) & jnp.all(jnp.array(
      [jnp.all(jnp.isfinite(g)) for g in jax.tree_util.tree_leaves(grads)])))
  informative = jnp.sum(mask) > 0.
  apply = finite & informative
  lr = means_lr(iteration.astype(jnp.float32), config, extent)
  fields = to_fields(params)
  opt_state = set_means_lr(state.opt_state, lr)
  updates, new_opt = make_optimizer(config, extent).update(grads, opt_state, fields)
  new_fields = optax.apply_updates(fields, updates)
  keep = lambda new, old: jnp.where(apply, new, old)
  new_fields = jax.tree_util.tree_map(keep, new_fields, fields)
  new_opt = jax.tree_util.tree_map(keep, new_opt, state.opt_state)
  stats = DensityStrategy.of(config).update_state(state.stats, grad2d, out['radius'],
                                                  cam.h, cam.w, iteration, apply)
  is_pseudo = data['is_pseudo'][idx]
  step_stats = {'loss': loss, 'mse': mse, 'psnr': metrics.mse_to_psnr(mse), 'lr': lr,
                'finite': finite, 'sh_degree': degree, 'cap_bound': out['cap_bound'],
                'image': idx, 'is_pseudo': is_pseudo,
                'pseudo_rays': jnp.where(is_pseudo, jnp.sum(mask), 0.)}
  new_state = GaussianTrainState(
      step=iteration, params=from_fields(new_fields, params.active), opt_state=new_opt,
      nan_skips=state.nan_skips + jnp.where(finite, 0, 1), stats=stats,
      dropped=state.dropped, pseudo_images=state.pseudo_images + is_pseudo.astype(
          jnp.int32))
  return new_state, step_stats


def training_data(scene, pseudo=None):
  """Device arrays of the views a step draws from: the real training views, then the
  pseudo-views (masks of real views are all ones)."""
  idx = np.asarray(scene.train_idx)
  n = len(idx)
  data = {'images': jnp.asarray(scene.images[idx], jnp.float32),
          'poses': jnp.asarray(scene.poses[idx], jnp.float32),
          'masks': jnp.ones((n, scene.height, scene.width), jnp.float32),
          'is_pseudo': jnp.zeros((n,), bool)}
  if pseudo is None:
    return data
  m = pseudo.images.shape[0]
  extra = {'images': jnp.asarray(pseudo.images, jnp.float32),
           'poses': jnp.asarray(pseudo.poses, jnp.float32),
           'masks': jnp.asarray(pseudo.masks, jnp.float32),
           'is_pseudo': jnp.ones((m,), bool)}
  return jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), data, extra)


# ------------------------------------------------------------------------- the loop


def _log_fields(state, stats):
  """The fields of a logged step's record (stats on the host) and the bar's count."""
  n = int(jnp.sum(state.params.active))
  return {'loss': float(stats['loss']), 'psnr': float(stats['psnr']),
          'lr': float(stats['lr']), 'nan_skips': int(state.nan_skips),
          'pseudo_rays': int(stats['pseudo_rays']),
          'pseudo_images': int(state.pseudo_images), 'num_gaussians': n,
          'cap_bound': float(stats['cap_bound']), 'dropped': int(state.dropped),
          'sh_degree': int(stats['sh_degree'])}, {'n': n}


def train_gaussians(config, scene, out_dir, pseudo, window=(0, 0), init_params=None,
                    eval_fn=None, time_offset: float = 0., desc: str = 'train',
                    show_progress: bool = True) -> fit.TrainResult:
  """Trains a fresh Gaussian scene (or resumes the one in out_dir) for max_steps steps
  with fit.fit, the densification strategy between steps.

  Args:
    config: Config. scene: Scene (images, poses, camera, world box).
    out_dir: directory of checkpoints and log.jsonl (resumed when checkpoints exist);
      None trains in memory (no checkpoints, no log).
    pseudo: None or a pseudo_views.PseudoViews (images, poses, masks).
    window: (start, end): pseudo-views are drawn for start <= step < end only.
    init_params: start from these Gaussians instead of a random initialisation.
    eval_fn: optional Gaussians -> test PSNR (cheap), called every config.eval_every
      steps.
    time_offset: seconds added to logged times (cumulative time over rounds).
    desc: progress-bar label. show_progress: draw the bar.

  Returns:
    fit.TrainResult whose state is a GaussianTrainState.
  """
  cam = Camera.of(scene)
  extent = scene_extent(config, scene)
  extent_arr = jnp.asarray(extent, jnp.float32)
  has_pseudo = pseudo is not None and window[1] > window[0]
  strategy = DensityStrategy.of(config)

  def fresh_state(k_init):
    params = init_gaussians(config, scene, k_init) if init_params is None else init_params
    return init_state(config, params, extent)

  data = {False: training_data(scene)}
  if has_pseudo:
    data[True] = training_data(scene, pseudo)

  def step_fn(state, pseudo_on, key):  # The densification draws from split(key)[1].
    return train_step(config, cam, pseudo_on, state, data[pseudo_on], extent_arr,
                      jax.random.split(key)[0])

  # place: own copies, since the jitted steps donate the state, never the caller's
  # init_params.
  return fit.fit(config, out_dir, fresh_state, step_fn, _log_fields,
                 window=window if has_pseudo else (0, 0), place=strong_types,
                 after_step=lambda state, done, key: strategy.step_post_backward(
                     state, done, extent_arr, key),
                 eval_fn=eval_fn, time_offset=time_offset, desc=desc,
                 show_progress=show_progress)


# ------------------------------------------------------------------------- rendering


@functools.partial(jax.jit, static_argnums=(0, 1))
def _render_one(config, cam, params, pose):
  out = render_lib.render(params, pose, cam.focal, cam.h, cam.w, 3, background(config),
                          config.gs_tile_cap, NEAR, TILE,
                          capacity=config.gs_list_capacity)
  acc = out['acc']
  depth = jnp.where(acc > 0., out['depth'] / jnp.where(acc > 0., acc, 1.), 0.)
  return {'rgb': out['rgb'], 'depth': depth, 'acc': acc}


def render_views(config, scene, params, poses, show_progress=False):
  """Renders the Gaussians at camera poses with SH degree 3 and the config's background.

  With several processes each renders every P-th view; all get every view.

  Args:
    config: Config. scene: Scene (its camera). params: Gaussians. poses: [N, 3, 4].
    show_progress: draw a progress bar.

  Returns:
    {'rgb': [N, H, W, 3], 'depth': [N, H, W] expected depth (weighted depth / acc where
    acc > 0, else 0), 'acc': [N, H, W]} numpy float32.
  """
  cam = Camera.of(scene)
  poses = np.asarray(poses, np.float32)
  params = distributed.local(params)
  bar = progress_bar(total=len(poses), desc='render', disable=not show_progress,
                     unit='view')

  def render(k):
    out = jax.device_get(_render_one(config, cam, params, jnp.asarray(poses[k])))
    bar.update(1)
    return out
  outs = distributed.map_shares(render, len(poses))  # Each process renders its share.
  bar.close()
  if not outs:
    return {'rgb': np.zeros((0, cam.h, cam.w, 3), np.float32),
            'depth': np.zeros((0, cam.h, cam.w), np.float32),
            'acc': np.zeros((0, cam.h, cam.w), np.float32)}
  return {k: np.stack([np.asarray(o[k], np.float32) for o in outs]) for k in outs[0]}
