"""The web viewer (renerf_jax/viewer.py, view.py) on a run of the embedded procedural
scene: its frames against the evaluation's renders, two rounds side by side, following a
run in training, and the page in a real browser (headless Chromium, driven by
Playwright: an image arrives, the camera moves, a click on a pseudo-view frustum and the
panel's button snap to pseudo-view cameras, and the screenshots differ).

Chromium is Debian's (`/usr/bin/chromium`, installed by .ci/run); where no browser can be
installed the test is skipped with the reason printed.
"""
import dataclasses
import os
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest

from benchmarks.browser import CHROMIUM, drag, launch
from benchmarks.ports import free_port
from conftest import REPO, tiny_config


def _wait(cond, timeout, what):
  t0 = time.time()
  while time.time() - t0 < timeout:
    if cond():
      return
    time.sleep(.1)
  raise AssertionError(f'timed out after {timeout} s waiting for {what}')


def _canvas_shot(page, path):
  """Screenshot of the 3D canvas as float32 [H, W, 3] in [0, 1]."""
  import imageio.v3 as iio  # pylint: disable=g-import-not-at-top
  page.locator('canvas').first.screenshot(path=path)
  return iio.imread(path)[..., :3].astype(np.float32) / 255.


@pytest.fixture(scope='module')
def demo_run(tmp_path_factory):
  """B and R1 of a tiny model on the embedded scene, in a run directory (pseudo-views
  masked by the Laplace uncertainty)."""
  from renerf_jax import cli, round_driver  # pylint: disable=g-import-not-at-top
  from renerf_jax.datasets import load_scene  # pylint: disable=g-import-not-at-top
  config = tiny_config(num_rounds=1, interp_factors='0.5', use_masks=True)
  run_dir = str(tmp_path_factory.mktemp('viewer') / 'run')
  cli.check_run_dir(config, run_dir, create=True)
  round_driver.run_rounds(config, load_scene(config), run_dir, show_progress=False)
  return run_dir


def test_viewer_in_headless_chromium(demo_run, tmp_path):
  if shutil.which(CHROMIUM) is None:
    pytest.skip(f"no browser at {CHROMIUM}: .ci/run installs Debian's chromium with "
                'apt-get; set RENERF_CHROMIUM to use another')
  from playwright.sync_api import sync_playwright  # pylint: disable=g-import-not-at-top
  from renerf_jax import view_cameras as vc  # pylint: disable=g-import-not-at-top
  from renerf_jax.viewer import Viewer, ViewerOptions  # pylint: disable=g-import-not-at-top

  viewer = Viewer(demo_run, port=free_port(),
                  options=ViewerOptions(preview_side=32, full_side=64, settle_seconds=.2))
  try:
    assert [ri.label for ri in viewer.rounds] == ['B (round 0)', 'R1']
    url = f'http://127.0.0.1:{viewer.server.get_port()}'
    with sync_playwright() as p:
      browser = launch(p)
      page = browser.new_page(viewport={'width': 1000, 'height': 700})
      page.goto(url)
      # An image arrives: a full-size frame of the shown round at the first training camera.
      _wait(lambda: viewer.stats.frames >= 1 and viewer._clients, 120, 'a first frame')
      client = next(iter(viewer._clients.values())).client
      _wait(lambda: viewer.stats.last_frame is not None and
            max(viewer.stats.last_frame.shape[:2]) == 64, 60, 'the full-size frame')
      time.sleep(1.)  # Let the browser draw it.
      first = _canvas_shot(page, str(tmp_path / 'first.png'))
      assert first.std() > .02, 'the page shows a blank canvas'
      pose0 = vc.pose_from_browser(client.camera.wxyz, client.camera.position)
      frames0 = viewer.stats.frames

      # Move the camera: drag across the canvas (orbit).
      drag(page, 120, 40)
      _wait(lambda: np.abs(vc.pose_from_browser(client.camera.wxyz, client.camera.position)
                           - pose0).max() > 1e-3, 30, 'the browser camera to move')
      _wait(lambda: viewer.stats.frames > frames0, 60, 'a frame at the moved camera')
      time.sleep(1.5)
      moved = _canvas_shot(page, str(tmp_path / 'moved.png'))
      assert np.abs(moved - first).mean() > .01, 'moving the camera changed nothing'

      # Snap to a pseudo-view camera by clicking its frustum: step back from the first
      # training camera so the cameras are in view, then click the frustum's image.
      viewer.gui_model.value = 'R1'
      _wait(lambda: 'pseudo 0' in viewer.gui_camera.options, 30, 'the pseudo-view cameras')
      cams = {name: pose for name, _, pose, _ in viewer._cameras()}
      back = cams[viewer.gui_camera.options[0]].copy()
      back[:, 3] += 8. * viewer.scale * back[:, 2]  # OpenGL +z points backwards.
      viewer._set_camera(client, back, client.camera.fov)
      _wait(lambda: np.abs(vc.pose_from_browser(client.camera.wxyz, client.camera.position)
                           - back).max() < 1e-3, 30, 'the camera to step back')
      time.sleep(1.5)
      box = page.locator('canvas').first.bounding_box()
      x, y = vc.browser_pixel(vc.frustum_centre(cams['pseudo 0'], viewer.scale),
                              client.camera.wxyz, client.camera.position,
                              client.camera.fov, box['width'], box['height'])
      page.mouse.click(box['x'] + x, box['y'] + y)
      _wait(lambda: viewer.stats.last_camera == 'pseudo 0', 60,
            'a frame at the clicked pseudo-view camera')
      np.testing.assert_allclose(
          vc.pose_from_browser(client.camera.wxyz, client.camera.position), cams['pseudo 0'],
          atol=1e-3)
      # At a pseudo-view camera the PSNR compares R1 with the pseudo-view it trained on.
      assert viewer.stats.last_psnr is not None and np.isfinite(viewer.stats.last_psnr)
      time.sleep(1.5)
      snapped = _canvas_shot(page, str(tmp_path / 'snapped.png'))
      assert np.abs(snapped - first).mean() > .01
      assert np.abs(snapped - moved).mean() > .01

      # The panel's "Go to camera" button does the same for the camera picked there.
      viewer.gui_camera.value = 'pseudo 1'
      page.get_by_role('button', name='Go to camera').click()
      _wait(lambda: viewer.stats.last_camera == 'pseudo 1', 60, 'a frame at pseudo 1')
      np.testing.assert_allclose(
          vc.pose_from_browser(client.camera.wxyz, client.camera.position), cams['pseudo 1'],
          atol=1e-3)
      browser.close()
  finally:
    viewer.stop()


