"""A screenshot of the web viewer on a finished run (the picture in the README).

python -m experiments.viewer_screenshot --run_dir RUN --out experiments/results/viewer/screenshot.png

Opens the viewer (renerf_jax/viewer.py) on RUN in headless Chromium
(benchmarks/browser.py), steps back from the first training camera by --back frustum
sizes so the cameras are in view, shows the last round on the left and B on the right
(split at the middle), waits for the full frame and saves the page.
"""
import argparse
import time

import numpy as np

from benchmarks.browser import launch
from benchmarks.ports import free_port


def main():
  p = argparse.ArgumentParser(description=__doc__,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
  p.add_argument('--run_dir', required=True)
  p.add_argument('--out', required=True)
  p.add_argument('--back', type=float, default=6.)
  p.add_argument('--layer', default='rgb')
  p.add_argument('--width', type=int, default=1200)
  p.add_argument('--height', type=int, default=700)
  args = p.parse_args()
  from playwright.sync_api import sync_playwright  # pylint: disable=g-import-not-at-top
  from renerf_jax.viewer import Viewer  # pylint: disable=g-import-not-at-top
  viewer = Viewer(args.run_dir, port=free_port())
  try:
    labels = [ri.label for ri in viewer.rounds]
    viewer.gui_model.value = labels[-1]
    viewer.gui_compare.value = labels[0] if len(labels) > 1 else 'none'
    viewer.gui_layer.value = args.layer
    with sync_playwright() as pw:
      browser = launch(pw)
      page = browser.new_page(viewport={'width': args.width, 'height': args.height})
      page.goto(f'http://127.0.0.1:{viewer.server.get_port()}')
      t0 = time.time()
      while not viewer._clients and time.time() - t0 < 120:  # pylint: disable=protected-access
        time.sleep(.2)
      client = next(iter(viewer._clients.values())).client  # pylint: disable=protected-access
      pose = np.asarray(viewer.scene.poses[viewer.scene.train_idx[0]], np.float64).copy()
      pose[:, 3] += args.back * viewer.scale * pose[:, 2]  # OpenGL +z points backwards.
      viewer._set_camera(client, pose, client.camera.fov)  # pylint: disable=protected-access
      frames = viewer.stats.frames
      t0 = time.time()
      while time.time() - t0 < 300:
        time.sleep(1.)
        if viewer.stats.frames > frames and viewer.stats.last_frame is not None and \
            max(viewer.stats.last_frame.shape[:2]) == viewer.opts.full_side:
          break
      time.sleep(3.)
      for button in page.locator('.mantine-Notification-root button').all():
        button.click()  # The "software WebGL" notice.
      time.sleep(1.)
      page.screenshot(path=args.out)
      browser.close()
  finally:
    viewer.stop()
  print(f'wrote {args.out}')


if __name__ == '__main__':
  main()
