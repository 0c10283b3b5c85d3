"""Configuration: one frozen, hashable `Config` dataclass set entirely through gin.

The Config is passed as a *static* argument to the jitted steps, so every switch in it
(a disabled regulariser, NDC on/off, the field backbone) decides at trace time which code
exists in the compiled step: switched-off work costs nothing.

Each field belongs to one concern (config_fields.GROUPS: shared, NeRF, Gaussians,
Re-Nerfing, evaluation / logging / IO) and says which backbone reads it; a field the
chosen `Config.backbone` ignores, set away from its default, is refused
(config_checks.check_backbone_fields). docs/configs.md lists the fields by concern.
"""
import dataclasses
import os
from typing import Sequence, Tuple, Union

import gin

from renerf_jax.config_checks import check_config
from renerf_jax.config_domains import BOX, FACTORS, MIN_NEAR, NUM_ROUNDS, TARGETS
from renerf_jax.config_fields import AFFECTS, fields_with, ignored_by  # pylint: disable=unused-import
from renerf_jax.config_fields import config_differences  # pylint: disable=unused-import
from renerf_jax.config_fields import gaussians, nerf, renerf, report, shared
from renerf_jax.errors import ConfigError
from renerf_jax.gin_files import GIN_CONFIGS_DIR, resolve_gin_config, set_gin_search_path


