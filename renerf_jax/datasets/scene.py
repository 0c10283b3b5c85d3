"""The Scene container, the RegNeRF few-shot split, and ray pools for training."""
import dataclasses
import functools
from typing import Optional

import jax
import jax.numpy as jnp
import numpy as np

from renerf_jax import cameras
from renerf_jax.errors import DataError


@dataclasses.dataclass(frozen=True)
class Scene:
  """A posed image set (host numpy arrays) and the cameras' ray conventions."""
  name: str
  images: np.ndarray  # [N, H, W, 3] float32 in [0, 1].
  poses: np.ndarray  # [N, 3, 4] camera-to-world (OpenGL convention).
  focal: float  # Pixels.
  near: float  # Ray near bound (NDC: 0).
  far: float  # Ray far bound (NDC: 1).
  use_ndc: bool
  white_bkgd: bool
  train_idx: np.ndarray  # [n_train] int.
  test_idx: np.ndarray  # [n_test] int.
  depths: Optional[np.ndarray] = None  # [N, H, W] ground-truth z-depth when known.
  forward_facing: bool = True
  focus_depth: float = 1.0  # Depth the random forward-facing poses look at.
  bbox: tuple = ((-1., -1., -1.), (1., 1., 1.))  # Scene box (NDC cube for LLFF).
  # World-space box ((lo x, y, z), (hi x, y, z)) holding the scene content (where a
  # Gaussian scene is initialised; bbox is the NDC cube for LLFF); None: unknown.
  world_bounds: Optional[tuple] = None
  # Camera intrinsics shared by every view when not the centred pinhole of `focal`:
  # (fx, fy, cx, cy, k1, k2, p1, p2), pixels and OpenCV distortion (transforms.json).
  # Every view's rays use them (camera_rays); the random unobserved poses of RegNeRF's
  # depth TV are virtual cameras and stay the centred pinhole of `focal` = fx.
  intrinsics: Optional[tuple] = None

  @property
  def height(self) -> int:
    return int(self.images.shape[1])

  @property
  def width(self) -> int:
    return int(self.images.shape[2])


def downsample_scene(scene: Scene, k: int) -> Scene:
  """Box-filters a scene's images (and depths) by an integer factor k.

  Args:
    scene: the loaded scene.
    k: downsampling factor (1: the scene itself); H and W are centre-cropped to
      multiples of k (the principal point moves by at most half a source pixel).

  Returns:
    The scene at 1/k resolution with focal / k: a low-res pixel's ray is the ray through
    the centre of the k x k source pixels it averages.
  """
  if k == 1:
    return scene
  h, w = scene.height // k, scene.width // k
  if h < 1 or w < 1:
    raise DataError(f'Config.image_downsample={k} is larger than the '
                    f'{scene.height}x{scene.width} images of scene {scene.name!r}')
  y0, x0 = (scene.height - h * k) // 2, (scene.width - w * k) // 2

  def box(a):
    a = a[:, y0:y0 + h * k, x0:x0 + w * k]
    return a.reshape(a.shape[0], h, k, w, k, *a.shape[3:]).mean(axis=(2, 4)).astype(a.dtype)
  intrinsics = scene.intrinsics
  if intrinsics is not None:  # Pixel i spans source [x0 + i k, x0 + (i + 1) k].
    fx, fy, cx, cy = intrinsics[:4]
    intrinsics = (fx / k, fy / k, (cx - x0) / k, (cy - y0) / k) + tuple(intrinsics[4:])
  return dataclasses.replace(
      scene, images=box(scene.images), focal=scene.focal / k, intrinsics=intrinsics,
      depths=None if scene.depths is None else box(scene.depths))


def focus_depth_from_bounds(bounds, dt=0.75):
  """LLFF render-path focus: 1 / ((1 - dt) / close + dt / inf), close = 0.9 min bound,
  inf = 5 max bound (a depth between the nearest and a far point, weighted to the far)."""
  close, inf = bounds.min() * .9, bounds.max() * 5.
  return float(1. / ((1. - dt) / close + dt / inf))


FRUSTUM_DEPTH_CAP = 8.  # frustum_bounds: far depths capped at this x the smallest near.


