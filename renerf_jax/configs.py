"""Configuration: one frozen, hashable `Config` dataclass set entirely through gin.

The Config is passed as a *static* argument to the jitted steps, so every switch in it
(a disabled regulariser, NDC on/off, the field backbone) decides at trace time which code
exists in the compiled step: switched-off work costs nothing.
"""
import dataclasses
import logging
import os
from typing import Sequence, Tuple

import gin

from renerf_jax.config_checks import check_config
from renerf_jax.errors import ConfigError
from renerf_jax.report import to_jsonable


# What a Config field can change, declared once per field (its `affects` category) and
# read by every rule that decides what may be shared or resumed (see fields_where):
#   baseline   round 0: the baseline's parameters or its reported metrics;
#   pseudo     round r's pseudo-views or masks, given model B;
#   hessian    the Hessian pass of the masks, given B and its training rays;
#   render     the pixels of a pseudo-view rendered at a given pose, given B;
#   resumable  may change between invocations on one run directory.
# Fields without a category ('model': data, model, optimisation, regularisers) change
# everything. Round r >= 1 depends on every field but 'io', 'report', 'rounds' and the
# chunk sizes' speed (D's training: 'd_training').
AFFECTS = {
    'model': ('baseline', 'pseudo', 'hessian', 'render'),
    'report': ('baseline', 'resumable'),  # what is logged and evaluated, not trained
    'io': ('resumable',),  # when checkpoints are written
    'rounds': ('resumable',),  # how many rounds run (each round is the same)
    'd_training': (),  # how D is trained from the pseudo-views
    'pseudo_poses': ('pseudo',),  # which pseudo-views are rendered
    'masks': ('pseudo',),  # whether and how pseudo-view pixels are masked
    'hessian': ('pseudo', 'hessian'),  # the Laplace approximation
    'hessian_chunk': ('pseudo', 'hessian', 'resumable'),  # its summation order
    'render_chunk': ('pseudo', 'render', 'resumable'),  # rendering's batch shapes
}


def _f(default, category: str):
  """A Config field with its `affects` category (a key of AFFECTS)."""
  return dataclasses.field(default=default, metadata={'affects': category})


