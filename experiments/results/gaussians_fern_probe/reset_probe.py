"""The opacity-reset probe: 300 steps without densification (cap 256), then a reset:
which opacities get gradients, and how fast the training PSNR recovers.

  python experiments/results/gaussians_fern_probe/reset_probe.py   (from the repository root)
"""
import jax, jax.numpy as jnp, numpy as np, dataclasses
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene
from renerf_jax.gaussians import training as gt
from renerf_jax.gaussians.strategy import DensityStrategy
OLD = ['Config.gs_sh_interval_frac = 0.05', 'Config.gs_grad_threshold = 5e-4',
       'Config.gs_min_opacity = 0.005', 'Config.gs_lr_means_init = 1.6e-4',
       'Config.gs_lr_means_final = 1.6e-6']  # The FSGS-schedule config of the probes.
config = load_config(['gaussians_llff3_cpu.gin'], OLD + [
    'Config.gs_tile_cap = 256', 'Config.max_steps = 1500',
    'Config.gs_densify_until_frac = 0.05'])
scene = load_scene(config)
extent = gt.scene_extent(config, scene); ext = jnp.asarray(extent, jnp.float32)
state = gt.init_state(config, gt.init_gaussians(config, scene, jax.random.PRNGKey(0)), extent)
cam = gt.Camera.of(scene); data = gt.training_data(scene)
for s in range(300):
  state, st = gt.train_step(config, cam, False, state, data, ext, jax.random.PRNGKey(s))
print('psnr before reset', float(st['psnr']), 'extent', extent)
op = jax.nn.sigmoid(state.params.opacity_logits)
print('opacity quantiles', np.quantile(np.asarray(op), [0.1, 0.5, 0.9, 0.99]))
state = DensityStrategy.of(config).reset_opacity(state)
img, pose, mask = data['images'][0], data['poses'][0], data['masks'][0]
loss, mse, out, grads, g2 = gt.loss_and_grads(config, cam, state.params, img, pose, mask, jnp.int32(0))
g = np.asarray(grads['opacity_logits'])
print('after reset: loss', float(loss), 'grad<0 (raise opacity):', int((g < 0).sum()), 'grad>0:', int((g > 0).sum()), 'zero:', int((g == 0).sum()))
print('acc mean', float(out['acc'].mean()), 'rgb mean', float(out['rgb'].mean()), 'target mean', float(img.mean()))
for s in range(300, 360):
  state, st = gt.train_step(config, cam, False, state, data, ext, jax.random.PRNGKey(s))
  if s % 10 == 0:
    op = np.asarray(jax.nn.sigmoid(state.params.opacity_logits))
    print(s, 'psnr', round(float(st['psnr']), 2), 'opacity median', float(np.median(op)), 'frac<0.005', float((op < 0.005).mean()), 'lr', float(st['lr']))