def frustum_bounds(poses, bounds, focal, height, width, depth_cap=FRUSTUM_DEPTH_CAP):
  """World box of the camera frusta between each image's near and (capped) far depth.

  The loaders pass the training cameras only (the test poses stay unseen).

  The box holds the 4 image-corner rays of every camera at depth near_i and at depth
  max(near_i, min(far_i, depth_cap * min_j near_j)). The far bounds are capped because
  they can be far larger than the content (a few distant points; LLFF's far / near is
  4-6 for its own captures but over 20 for re-processed ones), and the box is where
  random Gaussians are spread uniformly: with the cap of 8 the frusta of LLFF's own
  captures (fern: far bounds under 4.7 x the smallest near) are whole.

  Args:
    poses: [N, 3, 4] OpenGL camera-to-world. bounds: [N, 2] near/far z-depths (the
      scene's units, after any rescaling). focal: pixels. height, width: image size.
    depth_cap: the far cap as a multiple of the smallest near bound.

  Returns:
    ((lo x, y, z), (hi x, y, z)) Python floats.
  """
  poses = np.asarray(poses, np.float64)
  bounds = np.asarray(bounds, np.float64)
  near = bounds[:, 0]
  far = np.maximum(near, np.minimum(bounds[:, 1], depth_cap * near.min()))
  hx, hy = 0.5 * width / focal, 0.5 * height / focal
  corners = np.array([[sx * hx, sy * hy, -1.] for sx in (-1., 1.) for sy in (-1., 1.)])
  dirs = np.einsum('nij,kj->nki', poses[:, :3, :3], corners)  # [N, 4, 3], unit z-depth.
  pts = np.concatenate([poses[:, None, :3, 3] + d[:, None, None] * dirs
                        for d in (near, far)], axis=1).reshape(-1, 3)
  return tuple(float(v) for v in pts.min(0)), tuple(float(v) for v in pts.max(0))


def fewshot_split(n_images, n_input_views, llffhold=8):
  """RegNeRF's LLFF split: test = every llffhold-th image; n train views evenly spread.

  Args:
    n_images: images in the scene.
    n_input_views: training views to pick from the non-test images.
    llffhold: test hold-out period.

  Returns:
    (train_idx, test_idx) int arrays.
  """
  all_idx = np.arange(n_images)
  test_idx = all_idx[::llffhold]
  rest = np.array([i for i in all_idx if i not in set(test_idx.tolist())])
  if n_input_views > len(rest):
    raise DataError(f'Config.n_input_views={n_input_views} but only {len(rest)} '
                    f'non-test images are available of {n_images} (every '
                    f'Config.llffhold={llffhold}-th is a test view)')
  pick = np.round(np.linspace(0, len(rest) - 1, n_input_views)).astype(int)
  return rest[pick], test_idx


@functools.lru_cache(maxsize=64)
def _image_rays_fn(height, width, focal, use_ndc, near, far, intrinsics):
  """The jitted ray generator of one camera (kept: a new jit per call would trace and
  compile again every time)."""
  return jax.jit(jax.vmap(lambda c2w: cameras.image_rays(
      c2w, height, width, focal, use_ndc, near, far, intrinsics)))


def camera_rays(scene: Scene, idx, poses=None) -> cameras.Rays:
  """Rays of full images: [len(idx), H, W] for the scene's cameras (or given poses)."""
  poses = scene.poses[np.asarray(idx)] if poses is None else poses
  intr = None if scene.intrinsics is None else tuple(float(v) for v in scene.intrinsics)
  fn = _image_rays_fn(scene.height, scene.width, float(scene.focal), bool(scene.use_ndc),
                      float(scene.near), float(scene.far), intr)
  return fn(jnp.asarray(poses, jnp.float32))


def ray_pool(scene: Scene, idx, images=None, masks=None, poses=None):
  """All rays of the given views flattened into a training pool.

  Args:
    scene: the Scene.
    idx: view indices (ignored when `poses` is given).
    images: optional [V, H, W, 3] images replacing scene.images[idx] (pseudo-views).
    masks: optional [V, H, W] loss weights in [0, 1] (0: never enters the loss).
    poses: optional [V, 3, 4] camera poses replacing scene.poses[idx].

  Returns:
    dict with 'rays' (Rays [P]), 'rgb' [P, 3] and 'lossmult' [P, 1], jnp arrays.
  """
  rays = camera_rays(scene, idx, poses)
  images = scene.images[np.asarray(idx)] if images is None else images
  rgb = jnp.asarray(images, jnp.float32).reshape(-1, 3)
  if masks is None:
    lossmult = jnp.ones((rgb.shape[0], 1), jnp.float32)
  else:
    lossmult = jnp.asarray(masks, jnp.float32).reshape(-1, 1)
  flat = jax.tree_util.tree_map(lambda x: x.reshape((-1,) + x.shape[3:]), rays)
  return {'rays': flat, 'rgb': rgb, 'lossmult': lossmult}