@gin.configurable()
@dataclasses.dataclass(frozen=True)
class Config:
  """All knobs. Defaults are RegNeRF llff3 values unless a comment says otherwise."""
  # --- data ---
  # 'llff', 'transforms' (Instant-NGP / nerfstudio transforms.json), 'blender' or
  # 'procedural' (the embedded scene).
  dataset_loader: str = 'llff'
  data_dir: str = ''  # Folder that holds the scene folders (e.g. .../nerf_llff_data).
  scene: str = 'fern'  # Scene folder name inside data_dir.
  factor: int = 8  # LLFF image downsampling factor (reads images_<factor>).
  # Extra box-filter downsampling of the loaded images (focal / k, sizes cropped to a
  # multiple of k), for the small CPU table configs; 1: off.
  image_downsample: int = 1
  n_input_views: int = 3  # Few-shot training views (RegNeRF split).
  # transforms.json captures: camera centres moved so the point nearest every optical
  # axis is the origin, then scaled so the farthest camera is at distance 1 (the scene
  # box with them), as mip-NeRF 360 places unbounded scenes for its contraction.
  normalize_poses: bool = False
  llffhold: int = 8  # Every llffhold-th image is a test view.
  # Blender layout (transforms_test.json): every test_stride-th test frame is a test view
  # (the few-shot Blender protocol of DietNeRF / FreeNeRF: 8, i.e. 25 of lego's 200).
  test_stride: int = 1
  # Blender layout: which n_input_views frames of transforms_train.json train.
  # 'standard': the few-shot split of DietNeRF, RegNeRF, FreeNeRF, FSGS and DNGaussian
  # (train ids 26, 86, 2, 55, 75, 93, 16, 73; the first n_input_views of them);
  # 'linspace': evenly spaced over the train frames (this project's split before issue 49).
  blender_split: str = 'standard'
  white_bkgd: bool = False  # Composite on white (Blender).
  use_ndc: bool = True  # NDC space for forward-facing scenes; never for 360 scenes.
  near: float = 0.  # Near plane (NDC: 0).
  far: float = 1.  # Far plane (NDC: 1).
  # (scene, near) pairs: that LLFF scene's per-image near bounds are raised to at least
  # `near` (poses_bounds.npy units) before RegNeRF's scaling by 1 / (0.75 min near).
  # Corrects a capture whose bounds came from spurious near points (the loader warns when
  # bounds look like that); gin_configs/modifiers/shared_bounds.gin has the values measured
  # for ../shared/data's re-processed room and trex. Off: (). Only the pair of
  # Config.scene is kept (so a run of another scene has the same Config with or without
  # the modifier, and its run directory stays reusable): set the scene through gin or the
  # constructor, never with dataclasses.replace (the other scenes' pairs are gone).
  llff_min_near: Tuple[Tuple[str, float], ...] = ()
  procedural_size: Tuple[int, int] = (48, 64)  # (H, W) of the embedded scene.
  procedural_views: int = 17  # Number of images the embedded scene renders.
  # --- optimisation ---
  seed: int = 0  # Seeds the per-step draws (rays, sample jitter, density noise) and,
  # unless init_seed >= 0, the parameters' initialisation.
  init_seed: int = -1  # The initialisation's own seed; -1: Config.seed.
  max_steps: int = 69768  # RegNeRF llff3: 69768.
  batch_size: int = 4096  # Rays per step (real/pseudo views).
  lr_init: float = 2e-3
  lr_final: float = 2e-5
  lr_delay_steps: int = 512
  lr_delay_mult: float = 0.01
  # The log-linear decay lr_init -> lr_final runs over the last (1 - this) of max_steps;
  # before it the lr stays at lr_init (0: over all steps, mip-NeRF's schedule).
  lr_decay_start_frac: float = 0.
  grad_max_norm: float = 0.1  # Clip by global norm (0: off).
  grad_max_val: float = 0.1  # Clip by value (0: off).
  adam_eps: float = 1e-8
  coarse_loss_mult: float = 0.1
  # --- model: sampling ---
  num_samples: int = 128  # Samples per level (coarse and fine).
  num_levels: int = 2  # Coarse + fine, sharing one field.
  resample_padding: float = 0.01
  stop_level_grad: bool = True
  ray_shape: str = 'cylinder'  # 'cone' or 'cylinder'.
  lindisp: bool = False  # Samples evenly spaced in disparity.
  # Unbounded scenes: mip-NeRF 360's spacing, half the samples linear on [near, 1], half
  # in disparity on [1, far] (with the cameras within distance 1 of the scene centre:
  # Config.normalize_poses); overrides lindisp.
  piecewise_spacing: bool = False
  # Unbounded scenes: sample Gaussians contracted into radius 2 before the fields
  # (contraction.py): '' (none), 'l2' (mip-NeRF 360's ball) or 'inf' (nerfacto's cube);
  # set grid_box to ((-2, -2, -2), (2, 2, 2)) with it.
  contraction: str = ''
  randomized: bool = True  # Stratified jitter while training.
  # --- model: field ---
  backbone: str = 'nerf'  # The model family Re-Nerfing runs on (backbones.py): 'nerf' or
  # 'gaussians' (3D Gaussian Splatting, the gs_* fields below).
  field: str = 'mlp'  # 'mlp' (mip-NeRF MLP) or 'grid' (fast multi-resolution grid).
  net_depth: int = 8
  net_width: int = 256
  skip_layer: int = 4
  net_depth_viewdirs: int = 1
  net_width_viewdirs: int = 128
  min_deg_point: int = 0
  max_deg_point: int = 16
  deg_view: int = 4
  use_viewdirs: bool = True
  density_bias: float = -1.
  rgb_padding: float = 0.001
  density_noise: float = 1.  # Std of noise added to raw density in training only.
  density_activation: str = 'softplus'  # 'softplus' (mip-NeRF) or 'exp' (trunc_exp,
  # Instant-NGP; the grid backbone needs it, see model.raw_to_outputs).
  # --- Gaussians backbone (Config.backbone = 'gaussians') ---
  # 3D Gaussian Splatting (Kerbl et al. 2023) at a static capacity (renerf_jax/gaussians).
  # Step counts are fractions of max_steps (3DGS: 30000 steps), so they scale with a run.
  gs_capacity: int = 20000  # Gaussian slots; densification fills the inactive ones.
  gs_init_points: int = 5000  # Random initial Gaussians, uniform in Scene.world_bounds.
  gs_init_opacity: float = 0.1  # Their opacity (3DGS: 0.1).
  gs_init_knn: bool = True  # Their scale: 3DGS's 3-nearest-neighbour distance (else the
  # box spacing, box side / gs_init_points^(1/3)).
  gs_tile_cap: int = 0  # At most this many Gaussians (the nearest) per 16x16 tile; 0: all.
  gs_extent: float = 0.  # Scene extent (lr, densify sizes); 0: 3DGS's 1.1 x camera radius.
  gs_sh_interval_frac: float = 1000 / 30000  # SH degree +1 every this (3DGS: 1000), to 3.
  gs_densify_from_frac: float = 500 / 30000  # Densify after this step (3DGS: 500)...
  gs_densify_until_frac: float = 15000 / 30000  # ... until this one (3DGS: 15000)...
  gs_densify_every_frac: float = 100 / 30000  # ... every this many (3DGS: 100).
  gs_opacity_reset_every_frac: float = 3000 / 30000  # Opacity reset period (3DGS: 3000).
  gs_grad_threshold: float = 5e-4  # Mean view-space gradient to densify at (3DGS: 2e-4;
  # FSGS's few-shot LLFF value 5e-4 here: fewer, better-supported Gaussians from 3 views;
  # DNGaussian uses 1.3e-3).
  gs_min_opacity: float = 0.005  # Prune Gaussians less opaque than this.
  gs_percent_dense: float = 0.01  # Clone below / split above this fraction of the extent.
  gs_lr_means_init: float = 1.6e-4  # Position lr (x the extent), decayed exponentially...
  gs_lr_means_final: float = 1.6e-6  # ... to this at max_steps.
  gs_lr_sh_dc: float = 2.5e-3  # Lr of the SH DC (base colour) coefficients.
  gs_lr_sh_rest: float = 2.5e-3 / 20  # Lr of the higher SH coefficients.
  gs_lr_opacity: float = 0.05  # Lr of the opacity logits.
  gs_lr_scales: float = 5e-3  # Lr of the log scales.
  gs_lr_quats: float = 1e-3  # Lr of the rotations.
  gs_lambda_dssim: float = 0.2  # Loss (1 - l) L1 + l (1 - SSIM).
  gs_background: Tuple[float, float, float] = (0., 0., 0.)  # Background (white_bkgd: white).
  # --- RegNeRF regularisers (0 / False switches a term off: nothing of it is traced) ---
  depth_tv_loss_mult: float = 0.1  # Depth-TV weight after the decay (0: off).
  depth_tv_decay: bool = True  # Log-linear decay from _start to _end over _maxstep.
  depth_tv_mult_start: float = 400.
  depth_tv_mult_end: float = 0.1
  depth_tv_maxstep: int = 512
  n_random_poses: int = 10000  # Unobserved poses for the depth-TV patches.
  batch_size_random: int = 4096  # Rays per step from random poses (64 patches of 8x8).
  patch_size: int = 8
  random_pose_spread: float = 1.2  # Forward-facing: box of camera centres enlarged by this.
  anneal_nearfar: bool = True
  anneal_nearfar_steps: int = 512
  anneal_nearfar_perc: float = 0.0001
  anneal_mid_perc: float = 1.0
  # --- FreeNeRF regularisers (off in llff3.gin, on in llff3_freenerf.gin) ---
  freq_reg: bool = False  # Open the IPE frequency bands linearly...
  freq_reg_end: float = 0.9  # ... until this fraction of max_steps.
  occ_reg_mult: float = 0.  # Occlusion regularisation weight (FreeNeRF: 0.01; 0: off).
  occ_reg_range: int = 20  # Samples nearest to the camera that are penalised.
  # mip-NeRF 360's distortion loss on the last level's weights of every ray rendered in a
  # step (the batch and the random-pose patches); 0: off (nothing computed).
  distortion_loss_mult: float = 0.
  # A near-camera density penalty (regularizers.near_camera_weight): the batch's mean
  # rendering weight within near_camera_radius (world units) of a training camera's
  # centre, times this (0: off, nothing computed). Needs use_ndc = False.
  near_camera_loss_mult: float = 0.
  near_camera_radius: float = 0.15
  # --- grid backbone (Config.field = 'grid') ---
  grid_levels: int = 12  # Resolution levels of the multi-resolution grid.
  grid_base_res: int = 16  # Coarsest resolution (vertices per axis - 1).
  grid_max_res: int = 512  # Finest resolution.
  grid_features: int = 2  # Features per level.
  grid_log2_hashmap_size: int = 17  # Entries per level when hashed (2^n); dense if smaller.
  grid_mlp_width: int = 64  # Width of the tiny density / colour MLPs.
  grid_init_scale: float = 1e-4  # Uniform init range of the tables.
  grid_box: Tuple[Tuple[float, ...], Tuple[float, ...]] = ((-1., -1., -1.), (1., 1., 1.))
  # Box the grid covers: the NDC cube for LLFF; about +-1.5 for NeRF-synthetic.
  outside_box: str = 'clamp'  # Density at samples outside grid_box: 'clamp' (the fields
  # clamp the point onto the box's faces: LLFF's NDC rays leave the box sideways) or
  # 'empty' (0: a bounded scene's box holds it all, as Instant-NGP's aabb; lego8.gin).
  # --- sampler ---
  sampler: str = 'coarse_fine'
  # 'coarse_fine' (mip-NeRF: every level renders colour with the one field, the coarse
  # level weighted by coarse_loss_mult) or 'proposal' (mip-NeRF 360 / nerfacto: level 0
  # samples a tiny density-only grid, fields/proposal.py, trained by the interlevel loss;
  # only the last level renders colour). 'proposal' needs num_levels = 2.
  proposal_samples: int = 64  # Samples of the proposal level ('proposal' only).
  proposal_levels: int = 5  # Grid levels of the proposal field (grid_base_res upwards).
  proposal_max_res: int = 128  # Its finest resolution.
  proposal_log2_hashmap_size: int = 17  # Its entries per level when hashed (2^n).
  proposal_mlp_width: int = 16  # Hidden width of its density MLP.
  interlevel_loss_mult: float = 1.  # Weight of the proposal's interlevel loss.
  # --- Re-Nerfing ---
  num_rounds: int = _f(0, 'rounds')
  # Re-Nerfing rounds after the baseline (0: baseline only).
  pseudo_mix: str = _f('pixels', 'd_training')
  # How D draws rays while the pseudo-views are on: 'pixels' (the paper: they are "part of
  # the training images": rays uniform over every usable pixel of the real and the
  # pseudo-views together; masked pseudo pixels are never drawn) or 'fraction' (a fixed
  # pseudo_frac of each batch from the pseudo-views, masked pixels drawn with weight 0).
  pseudo_frac: float = _f(0.5, 'd_training')  # The pseudo share with pseudo_mix='fraction'.
  pseudo_until_frac: float = _f(0.072, 'd_training')
  # K as a fraction of max_steps: pseudo-view rays only for steps < K (RegNeRF's MLP:
  # 5000 / 69768 = 7.2%; the grid configs set their own). Never before the near/far
  # annealing ends.
  pseudo_schedule: str = _f('early', 'd_training')
  # Table "why": 'early' (steps < K, the method), 'all'
  # (keep to the end) or 'late' (only the last K steps).
  renerf_init: str = _f('reset', 'd_training')
  # 'reset' (D from scratch, the method) or 'continue' (from B).
  d_seed: str = _f('offset', 'd_training')
  # D's seed in round r (renerf.round_config): 'offset' (seed + 1000 r for its
  # initialisation and its draws: a model as different from B as another seed), 'same_init'
  # (B's initialisation, draws from seed + 1000 r) or 'same' (B's seed for both: D differs
  # from B only by the pseudo-views, so D without pseudo-views is B bit for bit).
  interp_factors: str = _f('7x', 'pseudo_poses')
  # Preset name (2x, 3x, 3x_b, 3x_c, 4x, 5x, 7x, 11x) or
  # comma-separated factors, e.g. '0.25,0.5'.
  sequencing: str = _f('position', 'pseudo_poses')
  # Neighbour sequencing: ordered, position or rotation.
  pseudo_targets: str = _f('interp', 'pseudo_poses')
  # 'interp', 'test' (test poses), 'random' or a
  # '+' combination such as 'interp+test'.
  pseudo_n_random: int = _f(4, 'pseudo_poses')
  # Random unobserved poses for pseudo_targets 'random'.
  pseudo_source: str = _f('render', 'pseudo_poses')
  # 'render' (B's renders: Re-Nerfing) or 'photo' (the oracle: the real photos at the
  # unused views, with pseudo_targets 'unused').
  # --- Laplace uncertainty (Bayes' Rays style) and masks ---
  use_masks: bool = _f(False, 'masks')
  # Mask uncertain pseudo-view pixels (with mask_signal 'laplace': after the Hessian pass).
  mask_signal: str = _f('one_minus_acc', 'masks')
  # The uncertainty the masks threshold: a Hessian-free signal of one render,
  # 'one_minus_acc' (the default: the lowest mean AUSE over six scenes),
  # 'depth_variance', 'weight_entropy' (renerf_jax/uncertainty/signals.py), or 'laplace'
  # (the Bayes'-Rays-style Hessian pass below).
  # experiments/results/uncertainty_quality_llff/uq_tiny.md compares them.
  deform_log2_res: int = _f(8, 'hessian')
  # L: the deformation grid has (2^L + 1)^3 vertices.
  hessian_rays: int = _f(65536, 'hessian')  # R: training rays in the Hessian pass.
  hessian_lambda: float = _f(1e-4, 'hessian')
  # Prior precision lambda (keeps Sigma finite).
  hessian_chunk: int = _f(1024, 'hessian_chunk')
  # Rays per jitted chunk of the Hessian pass (memory vs speed).
  mask_keep_frac: float = _f(0.8, 'masks')
  # Keep this fraction of pseudo pixels (mu by bisection)...
  mask_threshold: float = _f(-1., 'masks')
  # ... unless >= 0: absolute mu on the uncertainty.
  # --- logging, evaluation, checkpoints ---
  print_every: int = _f(100, 'report')
  eval_every: int = _f(500, 'report')  # Steps between cheap test PSNR evaluations (0: off).
  eval_n_views: int = _f(3, 'report')  # Test views in the cheap evaluation.
  eval_stride: int = _f(4, 'report')
  # Pixel stride of the cheap evaluation (1: full images).
  checkpoint_every: int = _f(1000, 'io')
  render_chunk: int = _f(4096, 'render_chunk')  # Rays per chunk when rendering full images.
  lpips_nets: Tuple[str, ...] = _f(('alex', 'vgg'), 'report')

  def __post_init__(self):
    check_config(self)