@dataclasses.dataclass
class _FakeCamera:
  """What the viewer reads of a browser's camera."""
  wxyz: np.ndarray
  position: np.ndarray
  fov: float = 1.
  aspect: float = 1.


@dataclasses.dataclass
class _FakeClient:
  camera: _FakeCamera
  client_id: int = 0


@pytest.fixture(scope='module')
def viewer(demo_run):
  from renerf_jax.viewer import Viewer, ViewerOptions  # pylint: disable=g-import-not-at-top
  v = Viewer(demo_run, port=free_port(), options=ViewerOptions(poll_seconds=3600.))
  yield v
  v.stop()


def _client_at(pose, fov=1., aspect=1., snapped=None):
  from renerf_jax import view_cameras as vc  # pylint: disable=g-import-not-at-top
  from renerf_jax.viewer import _ClientState  # pylint: disable=g-import-not-at-top
  wxyz, pos = vc.browser_from_pose(pose)
  return _ClientState(_FakeClient(_FakeCamera(wxyz, pos, fov, aspect)), snapped=snapped)


def test_psnr_at_test_cameras_equals_the_evaluation(viewer, demo_run):
  """At a test camera the viewer renders that camera's own image: its PSNR against the
  photo is the evaluation's, view by view."""
  from renerf_jax import report, rundir  # pylint: disable=g-import-not-at-top
  viewer.gui_model.value, viewer.gui_layer.value = 'R1', 'error'
  per_image = report.read_json(rundir.metrics_path(rundir.eval_dir(
      rundir.round_dir(demo_run, 1))))['per_image']
  scene = viewer.scene
  for rec, i in zip(per_image, scene.test_idx):
    cam = next(c for c in viewer._cameras() if c[0] == f'test {i}')
    st = _client_at(cam[2], aspect=scene.width / scene.height,
                    snapped=viewer.snapped_camera(*cam))
    img, psnr = viewer.frame(st, 64)
    assert img.shape == (scene.height, scene.width, 3)
    assert psnr == pytest.approx(rec['psnr'], abs=1e-3)
  # Moved away from the camera: a browser-camera frame without a photo.
  moved = cam[2].copy()
  moved[:, 3] += .05
  st = _client_at(moved, aspect=2., snapped=viewer.snapped_camera(*cam))
  img, psnr = viewer.frame(st, 40)
  assert psnr is None and img.shape == (20, 40, 3)


def test_pseudo_view_camera_shows_its_stored_uncertainty(viewer, demo_run):
  """At a pseudo-view camera: the PSNR is against the pseudo-view image, and the
  'uncertainty' layer is the Laplace uncertainty its mask was cut from."""
  from renerf_jax import run_contents  # pylint: disable=g-import-not-at-top
  from renerf_jax.pseudo_views import uncertainty_heatmap  # pylint: disable=g-import-not-at-top
  pv = run_contents.round_pseudo_views(demo_run, 1)
  assert np.any(pv.uncertainty) and 0. < pv.masks.mean() < 1.
  viewer.gui_model.value, viewer.gui_compare.value = 'R1', 'none'
  scene = viewer.scene
  cam = next(c for c in viewer._cameras() if c[0] == 'pseudo 1')
  aspect = scene.width / scene.height
  viewer.gui_layer.value = 'uncertainty'
  at_cam = viewer.snapped_camera(*cam)
  img, psnr = viewer.frame(_client_at(cam[2], aspect=aspect, snapped=at_cam), 64)
  np.testing.assert_allclose(img, uncertainty_heatmap(pv.uncertainty[1], pv.uncertainty))
  viewer.gui_layer.value = 'rgb'
  rgb, _ = viewer.frame(_client_at(cam[2], aspect=aspect, snapped=at_cam), 64)
  mse = np.mean((np.clip(rgb, 0., 1.) - pv.images[1])**2)
  assert psnr == pytest.approx(-10. * np.log10(mse), abs=1e-3)


