"""The edge that writes a run's results: evaluations and pseudo-views, read back."""
import json

import imageio.v2 as imageio
import numpy as np

from renerf_jax.evaluation import Evaluation
from renerf_jax.outputs import load_pseudo_views, save_evaluation, save_pseudo_views
from renerf_jax.pseudo_views import PseudoViews


def test_save_evaluation_writes_metrics_and_renders(tmp_path):
  rng = np.random.default_rng(0)
  per_image = [{'name': 'test_003', 'psnr': 20., 'ssim': .5},
               {'name': 'test_011', 'psnr': 24., 'ssim': .7}]
  ev = Evaluation(per_image=per_image, mean={'psnr': 22., 'ssim': .6},
                  images=rng.random((2, 5, 7, 3)).astype(np.float32),
                  distances=rng.random((2, 5, 7)).astype(np.float32),
                  columns=('name', 'psnr', 'ssim'))
  save_evaluation(str(tmp_path / 'eval'), ev)
  saved = json.loads((tmp_path / 'eval' / 'metrics.json').read_text())
  assert saved == {'per_image': per_image, 'mean': {'psnr': 22., 'ssim': .6}}
  md = (tmp_path / 'eval' / 'metrics.md').read_text()
  assert 'test_011' in md and 'mean' in md and 'lpips' not in md
  png = imageio.imread(tmp_path / 'eval' / 'test_011.png')
  np.testing.assert_array_equal(png, np.round(ev.images[1] * 255).astype(np.uint8))
  assert imageio.imread(tmp_path / 'eval' / 'depth_003.png').shape == (5, 7, 3)
  save_evaluation(str(tmp_path / 'quiet'), ev, save_png=False)
  assert sorted(p.name for p in (tmp_path / 'quiet').iterdir()) == ['metrics.json',
                                                                     'metrics.md']


def test_pseudo_views_round_trip_bit_exact(tmp_path):
  rng = np.random.default_rng(1)
  pv = PseudoViews(images=rng.random((3, 4, 6, 3)).astype(np.float32),
                   poses=rng.standard_normal((3, 3, 4)).astype(np.float32),
                   masks=(rng.random((3, 4, 6)) > .5).astype(np.float32),
                   uncertainty=rng.random((3, 4, 6)).astype(np.float32))
  assert load_pseudo_views(str(tmp_path / 'views')) is None  # not written yet
  save_pseudo_views(str(tmp_path / 'views'), pv, [{'i': i} for i in range(3)])
  back = load_pseudo_views(str(tmp_path / 'views'))
  for k in ('images', 'poses', 'masks', 'uncertainty'):
    np.testing.assert_array_equal(getattr(back, k), getattr(pv, k))
  names = {p.name for p in (tmp_path / 'views').iterdir()}
  assert {'views.npz', 'views.json', 'view_002.png', 'mask_002.png',
          'uncertainty_002.png', 'panel_002.png'} <= names
  assert not any(n.endswith('.tmp') for n in names)
