"""The web viewer of a run (view.py): a viser server that renders the chosen round's
model from the camera each browser moves, beside the run's cameras.

- Any backbone: frames come from Backbone.render_views at a scene with the browser's
  camera (view_cameras.view_scene), first at a preview size, then, once the camera has
  stopped for `settle_seconds`, at the full size.
- The scene holds the training (blue), test (green) and the shown round's pseudo-view
  (orange) cameras as frustums with their images (pseudo-views tinted where masked).
  Clicking a frustum, or the "Go to camera" button, moves the browser to that camera;
  while the browser sits there, frames use that camera's own intrinsics, and the
  'error' layer and the PSNR compare the render with the photo (for a pseudo-view: with
  the pseudo-view image D was trained on, and the 'uncertainty' layer shows the
  uncertainty its masks were cut from, when the run used masks).
- Elsewhere the 'uncertainty' layer is 1 - accumulated opacity, the project's default
  mask signal (the Laplace field needs B's Hessian, computed only for pseudo-views).
- Two rounds side by side: "Compare with" splits the frame at the "Split" slider
  (left: Model, right: the other round).
- Live: with "Follow training" on, the viewer polls the unfinished round's training
  checkpoints every `poll_seconds` and shows the newest parameters. It only reads files,
  so training is slowed by the CPU the renders take (measured in
  experiments/results/viewer/).

The server's state (which frames went out, the rendering time) is kept for tests and the
benchmark in `stats`.
"""
import dataclasses
import threading
import time
from typing import Optional

import numpy as np

from renerf_jax import figures, run_contents
from renerf_jax import view_cameras as vc
from renerf_jax.backbones import get_backbone
from renerf_jax.pseudo_views import uncertainty_heatmap
from renerf_jax.viewer_frames import FrameRenderer, ViewerOptions, ViewerStats

TRAIN_COLOUR, TEST_COLOUR, PSEUDO_COLOUR = (40, 90, 230), (30, 170, 60), (240, 140, 20)
NONE = 'none'


def camera_list(scene, pseudo):
  """[(name, kind, pose [3, 4], image [H, W, 3] or None)] of the cameras to draw: the
  training views, the test views and the pseudo-views (their masked images)."""
  out = [(f'train {i}', 'train', scene.poses[i], scene.images[i]) for i in scene.train_idx]
  out += [(f'test {i}', 'test', scene.poses[i], scene.images[i]) for i in scene.test_idx]
  if pseudo is not None:
    for j in range(len(pseudo.poses)):
      out.append((f'pseudo {j}', 'pseudo', np.asarray(pseudo.poses[j]),
                  vc.masked_view(pseudo.images[j], pseudo.masks[j])))
  return out


