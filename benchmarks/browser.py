"""Headless Chromium for the viewer's browser test and benchmark (Playwright driving
Debian's chromium; no browser download)."""
import os

CHROMIUM = os.environ.get('RENERF_CHROMIUM', '/usr/bin/chromium')
# A headless Chromium on a machine without a GPU or outside network: software WebGL
# (SwiftShader) and no background connections.
CHROMIUM_ARGS = ['--headless=new', '--no-sandbox', '--disable-gpu', '--disable-quic',
                 '--no-first-run', '--disable-background-networking',
                 '--disable-component-update', '--disable-sync', '--use-angle=swiftshader',
                 '--enable-unsafe-swiftshader']


def launch(playwright):
  """A headless Chromium browser (playwright.chromium.launch)."""
  return playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)


def drag(page, dx, dy, start=(.4, .5), steps=12):
  """Drags the mouse across the page's 3D canvas (the viewer's orbit control)."""
  box = page.locator('canvas').first.bounding_box()
  x, y = box['x'] + box['width'] * start[0], box['y'] + box['height'] * start[1]
  page.mouse.move(x, y)
  page.mouse.down()
  page.mouse.move(x + dx, y + dy, steps=steps)
  page.mouse.up()