def test_split_view_shows_two_rounds(viewer):
  scene = viewer.scene
  pose = scene.poses[scene.test_idx[0]]
  viewer.gui_layer.value, viewer.gui_compare.value = 'rgb', 'none'
  frames = {}
  for label in ('B (round 0)', 'R1'):
    viewer.gui_model.value = label
    frames[label], _ = viewer.frame(_client_at(pose, aspect=1.5), 48)
  assert np.abs(frames['R1'] - frames['B (round 0)']).max() > 1e-3
  viewer.gui_model.value, viewer.gui_compare.value, viewer.gui_split.value = (
      'R1', 'B (round 0)', .5)
  try:
    both, _ = viewer.frame(_client_at(pose, aspect=1.5), 48)
  finally:
    viewer.gui_compare.value = 'none'
  np.testing.assert_allclose(both[:, :24], frames['R1'][:, :24], atol=1e-5)
  np.testing.assert_allclose(both[:, 25:], frames['B (round 0)'][:, 25:], atol=1e-5)


def test_follow_training_shows_the_newest_checkpoint(demo_run, tmp_path):
  """A run whose round 1 is still training: the viewer lists it with its checkpoint's
  step, and a newer checkpoint is loaded by refresh()."""
  from flax import serialization  # pylint: disable=g-import-not-at-top
  import jax  # pylint: disable=g-import-not-at-top
  from renerf_jax import rundir, run_contents  # pylint: disable=g-import-not-at-top
  from renerf_jax.viewer import Viewer, ViewerOptions  # pylint: disable=g-import-not-at-top
  run = str(tmp_path / 'run')
  shutil.copytree(demo_run, run)
  done_r1, run_r1 = rundir.round_dir(demo_run, 1), rundir.round_dir(run, 1)
  for path in (rundir.done_path, rundir.params_path):
    os.remove(path(run_r1))
  config = run_contents.run_config(run)
  b_params, _ = run_contents.load_params(config, run, 0)
  with open(rundir.params_path(done_r1), 'rb') as f:
    r1_params = serialization.from_bytes(b_params, f.read())
  ckpts = rundir.round_checkpoints_dir(run, 1)
  shutil.rmtree(ckpts)
  meta = {'train_seconds': np.zeros((), np.float64)}
  rundir.save_checkpoint(ckpts, {'state': {'step': 10, 'params': b_params}, 'meta': meta}, 10)
  v = Viewer(run, port=free_port(), options=ViewerOptions(poll_seconds=3600.))
  try:
    assert [(ri.label, ri.done, ri.step) for ri in v.rounds] == [
        ('B (round 0)', True, None), ('R1', False, 10)]
    same = jax.tree_util.tree_map(np.array_equal, v.params(1)[0], b_params)
    assert all(jax.tree_util.tree_leaves(same))
    assert not v.refresh()  # Nothing new.
    rundir.save_checkpoint(ckpts, {'state': {'step': 20, 'params': r1_params},
                                   'meta': meta}, 20)
    assert v.refresh() and v.stats.reloads == 1
    assert (v.rounds[-1].done, v.rounds[-1].step) == (False, 20)
    params, step = v.params(1)
    assert step == 20
    same = jax.tree_util.tree_map(np.array_equal, params, r1_params)
    assert all(jax.tree_util.tree_leaves(same))
    # The round finishes: its final params replace the checkpoint's.
    for path in (rundir.params_path, rundir.done_path):
      shutil.copy(path(done_r1), path(run_r1))
    assert v.refresh() and v.rounds[-1].done and v.params(1)[1] is None
    assert v.gui_model.value == 'R1'
    # With num_rounds 'auto' a finished round can be discarded: the menus mark it and a
    # viewer that followed training moves to the model the run keeps (B); the compare
    # menu keeps pointing at the same round under its new label.
    v.gui_compare.value = 'R1'
    listed = run_contents.list_rounds
    run_contents.list_rounds = lambda *a: [dataclasses.replace(ri, kept=ri.index == 0)
                                           for ri in listed(*a)]
    try:
      assert v.refresh()
    finally:
      run_contents.list_rounds = listed
    assert v._labels() == ['B (round 0)', 'R1 (discarded)']
    assert (v.gui_model.value, v.gui_compare.value) == ('B (round 0)', 'R1 (discarded)')
  finally:
    v.stop()


def test_view_py_names_a_bad_run_directory(tmp_path):
  res = subprocess.run([sys.executable, 'view.py', '--run_dir', str(tmp_path / 'nothing')],
                       cwd=REPO, capture_output=True, text=True, timeout=120)
  assert res.returncode == 2
  lines = [l for l in res.stderr.splitlines() if l.strip()]
  assert len(lines) == 1 and 'is not a run directory' in lines[0], res.stderr
