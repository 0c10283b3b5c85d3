"""The frames of the web viewer (viewer.py): a round's parameters, one render at a
browser's camera, the picture of the chosen layer, and the per-browser worker that sends a
preview while the camera moves and the full frame once it stops.

`FrameRenderer` is the rendering half of `viewer.Viewer`, which sets the attributes it
reads (config, scene, backbone, run_dir, rounds, the GUI handles, the locks, opts, stats).
"""
import dataclasses
import time
from typing import Optional

import numpy as np

from renerf_jax import figures, run_contents
from renerf_jax import view_cameras as vc
from renerf_jax.metrics import mse_to_psnr


@dataclasses.dataclass
class ViewerOptions:
  """Options of the viewer (view.py's flags)."""
  preview_side: int = 64  # Longer side of a frame while the camera moves (pixels).
  full_side: Optional[int] = None  # Longer side once it stops (None: the photos').
  settle_seconds: float = 0.25  # Camera still this long: render at full size.
  poll_seconds: float = 2.0  # How often "Follow training" looks for a new checkpoint.
  max_fps: float = 0.  # Cap on frames a second over all browsers (0: no cap).
  jpeg_quality: int = 90


@dataclasses.dataclass
class ViewerStats:
  """What the viewer did (read by tests and benchmarks)."""
  frames: int = 0  # Frames sent to browsers.
  render_seconds: float = 0.  # Time spent rendering them.
  reloads: int = 0  # Parameter loads of a round in training ("Follow training").
  last_camera: str = ''  # 'browser' or the snapped camera's name of the last frame.
  last_psnr: Optional[float] = None  # PSNR of the last frame against its photo.
  last_frame: Optional[np.ndarray] = None  # [H, W, 3] uint8 of the last frame sent.
  last_step: Optional[int] = None  # Training step of the parameters last shown.