@gin.configurable()
@dataclasses.dataclass(frozen=True)
class Config:
  """All knobs. Defaults are RegNeRF llff3 values unless a comment says otherwise.

  Each field is declared by its concern (shared, nerf, gaussians, renerf, report: see
  config_fields), which records the backbone that reads it and what it can change
  (`affects`). Declaration order = the order of a run directory's config.gin and
  config.json, kept as it was (a few shared fields sit in another concern's block).
  """
  # --- shared: data and split ---
  # 'llff', 'transforms' (Instant-NGP / nerfstudio transforms.json), 'colmap' (sparse/0),
  # 'blender', 'procedural' (embedded forward-facing) or 'orbit' (embedded 360 degrees).
  dataset_loader: str = shared('llff', 'llff|transforms|colmap|blender|procedural|orbit')
  # Folder that holds the scene folders (e.g. .../nerf_llff_data).
  data_dir: str = shared('', 'text')
  scene: str = shared('fern', 'name')  # Scene folder name inside data_dir.
  factor: int = shared(8, '>=1')  # LLFF downsampling factor (reads images_<factor>).
  # Extra box-filter downsampling of the loaded images (focal / k, sizes cropped to a
  # multiple of k), for the small CPU table configs; 1: off.
  image_downsample: int = shared(1, '>=1')
  n_input_views: int = shared(3, '>=1')  # Few-shot training views (RegNeRF split).
  # transforms.json captures: camera centres moved so the point nearest every optical
  # axis is the origin, then scaled so the farthest camera is at distance 1 (the scene
  # box with them), as mip-NeRF 360 places unbounded scenes for its contraction.
  normalize_poses: bool = shared(False)
  # transforms.json: distorted or off-centre photos resampled to a centred pinhole camera
  # of their size, the uncovered border cropped (datasets/undistort.py, as COLMAP does):
  # the Gaussians render centred pinhole cameras only.
  undistort: bool = shared(False)
  llffhold: int = shared(8, '>=1')  # Every llffhold-th image is a test view.
  # Captures: how the n_input_views training views are chosen from the non-test photos,
  # 'linspace' (evenly by index) or 'coverage' (the paper's mip-NeRF 360 split: farthest
  # cameras first); and val_views validation views from the photos neither split uses
  # (datasets/split.py). Blender's layout: blender_split, and val from transforms_val.json.
  train_view_selection: str = shared('linspace', 'linspace|coverage')
  val_views: int = shared(0, '>=0')
  leave_out_view: int = shared(-1, '>=-1')  # Issue 64's probe (split.leave_out_view).
  # Blender layout (transforms_test.json): every test_stride-th test frame is a test view
  # (the few-shot Blender protocol of DietNeRF / FreeNeRF: 8, i.e. 25 of lego's 200).
  test_stride: int = shared(1, '>=1')
  # Blender layout: which n_input_views frames of transforms_train.json train. 'standard':
  # the few-shot split of DietNeRF ... DNGaussian (train ids 26, 86, 2, 55, 75, 93, 16,
  # 73, the first n_input_views); 'linspace': evenly spaced (before issue 49).
  blender_split: str = shared('standard', 'standard|linspace')
  white_bkgd: bool = shared(False)  # Composite on white (Blender).
  # NDC space for forward-facing scenes; never for 360 scenes.
  use_ndc: bool = shared(True)
  near: float = shared(0., '>=0')  # Near plane (NDC: 0).
  far: float = shared(1., '>0')  # Far plane (NDC: 1).
  # (scene, near) pairs: that LLFF scene's near bounds raised to at least `near` (before
  # RegNeRF's scaling), for bounds from spurious near points (modifiers/shared_bounds.gin:
  # room, trex). Off: (). Only Config.scene's pair is kept (a run of another scene stays
  # reusable): set the scene through gin, never with dataclasses.replace.
  llff_min_near: Tuple[Tuple[str, float], ...] = shared((), MIN_NEAR)
  procedural_size: Tuple[int, int] = shared((48, 64), '>=1')  # Embedded scenes' (H, W).
  procedural_views: int = shared(17, '>=1')  # Number of images an embedded scene renders.
  # --- shared: seeds and steps ---
  # Seeds the per-step draws (rays, sample jitter, density noise, the Gaussians' image
  # draws) and, unless init_seed >= 0, the parameters' initialisation.
  seed: int = shared(0, '>=0')
  init_seed: int = shared(-1, '>=-1')  # The initialisation's own seed; -1: Config.seed.
  max_steps: int = shared(69768, '>0')  # RegNeRF llff3: 69768.
  # --- NeRF: optimisation ---
  batch_size: int = nerf(4096, '>0')  # Rays per step (real/pseudo views).
  lr_init: float = nerf(2e-3, '>0')
  lr_final: float = nerf(2e-5, '>0')
  lr_delay_steps: int = nerf(512, '>=0')
  lr_delay_mult: float = nerf(0.01, '[0,1]')
  # The log-linear decay lr_init -> lr_final runs over the last (1 - this) of max_steps;
  # before it the lr stays at lr_init (0: over all steps, mip-NeRF's schedule).
  lr_decay_start_frac: float = nerf(0., '[0,1)')
  grad_max_norm: float = nerf(0.1, '>=0')  # Clip by global norm (0: off).
  grad_max_val: float = nerf(0.1, '>=0')  # Clip by value (0: off).
  adam_eps: float = nerf(1e-8, '>0')
  coarse_loss_mult: float = nerf(0.1, '>=0')
  # --- NeRF: sampling ---
  num_samples: int = nerf(128, '>=2')  # Samples per level (coarse and fine).
  num_levels: int = nerf(2, '>=1')  # Coarse + fine, sharing one field.
  resample_padding: float = nerf(0.01, '>=0')
  stop_level_grad: bool = nerf(True)
  ray_shape: str = nerf('cylinder', 'cone|cylinder')  # 'cone' or 'cylinder'.
  lindisp: bool = nerf(False)  # Samples evenly spaced in disparity.
  # Unbounded scenes: mip-NeRF 360's spacing, half the samples linear on [near, 1], half
  # in disparity on [1, far] (with the cameras within distance 1 of the scene centre:
  # Config.normalize_poses); overrides lindisp.
  piecewise_spacing: bool = nerf(False)
  # Unbounded scenes: sample Gaussians contracted into radius 2 before the fields
  # (contraction.py): '' (none), 'l2' (mip-NeRF 360's ball) or 'inf' (nerfacto's cube);
  # set grid_box to ((-2, -2, -2), (2, 2, 2)) with it.
  contraction: str = nerf('', ('', 'l2', 'inf'))
  randomized: bool = nerf(True)  # Stratified jitter while training.
  # --- shared: the backbone ---
  # The model family Re-Nerfing runs on (backbones.py): 'nerf' (the NeRF fields) or
  # 'gaussians' (3D Gaussian Splatting, the gs_* fields below).
  backbone: str = shared('nerf', 'nerf|gaussians')
  # --- NeRF: field ---
  field: str = nerf('mlp', 'mlp|grid')  # mip-NeRF's MLP or a fast multi-resolution grid.
  net_depth: int = nerf(8, '>=1')
  net_width: int = nerf(256, '>=1')
  skip_layer: int = nerf(4, '>=1')
  net_depth_viewdirs: int = nerf(1, '>=0')
  net_width_viewdirs: int = nerf(128, '>=1')
  min_deg_point: int = nerf(0, '>=0')
  max_deg_point: int = nerf(16, '>=0')
  deg_view: int = nerf(4, '>=0')
  use_viewdirs: bool = nerf(True)
  density_bias: float = nerf(-1., 'any')
  rgb_padding: float = nerf(0.001, '>=0')
  density_noise: float = nerf(1., '>=0')  # Std of the raw density's noise in training.
  # 'softplus' (mip-NeRF) or 'exp' (trunc_exp, Instant-NGP; the grid backbone needs it,
  # see model.raw_to_outputs).
  density_activation: str = nerf('softplus', 'softplus|exp')
  # --- Gaussians (Config.backbone = 'gaussians') ---
  # 3D Gaussian Splatting (Kerbl et al. 2023) at a static capacity (renerf_jax/gaussians).
  # Step counts are fractions of max_steps (3DGS: 30000 steps), so they scale with a run.
  gs_capacity: int = gaussians(20000, '>=1')  # Slots; densification fills inactive ones.
  gs_init_points: int = gaussians(5000, '>=1')  # Random start in Scene.world_bounds.
  gs_init_opacity: float = gaussians(0.1, '(0,1)')  # Their opacity (3DGS: 0.1).
  # Their scale: 3DGS's 3-nearest-neighbour distance (else the box spacing, box side /
  # gs_init_points^(1/3)).
  gs_init_knn: bool = gaussians(True)
  # 0: the random start is uniform in Scene.world_bounds (3DGS on Blender); k >= 1:
  # uniform among the box's points that k or more training cameras see (in the image,
  # beyond Config.near): for captures whose box holds the cameras (real scenes with a
  # background, fox), keeping Gaussians out of the space that no training view
  # constrains and, from k = 2, off the cameras' own lenses.
  gs_init_views: int = gaussians(0, '>=0')
  # 'random': the start above; 'sfm': the scene's SfM points that 2 or more training views
  # see (COLMAP tracks, else projection), at their colours (gaussians/start.py).
  gs_init: str = gaussians('random', 'random|sfm')
  # At most this many Gaussians (the nearest) per 16x16 tile; 0: all (up to the capacity).
  gs_tile_cap: int = gaussians(0, '>=0')
  # With gs_tile_cap 0, the rasteriser's pair buffer: K x this (8x8 pixel block,
  # Gaussian) pairs per image (K blocks), at most 2x this in one block; where it binds
  # the farthest are dropped (with the whole buffer full, the image's farthest pairs
  # first, from any block) and the tiles count in the cap-bound fraction that the
  # training log records. A fresh 100k-Gaussian fern at 126x94 needs 1464 on average
  # (20k: 622): raise it with gs_capacity far above 100k or large images.
  gs_list_capacity: int = gaussians(2048, '>=1')
  # Scene extent (lr, densify sizes); 0: 3DGS's 1.1 x camera radius.
  gs_extent: float = gaussians(0., '>=0')
  # SH degree +1 every this (3DGS: 1000), to 3.
  gs_sh_interval_frac: float = gaussians(1000 / 30000, '>0')
  # Densify after (3DGS: 500) ... until (3DGS: 15000) ... every (3DGS: 100) steps.
  gs_densify_from_frac: float = gaussians(500 / 30000, '[0,1]')
  gs_densify_until_frac: float = gaussians(15000 / 30000, '[0,1]')
  gs_densify_every_frac: float = gaussians(100 / 30000, '>0')
  # Opacity reset period (3DGS: 3000).
  gs_opacity_reset_every_frac: float = gaussians(3000 / 30000, '>0')
  # Mean view-space gradient to densify at (3DGS: 2e-4; FSGS's few-shot LLFF value 5e-4
  # here: fewer, better-supported Gaussians from 3 views; DNGaussian uses 1.3e-3).
  gs_grad_threshold: float = gaussians(5e-4, '>0')
  gs_min_opacity: float = gaussians(0.005, '[0,1)')  # Prune less opaque Gaussians.
  # Clone below / split above this fraction of the extent.
  gs_percent_dense: float = gaussians(0.01, '>0')
  # Position lr (x the extent), decayed exponentially...
  gs_lr_means_init: float = gaussians(1.6e-4, '>0')
  gs_lr_means_final: float = gaussians(1.6e-6, '>0')  # ... to this at max_steps.
  gs_lr_sh_dc: float = gaussians(2.5e-3, '>0')  # Lr of the SH DC (base colour) terms.
  gs_lr_sh_rest: float = gaussians(2.5e-3 / 20, '>0')  # Lr of the higher SH coefficients.
  gs_lr_opacity: float = gaussians(0.05, '>0')  # Lr of the opacity logits.
  gs_lr_scales: float = gaussians(5e-3, '>0')  # Lr of the log scales.
  gs_lr_quats: float = gaussians(1e-3, '>0')  # Lr of the rotations.
  gs_lambda_dssim: float = gaussians(0.2, '[0,1]')  # Loss (1 - l) L1 + l (1 - SSIM).
  # DropGaussian (gaussians/dropout.py): each Gaussian is left out of a training step's
  # render with a probability rising linearly to this at max_steps, the others' opacity
  # x 1 / (1 - p); 0: off, nothing traced (DropGaussian: 0.2).
  gs_drop_rate: float = gaussians(0., '[0,1)')
  # Background (white_bkgd: white).
  gs_background: Tuple[float, float, float] = gaussians((0., 0., 0.), '[0,1]')
  # --- NeRF: RegNeRF regularisers (0 / False switches a term off: nothing is traced) ---
  depth_tv_loss_mult: float = nerf(0.1, '>=0')  # Depth-TV weight past the decay (0: off).
  depth_tv_decay: bool = nerf(True)  # Log-linear decay from _start to _end over _maxstep.
  depth_tv_mult_start: float = nerf(400., '>0')
  depth_tv_mult_end: float = nerf(0.1, '>0')
  depth_tv_maxstep: int = nerf(512, '>=0')
  n_random_poses: int = nerf(10000, '>=1')  # Unobserved poses for the depth-TV patches.
  # Rays per step from random poses (64 patches of 8x8).
  batch_size_random: int = nerf(4096, '>=1')
  patch_size: int = nerf(8, '>=1')
  # Shared: random poses of forward-facing scenes (the NeRF's depth-TV patches and
  # Config.pseudo_targets 'random') lie in the box of camera centres enlarged by this.
  random_pose_spread: float = shared(1.2, '>0')
  anneal_nearfar: bool = nerf(True)
  anneal_nearfar_steps: int = nerf(512, '>=1')
  anneal_nearfar_perc: float = nerf(0.0001, '[0,1]')
  anneal_mid_perc: float = nerf(1.0, '[0,1]')
  # --- NeRF: FreeNeRF and other regularisers (FreeNeRF's: on in llff3_freenerf.gin) ---
  freq_reg: bool = nerf(False)  # Open the IPE frequency bands linearly...
  freq_reg_end: float = nerf(0.9, '(0,1]')  # ... until this fraction of max_steps.
  occ_reg_mult: float = nerf(0., '>=0')  # Occlusion reg. weight (FreeNeRF: 0.01; 0: off).
  occ_reg_range: int = nerf(20, '>=0')  # Samples nearest the camera it penalises.
  # mip-NeRF 360's distortion loss on the last level's weights of every ray rendered in a
  # step (the batch and the random-pose patches); 0: off (nothing computed).
  distortion_loss_mult: float = nerf(0., '>=0')
  # A near-camera density penalty (regularizers.near_camera_weight): the batch's mean
  # rendering weight within near_camera_radius (world units) of a training camera's
  # centre, times this (0: off, nothing computed). Needs use_ndc = False.
  near_camera_loss_mult: float = nerf(0., '>=0')
  near_camera_radius: float = nerf(0.15, '>=0')
  # --- NeRF: grid field (Config.field = 'grid') ---
  grid_levels: int = nerf(12, '>=1')  # Resolution levels of the multi-resolution grid.
  grid_base_res: int = nerf(16, '>=1')  # Coarsest resolution (vertices per axis - 1).
  grid_max_res: int = nerf(512, '>=1')  # Finest resolution.
  grid_features: int = nerf(2, '>=1')  # Features per level.
  # Entries per level when hashed (2^n); dense if smaller.
  grid_log2_hashmap_size: int = nerf(17, '[0,30]')
  grid_mlp_width: int = nerf(64, '>=1')  # Width of the tiny density / colour MLPs.
  grid_init_scale: float = nerf(1e-4, '>=0')  # Uniform init range of the tables.
  # Box the grid covers: the NDC cube for LLFF; about +-1.5 for NeRF-synthetic.
  grid_box: Tuple[Tuple[float, ...], Tuple[float, ...]] = nerf(
      ((-1., -1., -1.), (1., 1., 1.)), BOX)
  # Density at samples outside grid_box: 'clamp' (the fields clamp the point onto the
  # box's faces: LLFF's NDC rays leave the box sideways) or 'empty' (0: a bounded scene's
  # box holds it all, as Instant-NGP's aabb; lego8.gin).
  outside_box: str = nerf('clamp', 'clamp|empty')
  # --- NeRF: sampler ---
  # 'coarse_fine' (mip-NeRF: every level renders colour with the one field, the coarse
  # level weighted by coarse_loss_mult) or 'proposal' (mip-NeRF 360 / nerfacto: level 0
  # samples a tiny density-only grid, fields/proposal.py, trained by the interlevel loss;
  # only the last level renders colour). 'proposal' needs num_levels = 2.
  sampler: str = nerf('coarse_fine', 'coarse_fine|proposal')
  proposal_samples: int = nerf(64, '>=2')  # Samples of the proposal level.
  proposal_levels: int = nerf(5, '>=1')  # Its grid levels (from grid_base_res).
  proposal_max_res: int = nerf(128, '>=1')  # Its finest resolution.
  proposal_log2_hashmap_size: int = nerf(17, '[0,30]')  # 2^n entries a level if hashed.
  proposal_mlp_width: int = nerf(16, '>=1')  # Hidden width of its density MLP.
  interlevel_loss_mult: float = nerf(1., '>=0')  # Weight of its interlevel loss.
  # --- Re-Nerfing: rounds, D's training, pseudo-views ---
  # Rounds after the baseline (0: none), or 'auto': decided on validation views.
  num_rounds: Union[int, str] = renerf(0, NUM_ROUNDS, 'rounds')
  auto_max_rounds: int = renerf(3, '>=1', 'rounds')  # 'auto': at most this many rounds,
  auto_min_gain_se: float = renerf(1., '>=0', 'rounds')  # kept when gain > this x its se.
  # train.py also trains round 1's seed-matched control (renerf.control_config: B's
  # training at D's seed, no pseudo-views) in <run>/control/ and reports R1 against it.
  seed_control: bool = renerf(False, None, 'rounds')
  # How D draws rays while the pseudo-views are on (NeRF: the Gaussians draw whole
  # images, real and pseudo alike): 'pixels' (the paper: they are "part of the training
  # images": rays uniform over every usable pixel of the real and the pseudo-views
  # together; masked pseudo pixels are never drawn) or 'fraction' (a fixed pseudo_frac of
  # each batch from the pseudo-views, masked pixels drawn with weight 0).
  pseudo_mix: str = renerf('pixels', 'pixels|fraction', 'd_training', backbone='nerf')
  # The pseudo share with pseudo_mix='fraction'.
  pseudo_frac: float = renerf(0.5, '[0,1]', 'd_training', backbone='nerf')
  # K as a fraction of max_steps: pseudo-views only for steps < K (RegNeRF's MLP:
  # 5000 / 69768 = 7.2%; the grid and Gaussian configs set their own). With the NeRF,
  # never before the near/far annealing ends.
  pseudo_until_frac: float = renerf(0.072, '[0,1]', 'd_training')
  # Table "why": 'early' (steps < K, the method), 'all' (keep to the end) or 'late' (only
  # the last K steps).
  pseudo_schedule: str = renerf('early', 'early|all|late', 'd_training')
  # 'reset' (D from scratch, the method) or 'continue' (from B).
  renerf_init: str = renerf('reset', 'reset|continue', 'd_training')
  # D's seed in round r (renerf.round_config): 'offset' (seed + 1000 r for its
  # initialisation and its draws: a model as different from B as another seed),
  # 'same_init' (B's initialisation, draws from seed + 1000 r) or 'same' (B's seed for
  # both: D differs from B only by the pseudo-views, so D without pseudo-views is B bit
  # for bit).
  d_seed: str = renerf('offset', 'offset|same_init|same', 'd_training')
  # Preset name (2x, 3x, 3x_b, 3x_c, 4x, 5x, 7x, 11x) or comma-separated factors, e.g.
  # '0.25,0.5'.
  interp_factors: str = renerf('7x', FACTORS, 'pseudo_poses')
  # Neighbour sequencing: ordered, position or rotation.
  sequencing: str = renerf('position', 'ordered|position|rotation', 'pseudo_poses')
  # 'interp', 'test' (test poses), 'random' or a '+' combination such as 'interp+test'.
  pseudo_targets: str = renerf('interp', TARGETS, 'pseudo_poses')
  # Random unobserved poses for pseudo_targets 'random'.
  pseudo_n_random: int = renerf(4, '>=1', 'pseudo_poses')
  # 'render' (B's renders: Re-Nerfing) or 'photo' (the oracle: the real photos at the
  # unused views, with pseudo_targets 'unused').
  pseudo_source: str = renerf('render', 'render|photo', 'pseudo_poses')
  # --- Re-Nerfing: masks, Laplace uncertainty (Bayes' Rays style, NeRF only) ---
  # Mask uncertain pseudo-view pixels (with mask_signal 'laplace': after the Hessian pass).
  use_masks: bool = renerf(False, None, 'masks')
  # The uncertainty the masks threshold: a Hessian-free signal of one render,
  # 'one_minus_acc' (the default: the lowest mean AUSE over six scenes; the only one of
  # the Gaussians), 'depth_variance', 'weight_entropy' (uncertainty/signals.py; compared
  # in experiments/results/uncertainty_quality_llff/uq_tiny.md), 'laplace' (the Bayes'-Rays
  # Hessian pass below), or 'acc' (NeRF: opacity; at mask_threshold 0.5 what B renders empty).
  mask_signal: str = renerf('one_minus_acc', 'laplace|one_minus_acc|depth_variance|'
                            'weight_entropy|acc', 'masks')
  # L: the deformation grid has (2^L + 1)^3 vertices.
  deform_log2_res: int = renerf(8, '[0,10]', 'hessian', backbone='nerf')
  # R: training rays in the Hessian pass.
  hessian_rays: int = renerf(65536, '>=1', 'hessian', backbone='nerf')
  # Prior precision lambda (keeps Sigma finite).
  hessian_lambda: float = renerf(1e-4, '>0', 'hessian', backbone='nerf')
  # Rays per jitted chunk of the Hessian pass (memory vs speed).
  hessian_chunk: int = renerf(1024, '>=1', 'hessian_chunk', backbone='nerf')
  # Keep this fraction of pseudo pixels (mu by bisection)...
  mask_keep_frac: float = renerf(0.8, '[0,1]', 'masks')
  # ... unless >= 0: absolute mu on the uncertainty.
  mask_threshold: float = renerf(-1., '-1|>=0', 'masks')
  # --- evaluation, logging, IO ---
  print_every: int = report(100, '>=1')
  eval_every: int = report(500, '>=0')  # Steps between cheap test evaluations (0: off).
  eval_n_views: int = report(3, '>=1')  # Test views in the cheap evaluation.
  eval_stride: int = report(4, '>=1')  # Pixel stride of the cheap evaluation (1: all).
  checkpoint_every: int = report(1000, '>=1', 'io')
  # Rays per chunk when the NeRF renders full images.
  render_chunk: int = report(4096, '>=1', 'render_chunk', backbone='nerf')
  lpips_nets: Tuple[str, ...] = report(('alex', 'vgg'), 'alex|alexnet|vgg|vgg16')

  def __post_init__(self):
    check_config(self)