def field_category(name: str) -> str:
  """The `affects` category of Config field `name` ('model' when undeclared)."""
  return Config.__dataclass_fields__[name].metadata.get('affects', 'model')


def fields_where(effect: str, present: bool = True) -> Tuple[str, ...]:
  """Names of the Config fields whose category has (or, present=False, lacks) `effect`.

  Args:
    effect: 'baseline', 'pseudo', 'hessian', 'render' or 'resumable'.
    present: select the fields with the effect (True) or without it (False).

  Returns:
    Field names in declaration order.
  """
  return tuple(f.name for f in dataclasses.fields(Config)
               if (effect in AFFECTS[field_category(f.name)]) == present)


def config_differences(config, saved: dict, ignore=()) -> list:
  """Names of the fields outside `ignore` in which `config` and a saved config.json
  differ; a field missing from `saved` (added to Config later) counts as its default."""
  current = to_jsonable(dataclasses.asdict(config))
  defaults = to_jsonable(dataclasses.asdict(type(config)()))
  saved = dict({k: v for k, v in defaults.items() if k not in saved}, **saved)
  return sorted(k for k in set(saved) | set(current)
                if k not in ignore and saved.get(k) != current.get(k))


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


def _set_gin_search_path(folders: Sequence[str]):
  """gin's `include` searches the working directory, then `folders` in this order (and
  nothing an earlier load_config added)."""
  folders = list(dict.fromkeys(folders))
  prefixes = getattr(gin.config, '_LOCATION_PREFIXES', None)
  if isinstance(prefixes, list):
    prefixes[:] = [''] + folders
  else:  # A gin without the list: add what is missing.
    for folder in folders:
      gin.add_config_file_search_path(folder)


