"""The tiny model shared by the deformation, Laplace and uncertainty tests."""
import jax
import numpy as np

from renerf_jax.configs import Config
from renerf_jax.datasets import load_scene, ray_pool
from renerf_jax.nerf.fields import init_field_params

LAM = 1e-4
TINY = Config(dataset_loader='procedural', num_samples=8, net_depth=2, net_width=32,
              net_width_viewdirs=16, max_deg_point=4, deg_view=2, density_noise=0.,
              randomized=False, procedural_size=(12, 16), procedural_views=9,
              mask_signal='laplace')  # these tests are about the Laplace path


def tiny_setup():
  """Tiny config, random-init params and the flat training ray pool of the toy scene."""
  scene = load_scene(TINY)
  pool = ray_pool(scene, scene.train_idx)
  params = init_field_params(TINY, jax.random.PRNGKey(0))
  return TINY, params, pool


def take(rays, idx):
  return jax.tree_util.tree_map(lambda x: x[np.asarray(idx)], rays)
