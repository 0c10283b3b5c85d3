"""Writes the Colab-style notebooks from their cell sources (run: python notebooks/make_notebooks.py).

Each notebook reads its size from the environment variable RENERF_NOTEBOOK_SMALL (set by
the tests to run them top to bottom in seconds on the smallest config).
"""
import os

import nbformat

HERE = os.path.dirname(os.path.abspath(__file__))

QUICKSTART = [
    ('md', '# renerf-jax quick start\n\nOne Re-Nerfing round on the embedded 360-degree '
     'scene (no download; README command 1 runs the same config): train B on the training '
     'views, render pseudo-views between neighbouring training cameras, estimate B\'s '
     'Laplace uncertainty, mask uncertain pixels, train D from scratch, train the '
     'seed-matched control (D\'s seed, no pseudo-views), and plot test PSNR against run '
     'time. First run `pip install -e .` in the repository root (in Colab: '
     '`!pip install -e .` in a clone).'),
    ('code', '''import os, tempfile
import numpy as np
import matplotlib.pyplot as plt
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene
from renerf_jax import figures, renerf, report, round_driver, rundir

SMALL = os.environ.get('RENERF_NOTEBOOK_SMALL') == '1'
repo = os.path.abspath('..')
bindings = ['Config.use_masks = True', "Config.mask_signal = 'laplace'",
            'Config.deform_log2_res = 5', 'Config.hessian_rays = 4096']
if SMALL:  # seconds instead of minutes
  bindings += ['Config.procedural_size = (32, 32)', 'Config.procedural_views = 16',
               'Config.max_steps = 30', 'Config.pseudo_until_frac = 0.5', 'Config.eval_every = 15',
               'Config.hessian_rays = 256', 'Config.deform_log2_res = 2']
config = load_config([os.path.join(repo, 'gin_configs', 'demo.gin')], bindings)
scene = load_scene(config)
print(scene.images.shape, 'train views', scene.train_idx, 'test views', scene.test_idx)'''),
    ('code', '''n = len(scene.train_idx)
plt.figure(figsize=(1.5 * n, 1.8))
for k, i in enumerate(scene.train_idx):
  plt.subplot(1, n, k + 1); plt.imshow(scene.images[i]); plt.axis('off')
plt.suptitle('the training views'); plt.show()'''),
    ('code', '''run_dir = tempfile.mkdtemp(prefix='renerf_quickstart_')
state = round_driver.run_rounds(config, scene, run_dir)
control = round_driver.run_control(config, scene, run_dir, state)
print(renerf.rounds_table(state.metrics, control))
print('\\n'.join(renerf.deltas_vs_baseline(state.metrics, control)))'''),
    ('md', '## Pseudo-views, their uncertainty and masks'),
    ('code', '''pv = state.pseudo
n = min(4, pv.images.shape[0])
plt.figure(figsize=(3 * n, 7))
for j in range(n):
  plt.subplot(3, n, j + 1); plt.imshow(pv.images[j]); plt.axis('off')
  plt.subplot(3, n, n + j + 1); plt.imshow(figures.colorize(pv.uncertainty[j])); plt.axis('off')
  plt.subplot(3, n, 2 * n + j + 1); plt.imshow(pv.masks[j], cmap='gray', vmin=0, vmax=1); plt.axis('off')
plt.suptitle('pseudo-views (top), uncertainty (middle), masks (bottom)'); plt.show()
print('kept fraction of pseudo pixels:', float(np.mean(pv.masks)))'''),
    ('md', '## Error against run time'),
    ('code', '''curves = {}
for r in range(int(state.round_index) + 1):
  res = report.read_json(rundir.result_path(rundir.round_dir(run_dir, r)))
  curves['baseline' if r == 0 else f'round {r}'] = [(c['time'], c['eval_psnr']) for c in res['curve']]
for label, pts in curves.items():
  t, v = zip(*pts); plt.plot(t, v, 'o-', label=label)
plt.xlabel('cumulative wall-clock seconds'); plt.ylabel('test PSNR (strided pixels)'); plt.legend(); plt.grid(); plt.show()
assert all(np.isfinite(v) for pts in curves.values() for _, v in pts)'''),
]