def field_category(name: str) -> str:
  """The `affects` category of Config field `name` ('model' when undeclared)."""
  return Config.__dataclass_fields__[name].metadata.get('affects', 'model')


def fields_where(effect: str, present: bool = True) -> Tuple[str, ...]:
  """Names of the Config fields whose category has (or, present=False, lacks) `effect`
  ('baseline', 'pseudo', 'hessian', 'render' or 'resumable'), in declaration order."""
  return fields_with(Config, effect, present)


def _reset_ignored_bindings():
  """Binds the fields that the bound Config.backbone ignores to their defaults."""
  try:
    backbone = gin.query_parameter('Config.backbone')
  except ValueError:
    backbone = Config.__dataclass_fields__['backbone'].default
  with gin.unlock_config():  # Parsing finalised (locked) the config.
    for name in ignored_by(Config, backbone):
      gin.bind_parameter(f'Config.{name}', Config.__dataclass_fields__[name].default)


def load_config(gin_configs: Sequence[str] = (), gin_bindings: Sequence[str] = (),
                reset_ignored: bool = False) -> Config:
  """Parses gin files and bindings and returns the Config.

  Args:
    gin_configs: paths of .gin files; a path that does not exist as given is looked up
      in the repository's gin_configs/ (resolve_gin_config), so `llff3.gin` or `llff3`
      works from any directory.
    gin_bindings: binding strings.
    reset_ignored: fields the backbone ignores get their defaults whatever is bound (for
      a run directory's config.gin written before such settings were refused, e.g. a
      Gaussian run's anneal_nearfar = False: they change nothing of the run).

  Returns:
    Config.

  Raises:
    ConfigError: naming the missing file or the bad binding.
  """
  files = [resolve_gin_config(path) for path in gin_configs]
  gin.clear_config()
  # `include 'x.gin'` resolves next to the including file, then in gin_configs/.
  set_gin_search_path([os.path.dirname(os.path.abspath(p)) for p in files]
                      + [GIN_CONFIGS_DIR])
  try:
    gin.parse_config_files_and_bindings(files, list(gin_bindings), skip_unknown=False)
    if reset_ignored:
      _reset_ignored_bindings()
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