class Viewer(FrameRenderer):
  """A viser server showing one run directory (see the module docstring)."""

  def __init__(self, run_dir, host='127.0.0.1', port=8080,
               options: Optional[ViewerOptions] = None):
    import viser  # pylint: disable=g-import-not-at-top
    self.run_dir, self.opts = run_dir, options or ViewerOptions()
    self.config, self.scene = run_contents.open_run(run_dir)
    self.backbone = get_backbone(self.config)
    self.stats = ViewerStats()
    self.rounds = run_contents.list_rounds(self.config, run_dir)
    if not self.rounds:
      from renerf_jax.errors import RunDirError  # pylint: disable=g-import-not-at-top
      raise RunDirError(f'{run_dir} has no trained parameters yet (no finished round and '
                        'no checkpoint); wait for the first checkpoint')
    self._params = {}  # round -> (params, step)
    # The last training-log record of the round in training, read with its checkpoint.
    self._log_record = (None if self.rounds[-1].done else
                        run_contents.last_log_record(run_dir, self.rounds[-1].index))
    self._params_lock = threading.Lock()
    self._render_lock = threading.Lock()  # One render at a time (the CPU is shared).
    self._clients = {}  # client id -> _ClientState
    self._last_frame_time = 0.
    self._stop = threading.Event()
    self.server = viser.ViserServer(host=host, port=port, verbose=False,
                                    label='renerf-jax')
    if self.opts.full_side is None:
      self.opts = dataclasses.replace(self.opts, full_side=max(self.scene.height,
                                                                self.scene.width))
    self.scale = vc.frustum_scale(self.scene.poses)
    self._frustums = []
    self._build_gui()
    self._draw_cameras()
    self.server.on_client_connect(self._on_connect)
    self.server.on_client_disconnect(self._on_disconnect)
    self._poller = threading.Thread(target=self._poll, daemon=True)
    self._poller.start()

  # ----------------------------------------------------------------------------- GUI

  def _labels(self):
    return [ri.label for ri in self.rounds]

  def _round_of(self, label) -> Optional[int]:
    for ri in self.rounds:
      if ri.label == label:
        return ri.index
    return None

  def _build_gui(self):
    gui = self.server.gui
    c = self.config
    gui.add_markdown(f'**{self.run_dir}**  \n{self.scene.name}, backbone '
                     f'`{c.backbone}`, {len(self.scene.train_idx)} training views')
    labels = self._labels()
    self.gui_model = gui.add_dropdown(
        'Model', labels, initial_value=labels[run_contents.shown_round(self.rounds)])
    self.gui_compare = gui.add_dropdown('Compare with', [NONE] + labels, initial_value=NONE)
    self.gui_split = gui.add_slider('Split', 0., 1., .01, .5)
    self.gui_layer = gui.add_dropdown('Layer', vc.LAYERS, initial_value='rgb')
    side = int(self.opts.full_side)
    self.gui_side = gui.add_slider('Resolution', min(16, side), max(1024, side), 1, side)
    self.gui_follow = gui.add_checkbox('Follow training', initial_value=True)
    names = [name for name, *_ in self._cameras()]
    self.gui_camera = gui.add_dropdown('Camera', names, initial_value=names[0])
    self.gui_go = gui.add_button('Go to camera')
    self.gui_status = gui.add_markdown('')
    self.gui_decisions = gui.add_markdown(decisions_text(self.rounds))
    for h in (self.gui_model, self.gui_compare, self.gui_split, self.gui_layer,
              self.gui_side):
      h.on_update(lambda _: self._request_all())
    self.gui_model.on_update(lambda _: self._draw_cameras())

    @self.gui_go.on_click
    def _(event):
      self.snap(event.client, self.gui_camera.value)

  def _cameras(self):
    r = self._round_of(self.gui_model.value) if hasattr(self, 'gui_model') else None
    pseudo = run_contents.round_pseudo_views(self.run_dir, r) if r else None
    return camera_list(self.scene, pseudo)

  def _draw_cameras(self):
    """(Re)draws the frustums: training, test and the shown round's pseudo-views."""
    for h in self._frustums:
      h.remove()
    self._frustums = []
    cams = self._cameras()
    colours = {'train': TRAIN_COLOUR, 'test': TEST_COLOUR, 'pseudo': PSEUDO_COLOUR}
    fov = vc.fov_y(self.scene.height, self.scene.focal)
    aspect = self.scene.width / self.scene.height
    for name, kind, pose, image in cams:
      wxyz, pos = vc.browser_from_pose(pose)
      h = self.server.scene.add_camera_frustum(
          f'/cameras/{name.replace(" ", "_")}', fov=fov, aspect=aspect, scale=self.scale,
          thickness=1.5, thickness_units='screen', color=colours[kind],
          image=None if image is None else figures.to_uint8(image), wxyz=wxyz, position=pos)
      h.on_click(lambda event, name=name: self.snap(event.client, name))
      self._frustums.append(h)
    if hasattr(self, 'gui_camera'):
      self.gui_camera.options = [name for name, *_ in cams]

  # ------------------------------------------------------------------------- clients

  def _on_connect(self, client):
    st = _ClientState(client)
    self._clients[client.client_id] = st
    pose = self.scene.poses[self.scene.train_idx[0]]
    client.camera.up_direction = vc.mean_up(self.scene.poses)
    self._set_camera(client, pose, vc.fov_y(self.scene.height, self.scene.focal))
    client.camera.on_update(lambda _: self._request(st))
    st.thread = threading.Thread(target=self._worker, args=(st,), daemon=True)
    st.thread.start()
    self._request(st)

  def _on_disconnect(self, client):
    st = self._clients.pop(client.client_id, None)
    if st is not None:
      st.closed = True
      st.wake.set()

  def _set_camera(self, client, pose, fov):
    wxyz, pos = vc.browser_from_pose(pose)
    forward = -np.asarray(pose, np.float64)[:3, 2]
    with client.atomic():
      client.camera.fov = fov
      client.camera.position = pos
      client.camera.look_at = pos + forward * float(self.scene.focus_depth)
      client.camera.wxyz = wxyz

  def snap(self, client, name):
    """Moves a browser's camera to the named scene camera ('train 0', 'pseudo 3', ...)."""
    for cam_name, kind, pose, image in self._cameras():
      if cam_name == name:
        st = self._clients.get(client.client_id)
        if st is not None:
          st.snapped = self.snapped_camera(cam_name, kind, pose, image)
        self._set_camera(client, pose, vc.fov_y(self.scene.height, self.scene.focal))
        if st is not None:
          self._request(st)
        return
    raise KeyError(f'no camera named {name!r}')

  def snapped_camera(self, name, kind, pose, image):
    """What a frame at a scene camera compares with, fixed when the browser snaps there:
    (name, kind, pose, photo, uncertainty or None). For a pseudo-view: the pseudo-view
    image D trained on, and the uncertainty its mask was cut from (None without masks)."""
    photo, u = image, None
    if kind == 'pseudo':
      pv = run_contents.round_pseudo_views(self.run_dir,
                                           self._round_of(self.gui_model.value))
      j = int(name.split()[1])
      photo = np.asarray(pv.images[j])
      if np.any(pv.uncertainty):
        u = uncertainty_heatmap(pv.uncertainty[j], pv.uncertainty)
    return (name, kind, np.asarray(pose, np.float32), photo, u)

  def _at_snapped(self, st, pose):
    """Whether the browser sits at the camera it last snapped to (a camera message sent
    before the snap arrives later with the old pose: it does not cancel the snap)."""
    return st.snapped is not None and _same_pose(pose, st.snapped[2])

  def _request(self, st):
    st.requested = time.perf_counter()
    st.wake.set()

  def _request_all(self):
    for st in list(self._clients.values()):
      self._request(st)

  # -------------------------------------------------------------------------- live

  def _poll(self):
    """Follow training: newer checkpoints of the round in training, new rounds."""
    while not self._stop.wait(self.opts.poll_seconds):
      if not self.gui_follow.value:
        continue
      try:
        self.refresh()
      except Exception as e:  # pylint: disable=broad-except
        self.gui_status.content = f'refresh failed: {type(e).__name__}: {e}'

  def refresh(self) -> bool:
    """Re-reads the run's rounds: lists new ones (and shows the newest when "Follow
    training" is on and the newest was shown) and loads a newer checkpoint of the round
    in training.

    Returns:
      Whether anything changed (then every browser gets a new frame).
    """
    rounds = run_contents.list_rounds(self.config, self.run_dir)
    old = {ri.index: ri for ri in self.rounds}
    new_rounds = [ri.label for ri in rounds] != self._labels()
    changed = new_rounds
    if new_rounds:
      following = self.gui_model.value == self._labels()[-1]
      # By round index: a label changes when an 'auto' decision discards its round.
      model, compare = self._round_of(self.gui_model.value), self._round_of(
          self.gui_compare.value)
      self.rounds = rounds
      labels = self._labels()
      self.gui_model.options = labels
      self.gui_compare.options = [NONE] + labels
      by_index = {ri.index: ri.label for ri in rounds}
      if following and self.gui_follow.value:  # A round just discarded: the kept one.
        self.gui_model.value = labels[run_contents.shown_round(rounds)]
      elif model in by_index:
        self.gui_model.value = by_index[model]
      self.gui_compare.value = by_index.get(compare, NONE)
    else:
      self.rounds = rounds
    self.gui_decisions.content = decisions_text(rounds)
    for ri in rounds:  # A round that finished since: its final params replace the last
      if ri.done and ri.index in old and not old[ri.index].done:  # checkpoint's.
        with self._params_lock:
          self._params.pop(ri.index, None)
        changed = True
    live = rounds[-1]
    if not live.done:
      have = self._params.get(live.index, (None, None))[1]
      if have != live.step:
        self.params(live.index, reload=True)
        self._log_record = run_contents.last_log_record(self.run_dir, live.index)
        self.stats.reloads += 1
        changed = True
    if changed:
      self._request_all()
    return changed

  def stop(self):
    self._stop.set()
    for st in list(self._clients.values()):
      st.closed = True
      st.wake.set()
    self.server.stop()


def decisions_text(rounds) -> str:
  """The viewer's account of Config.num_rounds = 'auto': each finished round's decision
  (empty for a run without them)."""
  return '  \n'.join(ri.decision for ri in rounds if ri.decision)


@dataclasses.dataclass(eq=False)
class _ClientState:
  client: object
  wake: threading.Event = dataclasses.field(default_factory=threading.Event)
  requested: Optional[float] = None
  # (name, kind, pose, photo, uncertainty) of the scene camera it last snapped to.
  snapped: Optional[tuple] = None
  closed: bool = False
  thread: Optional[threading.Thread] = None


def _same_pose(a, b, tol=1e-3):
  """Whether two [3, 4] poses agree to `tol` (rotation entries and position relative to
  its scale): the browser echoes a camera we set with float rounding."""
  a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
  scale = max(1., float(np.abs(b[:, 3]).max()))
  return (np.abs(a[:, :3] - b[:, :3]).max() < tol and
          np.abs(a[:, 3] - b[:, 3]).max() < tol * scale)