BYO = [
    ('md', '# Bring your own LLFF scene\n\nPoint `DATA_DIR` at a folder holding `<scene>/'
     'poses_bounds.npy` and `<scene>/images_8/` (the LLFF layout; make them with COLMAP and '
     "LLFF's imgs2poses.py), then train the CPU configuration and evaluate it. First run "
     '`pip install -e .` in the repository root.'),
    ('code', '''import os, tempfile
import matplotlib.pyplot as plt
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene
from renerf_jax import renerf, round_driver, rundir
from renerf_jax.evaluation import view_name

DATA_DIR = os.environ.get('RENERF_DATA_DIR', os.path.abspath('../../shared/data/nerf_llff_data'))
SCENE = os.environ.get('RENERF_SCENE', 'fern')
SMALL = os.environ.get('RENERF_NOTEBOOK_SMALL') == '1'
bindings = [f'Config.data_dir = {DATA_DIR!r}', f'Config.scene = {SCENE!r}']
if SMALL:
  bindings += ['Config.max_steps = 10', 'Config.num_samples = 8', 'Config.batch_size = 256',
               'Config.eval_every = 10', 'Config.eval_stride = 16', "Config.lpips_nets = ('alex',)"]
config = load_config([os.path.abspath('../gin_configs/llff3_cpu.gin')], bindings)
scene = load_scene(config)
print(scene.name, scene.images.shape, 'train', scene.train_idx, 'test', scene.test_idx)'''),
    ('code', '''run_dir = tempfile.mkdtemp(prefix='renerf_byo_')
state = round_driver.run_rounds(config, scene, run_dir)
print(renerf.rounds_table(state.metrics))'''),
    ('code', '''img = plt.imread(rundir.render_path(rundir.eval_dir(rundir.round_dir(run_dir, 0)), view_name(scene.test_idx[0])))
plt.figure(figsize=(10, 4))
plt.subplot(1, 2, 1); plt.imshow(scene.images[scene.test_idx[0]]); plt.title('ground truth'); plt.axis('off')
plt.subplot(1, 2, 2); plt.imshow(img); plt.title('rendered'); plt.axis('off'); plt.show()'''),
]

CAPTURE = [
    ('md', '# Bring your own capture (COLMAP or nerfstudio)\n\nA folder as COLMAP writes it '
     '(`<scene>/sparse/0/{cameras,images,points3D}.bin` beside `<scene>/images/`: '
     "`Config.dataset_loader = 'colmap'`) or as nerfstudio writes it (`<scene>/"
     "transforms.json`: `'transforms'`). The photos are sorted by name; every 8th is a test "
     'view; the training views are chosen to cover the scene (`Config.train_view_selection '
     "= 'coverage'`) and a few validation views are kept apart for every choice you make "
     '(`Config.val_views`). Then B, pseudo-views and R1. Here: the shared beer capture (71 '
     'phone photos, a camera per photo, resampled to one pinhole camera). First run '
     '`pip install -e .` in the repository root.'),
    ('code', '''import os, tempfile
import matplotlib.pyplot as plt
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene
from renerf_jax import renerf, round_driver
from renerf_jax.figures import draw_split

DATA_DIR = os.environ.get('RENERF_CAPTURE_DIR', os.path.abspath('../../shared/data/colmap'))
SCENE = os.environ.get('RENERF_CAPTURE_SCENE', 'beer')
SMALL = os.environ.get('RENERF_NOTEBOOK_SMALL') == '1'
bindings = ["Config.dataset_loader = 'colmap'", f'Config.data_dir = {DATA_DIR!r}',
            f'Config.scene = {SCENE!r}', 'Config.factor = 1', 'Config.undistort = True',
            'Config.use_ndc = False', 'Config.normalize_poses = True', 'Config.near = 0.05',
            'Config.far = 1000.', 'Config.n_input_views = 12',
            "Config.train_view_selection = 'coverage'", 'Config.val_views = 4',
            'Config.image_downsample = 8', 'Config.num_rounds = 1']
if SMALL:  # seconds instead of minutes
  bindings += ['Config.image_downsample = 16', 'Config.max_steps = 10', 'Config.eval_every = 10',
               "Config.interp_factors = '0.5'", "Config.lpips_nets = ('alex',)"]
config = load_config([os.path.abspath('../gin_configs/grid_wide_recipe.gin'),
                      os.path.abspath('../gin_configs/modifiers/table_step.gin')], bindings)
scene = load_scene(config)
print(scene.name, scene.images.shape, 'train', scene.train_idx, 'val', scene.val_idx,
      'test', scene.test_idx, 'SfM points', scene.points.shape)'''),
    ('code', '''fig, ax = plt.subplots(figsize=(6, 6))
draw_split(ax, scene, 'the chosen cameras (seen from above the capture)'); plt.show()'''),
    ('code', '''run_dir = tempfile.mkdtemp(prefix='renerf_capture_')
state = round_driver.run_rounds(config, scene, run_dir)
print(renerf.rounds_table(state.metrics))
print('validation PSNR, B then R1:', [round(m['val_psnr'], 2) for m in state.metrics])'''),
]


def build(cells):
  nb = nbformat.v4.new_notebook()
  nb.metadata['kernelspec'] = {'name': 'python3', 'display_name': 'Python 3',
                               'language': 'python'}
  for kind, src in cells:
    nb.cells.append(nbformat.v4.new_markdown_cell(src) if kind == 'md'
                    else nbformat.v4.new_code_cell(src))
  return nb


if __name__ == '__main__':
  for name, cells in (('quickstart.ipynb', QUICKSTART), ('bring_your_own_llff.ipynb', BYO),
                      ('bring_your_own_capture.ipynb', CAPTURE)):
    nbformat.write(build(cells), os.path.join(HERE, name))
    print('wrote', name)
