"""experiments/phase_times.py: a round timed by phase (renerf.round_step with a backbone
whose phases take known times)."""
import json
import time
import types

import numpy as np
import pytest

from experiments import phase_times
from renerf_jax import backbones, evaluation, fit
from renerf_jax.pseudo_views import PseudoViews

# Seconds each fake phase sleeps.
SLEEP = {'step': 0.02, 'cheap': 0.03, 'synth': 0.05, 'test': 0.04, 'val': 0.06}


def fake_backbone(scene_of_test):
  """A backbone whose phases sleep SLEEP's seconds: training 4 steps with a cheap
  evaluation after steps 2 and 4, 3 pseudo-views, evaluations of 17.0 (test) and 18.0
  (validation) dB; its Gaussians' count is 5 in B and 7 in D."""

  def train(config, scene, out_dir, pseudo, eval_fn=None, **kw):
    del config, scene, out_dir, kw
    n = 5 if pseudo is None else 7
    params = types.SimpleNamespace(active=np.arange(9) < n)
    curve, spent = [], 0.
    for step in range(1, 5):
      time.sleep(SLEEP['step'] * (3 if step == 1 else 1))  # The first step compiles.
      spent += SLEEP['step'] * (3 if step == 1 else 1)
      if step % 2 == 0:
        curve.append({'step': step, 'train_seconds': spent, 'eval_psnr': eval_fn(params)})
    return fit.TrainResult(state=types.SimpleNamespace(params=params, nan_skips=0),
                           train_seconds=spent, curve=curve)

  def cheap_eval_fn(config, scene):
    def fn(params):
      time.sleep(SLEEP['cheap'])
      return 15.
    return fn

  def synthesize(config, scene, params, show_progress=False):
    time.sleep(SLEEP['synth'])
    h, w = scene.height, scene.width
    pv = PseudoViews(images=np.zeros((3, h, w, 3)), poses=np.zeros((3, 3, 4)),
                     masks=np.ones((3, h, w)), uncertainty=np.zeros((3, h, w)))
    return pv, {'seconds': SLEEP['synth']}, {}

  def evaluate(config, scene, params, show_progress=False):
    test = scene is scene_of_test
    time.sleep(SLEEP['test' if test else 'val'])
    psnr = 17. if test else 18.
    return evaluation.Evaluation(per_image=[], mean={'psnr': psnr}, images=None,
                                 distances=None, columns=[])

  return backbones.Backbone(name='fake', init_params=None, train=train,
                            synthesize=synthesize, cheap_eval_fn=cheap_eval_fn,
                            evaluate=evaluate, render_views=None)


def test_each_phase_is_timed_and_the_phases_add_up_to_the_round(tmp_path, monkeypatch):
  from renerf_jax.datasets import load_scene  # pylint: disable=g-import-not-at-top
  real_load = load_scene
  scenes = []

  def load(config):
    scenes.append(real_load(config))
    return scenes[-1]
  monkeypatch.setattr(phase_times, 'load_scene', load)
  monkeypatch.setattr(backbones, 'get_backbone', lambda cfg: fake_backbone(scenes[-1]))
  bindings = ["Config.dataset_loader = 'procedural'", 'Config.procedural_size = (16, 20)',
              'Config.procedural_views = 17', 'Config.n_input_views = 3',
              'Config.val_views = 2', 'Config.max_steps = 4',
              'Config.anneal_nearfar_steps = 1', 'Config.pseudo_until_frac = 0.5']
  phase_times.main(['--config', 'gin_configs/demo_llff.gin', '--data_dir', 'unused',
                    '--scene', 'procedural', '--out', str(tmp_path), '--name', 'p']
                   + [f'--gin_bindings={b}' for b in bindings])
  result = json.loads((tmp_path / 'p.json').read_text())
  ph = result['phases']
  for stage in ('B', 'R1'):
    train = ph[f'{stage} training (steps, compile, cheap evaluations)']
    assert ph[f'{stage} cheap evaluations'] >= 2 * SLEEP['cheap']
    assert train >= 6 * SLEEP['step'] + ph[f'{stage} cheap evaluations']
    assert ph[f'{stage} final evaluation (test views)'] >= SLEEP['test']
    assert ph[f'{stage} final evaluation (validation views)'] >= SLEEP['val']
    parts = (train + ph[f'{stage} final evaluation (test views)']
             + ph[f'{stage} final evaluation (validation views)']
             + ph.get(f'{stage} pseudo-views', 0.))
    assert parts <= ph[f'{stage} round (all of it)']
  assert ph['R1 pseudo-views'] >= SLEEP['synth'] and 'B pseudo-views' not in ph
  rounds = result['rounds']
  assert [r['steps'] for r in rounds] == [4, 4]
  # Steady seconds a step: from the first to the last cheap evaluation (step 2 to 4),
  # leaving out the first (compiling) step.
  assert rounds[0]['seconds_per_step'] == pytest.approx(SLEEP['step'])
  assert [(r['psnr'], r['val_psnr']) for r in rounds] == [(17., 18.), (17., 18.)]
  assert [(e['stage'], e['gaussians']) for e in result['gaussians']] == [
      ('B', 5), ('B', 5), ('R1', 7), ('R1', 7)]
  assert result['pseudo_views'] == {'views': 3} and result['resolution'] == [20, 16]
  md = (tmp_path / 'p.md').read_text()
  assert '| R1 pseudo-views |' in md and 'Gaussians at the cheap evaluations: B: 5, 5' in md
  assert 'python -m experiments.phase_times --config gin_configs/demo_llff.gin' in md


def test_steady_seconds_a_step_needs_two_records():
  assert phase_times.steady_seconds_per_step([{'step': 5, 'train_seconds': 2.}]) is None
  assert phase_times.steady_seconds_per_step(
      [{'step': 5, 'train_seconds': 2.}, {'step': 15, 'train_seconds': 3.}]) == 0.1