class FrameRenderer:
  """Rendering and sending frames (a base of viewer.Viewer; see the module docstring)."""

  # ------------------------------------------------------------------------ rendering

  def params(self, r, reload=False):
    """(params, step) of round r, cached; reload=True re-reads a round in training."""
    with self._params_lock:
      if reload or r not in self._params:
        p, step = run_contents.load_params(self.config, self.run_dir, r)
        if p is not None:
          self._params[r] = (p, step)
      return self._params.get(r, (None, None))

  def render(self, r, pose, scene):
    """One view of round r.

    Args:
      r: round index. pose: [3, 4] OpenGL camera-to-world. scene: the Scene whose camera
        (size, focal, intrinsics) the frame uses.

    Returns:
      {'rgb', 'depth', 'acc'} arrays of the view, or None before r has parameters.
    """
    params, _ = self.params(r)
    if params is None:
      return None
    with self._render_lock:
      out = self.backbone.render_views(self.config, scene, params, np.asarray(pose)[None])
    return {k: np.asarray(v[0]) for k, v in out.items()}

  def frame(self, st, side):
    """The picture for one browser at the camera it has now.

    Args:
      st: the browser's state (its camera; the scene camera it snapped to, if any).
      side: pixels on the longer side (at a snapped camera: that camera's own size).

    Returns:
      ([H, W, 3] float image, PSNR against the camera's photo or None); (None, None)
      before the shown round has parameters.
    """
    cam = st.client.camera
    pose = vc.pose_from_browser(cam.wxyz, cam.position)
    layer = self.gui_layer.value
    snapped = st.snapped if self._at_snapped(st, pose) else None
    stored_u = None  # The Laplace uncertainty a pseudo-view was masked with.
    if snapped is not None:
      scene, pose, photo = vc.scene_camera_scene(self.scene), snapped[2], snapped[3]
      if layer == 'uncertainty':
        stored_u = snapped[4]
    else:
      h, w = vc.render_size(cam.aspect, side)
      scene = vc.view_scene(self.scene, h, w, vc.focal_for_fov(h, cam.fov))
      photo = None
    psnr = None

    def picture(r):
      nonlocal psnr
      out = self.render(r, pose, scene)
      if out is None:
        return None
      if photo is not None:
        mse = float(np.mean((np.clip(out['rgb'], 0., 1.) - photo[..., :3])**2))
        psnr = psnr if psnr is not None else float(mse_to_psnr(mse))
      if layer == 'error' and photo is None:
        return vc.layer_image('rgb', out) * .35  # Dimmed: no photo at this camera.
      if stored_u is not None:
        return stored_u
      return vc.layer_image(layer, out, photo)

    a = picture(self._round_of(self.gui_model.value))
    if a is None:
      return None, None
    other = self._round_of(self.gui_compare.value)
    if other is not None:
      b = picture(other)
      if b is not None:
        a = vc.split_view(a, b, self.gui_split.value)
    if snapped is not None:
      a = vc.letterbox(a, cam.aspect)
    return a, psnr

  def _worker(self, st):
    """Per browser: a preview frame at each camera change, the full frame once still."""
    done_full_for = None
    while not st.closed and not self._stop.is_set():
      st.wake.wait(timeout=self.opts.settle_seconds)
      st.wake.clear()
      if st.closed or self._stop.is_set():
        return
      req = st.requested
      if req is None:
        continue
      try:
        done_full_for = self._serve(st, req, done_full_for)
      except Exception as e:  # pylint: disable=broad-except
        # A frame that fails (e.g. a camera the backbone rejects) is reported in the
        # panel; the viewer keeps serving this browser.
        self.gui_status.content = f'render failed: {type(e).__name__}: {e}'
        done_full_for = req

  def _serve(self, st, req, done_full_for):
    """One pass of a browser's worker: a preview or the full frame for request `req`.
    Returns the request whose full frame has been sent."""
    full_side = int(self.gui_side.value)
    cam = st.client.camera
    at_snap = self._at_snapped(st, vc.pose_from_browser(cam.wxyz, cam.position))
    # A preview only where it is smaller than the full frame (a snapped camera renders
    # its own size either way).
    still = (time.perf_counter() - req >= self.opts.settle_seconds or
             self.opts.preview_side >= full_side or at_snap)
    if still and done_full_for == req:
      return done_full_for
    side = full_side if still else self.opts.preview_side
    self._throttle()
    t0 = time.perf_counter()
    img, psnr = self.frame(st, side)
    dt = time.perf_counter() - t0
    if img is None:
      return done_full_for
    picture = figures.to_uint8(img)
    st.client.scene.set_background_image(picture, format='jpeg',
                                         jpeg_quality=self.opts.jpeg_quality)
    s = self.stats
    s.frames += 1
    s.render_seconds += dt
    s.last_frame = picture
    s.last_camera = st.snapped[0] if at_snap else 'browser'
    s.last_psnr = psnr
    r = self._round_of(self.gui_model.value)
    s.last_step = self._params.get(r, (None, None))[1]
    self._status(img.shape, dt, psnr, r)
    if still:
      return req
    if st.requested == req:  # Nothing newer: come back for the full frame.
      st.wake.set()
      time.sleep(max(0., self.opts.settle_seconds - (time.perf_counter() - req)))
    return done_full_for

  def _throttle(self):
    if self.opts.max_fps > 0:
      wait = self._last_frame_time + 1. / self.opts.max_fps - time.perf_counter()
      if wait > 0:
        time.sleep(wait)
    self._last_frame_time = time.perf_counter()

  def _status(self, shape, dt, psnr, r):
    info = next((ri for ri in self.rounds if ri.index == r), None)
    lines = [f'frame {shape[1]}x{shape[0]} in {dt * 1e3:.0f} ms']
    if psnr is not None:
      lines.append(f'PSNR against the photo: {psnr:.2f} dB')
    if info is not None and not info.done:
      rec = self._log_record or {}
      step = self._params.get(r, (None, None))[1]
      lines.append(f'training: showing step {step}; log at step {rec.get("step")}'
                   + (f', loss {rec["loss"]:.4f}' if 'loss' in rec else ''))
    self.gui_status.content = '  \n'.join(lines)