def load_config(gin_configs: Sequence[str] = (), gin_bindings: Sequence[str] = ()) -> Config:
  """Parses gin files and bindings and returns the Config.

  Args:
    gin_configs: paths of .gin files; a path that does not exist as given is looked up
      in the repository's gin_configs/ (resolve_gin_config), so `llff3.gin` or `llff3`
      works from any directory.
    gin_bindings: binding strings.

  Returns:
    Config.

  Raises:
    ConfigError: naming the missing file or the bad binding.
  """
  files = [resolve_gin_config(path) for path in gin_configs]
  gin.clear_config()
  # `include 'x.gin'` resolves next to the including file, then in gin_configs/.
  _set_gin_search_path([os.path.dirname(os.path.abspath(p)) for p in files]
                       + [GIN_CONFIGS_DIR])
  try:
    gin.parse_config_files_and_bindings(files, list(gin_bindings), skip_unknown=False)
    return Config()
  except (ValueError, KeyError, SyntaxError, TypeError, AttributeError, IOError) as e:
    if isinstance(e, ConfigError):
      raise ConfigError(str(e).splitlines()[0]) from None
    first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
    where = ', '.join(list(gin_configs) + [repr(b) for b in gin_bindings])
    raise ConfigError(f'bad gin configuration ({where}): {first}') from None
  finally:
    # The Config is the only product: no binding may leak into later Config() calls.
    gin.clear_config()


def config_to_gin(config: Config) -> str:
  """The Config as a gin file of bindings that reproduces it exactly."""
  return '\n'.join(f'Config.{f.name} = {getattr(config, f.name)!r}'
                    for f in dataclasses.fields(config)) + '\n'
