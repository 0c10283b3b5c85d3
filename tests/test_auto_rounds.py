"""Config.num_rounds = 'auto' (renerf_jax/auto_rounds.py): the decision on validation
views, its extreme inputs, and the rounds it trains in memory and on disk."""
import dataclasses
import json
import math
import types

import numpy as np
import pytest

from renerf_jax import auto_rounds, backbones, evaluation, fit, renerf, round_driver, rundir
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene
from renerf_jax.errors import ConfigError
from renerf_jax.pseudo_views import PseudoViews

BINDINGS = ["Config.dataset_loader = 'procedural'", 'Config.procedural_size = (32, 40)',
            'Config.procedural_views = 17', 'Config.n_input_views = 3',
            'Config.val_views = 3', 'Config.max_steps = 4', 'Config.anneal_nearfar_steps = 1',
            'Config.pseudo_until_frac = 0.5',
            "Config.lpips_nets = ('alex',)", "Config.num_rounds = 'auto'"]


# ------------------------------------------------------------------------- the decision


def test_a_gain_above_its_standard_error_is_kept():
  d = auto_rounds.decide(1, [20., 21., 22., 23.], [20.5, 21.4, 22.6, 23.5], 1.)
  gains = np.array([0.5, 0.4, 0.6, 0.5])
  assert d['take'] and d['round'] == 1 and d['views'] == 4
  assert d['gain'] == pytest.approx(gains.mean())
  assert d['se'] == pytest.approx(gains.std(ddof=1) / 2.)
  assert d['line'] == ('round 1 kept: validation gain +0.50 +- 0.04 dB (4 views), above 1 '
                       'standard errors')


def test_a_gain_within_its_noise_or_a_loss_is_discarded():
  noisy = auto_rounds.decide(2, [20., 21., 22.], [21., 20.5, 22.2], 1.)
  assert not noisy['take'] and noisy['gain'] > 0. and noisy['gain'] < noisy['se']
  assert noisy['line'].startswith('round 2 discarded, the run keeps round 1: validation '
                                  'gain +0.23 +- ')
  assert noisy['line'].endswith('(3 views), within 1 standard errors')
  loss = auto_rounds.decide(1, [20., 21.], [19., 20.], 0.)
  assert not loss['take'] and loss['gain'] == -1.
  assert loss['line'] == ('round 1 discarded, the run keeps B: validation gain -1.00 +- '
                          '0.00 dB (2 views), not above 0')
  # Equal renders: no gain, discarded whatever the threshold.
  assert not auto_rounds.decide(1, [20., 20.], [20., 20.], 0.)['take']


def test_the_threshold_is_a_multiple_of_the_standard_error():
  prev, cand = [20., 21., 22., 23.], [20.3, 21.5, 22.2, 23.4]  # mean 0.35, se 0.065
  se = auto_rounds.decide(1, prev, cand, 0.)['se']
  k_edge = 0.35 / se
  assert auto_rounds.decide(1, prev, cand, k_edge * 0.99)['take']
  assert not auto_rounds.decide(1, prev, cand, k_edge * 1.01)['take']
  # A constant gain has no spread: any positive gain exceeds any multiple of 0.
  d = auto_rounds.decide(1, [20., 21.], [20.1, 21.1], 1e9)
  assert d['take'] and d['se'] == pytest.approx(0., abs=1e-12)


def test_non_finite_psnrs():
  nan, inf = float('nan'), float('inf')
  d = auto_rounds.decide(1, [20., 21.], [nan, 25.], 0.)
  assert not d['take'] and 'NaN' in d['line'] and math.isnan(d['gain'])
  d = auto_rounds.decide(1, [nan, 21.], [20., 21.], 0.)
  assert d['take'] and d['line'] == 'round 1 kept: a validation PSNR of B is NaN'
  # Exact renders (PSNR inf): both exact counts as no change, one exact as a gain or loss.
  d = auto_rounds.decide(1, [inf, 20.], [inf, 21.], 0.)
  assert d['take'] and d['gain'] == 0.5 and np.isfinite(d['se'])
  assert auto_rounds.decide(1, [20., 20.], [inf, 20.], 1.)['take']
  d = auto_rounds.decide(1, [inf, 20.], [30., 20.], 0.)
  assert not d['take'] and d['gain'] == -inf


def test_bad_shapes_are_refused():
  for prev, cand in [([20.], [21.]), ([20., 21.], [20.]), ([], []),
                     ([[20., 21.]], [[20., 21.]])]:
    with pytest.raises(ValueError, match='need two equal lists'):
      auto_rounds.decide(1, prev, cand, 1.)


def test_selected_round_and_stopping():
  kept = lambda r: {'round': r, 'auto': {'take': True}}
  dropped = lambda r: {'round': r, 'auto': {'take': False}}
  assert auto_rounds.selected_round([{'round': 0}]) == 0
  assert auto_rounds.selected_round([{'round': 0}, kept(1), kept(2)]) == 2
  assert auto_rounds.selected_round([{'round': 0}, kept(1), dropped(2)]) == 1
  assert auto_rounds.selected_round([{'round': 0}, dropped(1)]) == 0
  assert auto_rounds.selected_round([{'round': 0}, {'round': 1}]) == 1  # integer rounds
  cfg = types.SimpleNamespace(num_rounds='auto', auto_max_rounds=2)
  assert not auto_rounds.stops_after(cfg, [{'round': 0}])
  assert not auto_rounds.stops_after(cfg, [{'round': 0}, kept(1)])
  assert auto_rounds.stops_after(cfg, [{'round': 0}, dropped(1)])
  assert auto_rounds.stops_after(cfg, [{'round': 0}, kept(1), kept(2)])
  fixed = types.SimpleNamespace(num_rounds=3, auto_max_rounds=5)
  assert auto_rounds.max_rounds(fixed) == 3 and auto_rounds.max_rounds(cfg) == 2
  # An integer count trains on past a decision stored by an earlier 'auto' invocation.
  assert not auto_rounds.stops_after(fixed, [{'round': 0}, dropped(1)])
  assert auto_rounds.stops_after(fixed, [{'round': 0}, kept(1), kept(2), dropped(3)])
  none = types.SimpleNamespace(num_rounds=0, auto_max_rounds=5)
  assert auto_rounds.max_rounds(none) == 0 and auto_rounds.stops_after(none, [{'round': 0}])


def test_auto_needs_two_validation_views():
  config = load_config(['demo_llff.gin'], BINDINGS + ['Config.val_views = 1'])
  with pytest.raises(ConfigError) as e:
    renerf.check_rounds_config(config, load_scene(config))
  assert str(e.value) == ("Config.num_rounds='auto' decides on validation views, and scene "
                          "'procedural' has 1 (Config.val_views=1); set Config.val_views >= "
                          '2 or an integer Config.num_rounds')


def test_num_rounds_domain():
  assert load_config(['demo_llff.gin'], BINDINGS).num_rounds == 'auto'
  for bad in ["'Auto'", "'2'", '-1', '1.0', 'True']:
    with pytest.raises(ConfigError) as e:
      load_config(['demo_llff.gin'], [f'Config.num_rounds = {bad}'])
    assert str(e.value).endswith("must be an integer >= 0 or 'auto'"), str(e.value)


# ------------------------------------------------------------- rounds with a fake model


def fake_backbone(val_psnrs, calls):
  """A backbone whose round r's model scores val_psnrs[r] (per view) on the validation
  views and 17 dB on the test views; `calls` counts its trainings."""

  def train(config, scene, out_dir, pseudo, **kw):
    del scene, out_dir, pseudo, kw
    r = config.seed // 1000  # renerf.round_config: D's seed is B's + 1000 r.
    calls.append(r)
    return fit.TrainResult(state=types.SimpleNamespace(
        params={'round': np.array([r], np.int32)}, nan_skips=0), train_seconds=1.,
                           curve=[])

  def synthesize(config, scene, params, show_progress=False):
    h, w = scene.height, scene.width
    return PseudoViews(images=np.zeros((2, h, w, 3), np.float32),
                       poses=np.zeros((2, 3, 4), np.float32),
                       masks=np.ones((2, h, w), np.float32),
                       uncertainty=np.zeros((2, h, w), np.float32)), {'seconds': 0.5}, {}

  def evaluate(config, scene, params, show_progress=False):
    r = int(params['round'][0])
    is_val = np.array_equal(scene.test_idx, VAL_IDX[0])
    views = val_psnrs[r] if is_val else [17.] * len(scene.test_idx)
    n, h, w = len(views), scene.height, scene.width
    return evaluation.Evaluation(
        per_image=[{'name': f'test_{i:03d}', 'psnr': v} for i, v in enumerate(views)],
        mean={'psnr': float(np.mean(views))}, images=np.zeros((n, h, w, 3), np.float32),
        distances=np.zeros((n, h, w), np.float32), columns=(('name', 'view'), ('psnr', 'PSNR')))

  return backbones.Backbone(
      name='fake', init_params=lambda cfg: {'round': np.zeros(1, np.int32)}, train=train,
      synthesize=synthesize, cheap_eval_fn=lambda cfg, sc: None, evaluate=evaluate,
      render_views=None)


VAL_IDX = [None]
GAINS = [[20., 21., 22.], [20.6, 21.5, 22.7], [21.2, 22.1, 23.2], [21.3, 22.0, 23.3]]


def _scene_and_config(extra=()):
  config = load_config(['demo_llff.gin'], BINDINGS + list(extra))
  scene = load_scene(config)
  VAL_IDX[0] = np.asarray(scene.val_idx)
  return config, scene


def test_in_memory_a_scene_that_says_go_trains_until_a_round_stops_paying(monkeypatch):
  config, scene = _scene_and_config(['Config.auto_max_rounds = 5'])
  calls = []
  monkeypatch.setattr(backbones, 'get_backbone', lambda cfg: fake_backbone(GAINS, calls))
  state = renerf.run_rounds(config, scene)
  # R1 and R2 gain ~0.6 dB on every view; R3 moves by +0.1, -0.1, +0.1: within its noise.
  assert calls == [0, 1, 2, 3]
  assert [m['auto']['take'] for m in state.metrics[1:]] == [True, True, False]
  assert auto_rounds.selected_round(state.metrics) == 2
  assert state.metrics[1]['val_psnr_views'] == GAINS[1]
  again = renerf.run_rounds(config, scene)  # Deterministic for a seed.
  assert [m['auto'] for m in again.metrics[1:]] == [m['auto'] for m in state.metrics[1:]]


def test_in_memory_a_scene_that_says_stop_trains_no_further_round(monkeypatch):
  config, scene = _scene_and_config()
  calls = []
  losing = [GAINS[0], [19.9, 21.2, 21.7]]
  monkeypatch.setattr(backbones, 'get_backbone', lambda cfg: fake_backbone(losing, calls))
  state = renerf.run_rounds(config, scene)
  assert calls == [0, 1] and len(state.metrics) == 2
  assert not state.metrics[1]['auto']['take']
  assert auto_rounds.selected_round(state.metrics) == 0


def test_auto_max_rounds_caps_the_rounds(monkeypatch):
  config, scene = _scene_and_config(['Config.auto_max_rounds = 2'])
  calls = []
  monkeypatch.setattr(backbones, 'get_backbone', lambda cfg: fake_backbone(GAINS, calls))
  state = renerf.run_rounds(config, scene)
  assert calls == [0, 1, 2] and auto_rounds.selected_round(state.metrics) == 2


def test_on_disk_the_decisions_resume_and_nothing_trains_again(tmp_path, monkeypatch):
  from renerf_jax import run_contents  # pylint: disable=g-import-not-at-top
  config, scene = _scene_and_config(['Config.auto_max_rounds = 5'])
  calls = []
  monkeypatch.setattr(backbones, 'get_backbone', lambda cfg: fake_backbone(GAINS, calls))
  run = str(tmp_path / 'run')
  state = round_driver.run_rounds(config, scene, run, show_progress=False)
  assert calls == [0, 1, 2, 3]
  assert not rundir.is_done(rundir.round_dir(run, 4))
  again = round_driver.run_rounds(config, scene, run, show_progress=False)
  assert calls == [0, 1, 2, 3]  # Read back, decisions included: nothing retrained.
  assert [m.get('auto') for m in again.metrics] == [m.get('auto') for m in state.metrics]
  assert again.metrics[3]['auto']['take'] is False
  rounds = run_contents.list_rounds(config, run)
  assert [r.index for r in rounds] == [0, 1, 2, 3]
  assert rounds[0].decision is None
  assert rounds[3].decision.startswith('round 3 discarded, the run keeps round 2: ')
  # The viewer's menus mark the discarded round and open on the kept one.
  assert [r.label for r in rounds] == ['B (round 0)', 'R1', 'R2', 'R3 (discarded)']
  assert run_contents.shown_round(rounds) == 2
  assert run_contents.shown_round(rounds[:3]) == 2
  assert run_contents.shown_round([dataclasses.replace(rounds[1], kept=False)]) == 0


def test_train_and_eval_py_with_auto_rounds_end_to_end(tmp_path, capsys):
  """A real (tiny) NeRF through train.py: a threshold no gain can pass discards R1, so the
  run trains B and R1, keeps B, says so per round, writes the decision into rounds.json;
  a second train.py resumes and trains nothing; eval.py stops where the run stopped;
  experiments/auto_rounds_signal.py renders the same per-view validation PSNRs again."""
  import eval as eval_py  # pylint: disable=g-import-not-at-top
  import train  # pylint: disable=g-import-not-at-top
  from test_uncertainty_quality import TINY  # pylint: disable=g-import-not-at-top
  from experiments.uncertainty_quality import PROCEDURAL  # pylint: disable=g-import-not-at-top
  run = tmp_path / 'table' / 'procedural' / 'Re-Nerfing' / 'seed0'  # renerf_scenes' layout
  argv = ['--gin_configs=experiments/configs/table_tiny.gin', f'--run_dir={run}'] + [
      f'--gin_bindings={b}' for b in PROCEDURAL + TINY + [
          'Config.val_views = 2', "Config.num_rounds = 'auto'", 'Config.auto_min_gain_se = 1e9',
          'Config.auto_max_rounds = 3']]
  train.main(argv)
  out = capsys.readouterr()
  lines = [l for l in out.out.splitlines() if l.startswith(('round 1 ', 'the run keeps'))]
  assert lines[0].startswith('round 1 discarded, the run keeps B: validation gain ')
  assert lines[1] == 'the run keeps B (round 0; auto_rounds.selected_round)'
  assert lines[0] in out.err  # Printed as it was decided, too.
  rounds = json.loads((run / 'rounds.json').read_text())
  assert [m['round'] for m in rounds] == [0, 1] and rounds[1]['auto']['take'] is False
  assert len(rounds[0]['val_psnr_views']) == 2 and 'auto' not in rounds[0]
  assert not (run / 'round_2').exists()
  assert lines[0] in (run / 'rounds.md').read_text()
  before = (run / 'round_1' / 'result.json').stat().st_mtime_ns
  train.main(argv)  # Resumed: both rounds read back, nothing trained again.
  assert lines[0] in capsys.readouterr().out
  assert (run / 'round_1' / 'result.json').stat().st_mtime_ns == before
  eval_py.main(argv)
  evaluated = json.loads((run / 'eval_rounds.json').read_text())['rounds']
  assert [m['round'] for m in evaluated] == [0, 1]
  assert 'is not finished' not in capsys.readouterr().err
  from experiments import auto_rounds_signal  # pylint: disable=g-import-not-at-top
  auto_rounds_signal.main(['--runs', str(tmp_path / 'table'), '--name', 'sig', '--out',
                           str(tmp_path / 'sig')])
  sig = json.loads((tmp_path / 'sig' / 'sig.json').read_text())
  (row,) = sig['rows']
  np.testing.assert_allclose(row['val_b'], rounds[0]['val_psnr_views'], atol=1e-3)
  np.testing.assert_allclose(row['val_r1'], rounds[1]['val_psnr_views'], atol=1e-3)
  assert row['val_gain'] == pytest.approx(rounds[1]['auto']['gain'], abs=1e-3)
  assert (row['backbone'], row['scene'], row['seed']) == ('table', 'procedural', 0)
  assert row['test_r1'] - row['test_b'] == pytest.approx(rounds[1]['psnr'] - rounds[0]['psnr'])
  assert (tmp_path / 'sig' / 'sig.png').stat().st_size > 0


def test_signal_summary_by_hand():
  """experiments/auto_rounds_signal.summarize: the rule's outcome against always-B,
  always-R1 and the oracle on rows whose choices are known."""
  from experiments import auto_rounds_signal as sig  # pylint: disable=g-import-not-at-top
  row = lambda sc, seed, b, r1, gain, take: dict(
      backbone='grid', scene=sc, seed=seed, test_b=b, test_r1=r1, val_gain=gain, se=0.1,
      views=4, **{f'take_{k:g}': take for k in sig.THRESHOLDS})
  rows = [row('a', 0, 20., 21., 0.8, True), row('a', 1, 20., 19., -0.5, False),
          row('b', 0, 10., 9.5, 0.3, True), row('b', 1, 12., 12.5, -0.1, False)]
  scenes, overall = sig.summarize(rows)
  a, b = scenes
  assert (a['always_B'], a['always_R1'], a['oracle'], a['auto_1']) == (20., 20., 20.5, 20.5)
  assert (b['always_B'], b['always_R1'], b['oracle'], b['auto_1']) == (11., 11., 11.25, 10.75)
  o = overall['all']
  assert o['worst_auto_1_minus_B'] == -0.25 and o['worst_scene_1'] == 'grid b'
  assert o['regret_1'] == pytest.approx((20.5 + 11.25) / 2 - (20.5 + 10.75) / 2)
  assert o['r_pooled'] == pytest.approx(np.corrcoef([0.8, -0.5, 0.3, -0.1],
                                                    [1., -1., -0.5, 0.5])[0, 1])


def test_signal_rule_over_several_rounds_by_hand():
  """auto_rounds_signal with rounds beyond R1: the rule walks round after round and stops
  at the first discarded one; the oracle is the best round per seed; later rounds' signal
  is paired with their test gain over the previous round."""
  from experiments import auto_rounds_signal as sig  # pylint: disable=g-import-not-at-top
  up, flat = [20., 21., 22.], [20., 20.1, 19.9]  # Per-view PSNRs of a model.
  views = [up, [v + 1. for v in up], [v + .9 for v in up], [v + 3. for v in up]]
  sel, decisions = sig.rule(views, 1.)
  assert sel == 1 and [d['take'] for d in decisions] == [True, False]  # R3 never reached.
  assert sig.rule([up, flat], 1.)[0] == 0
  assert sig.rule(views[:2] + [[v + 2. for v in up]], 0.)[0] == 2
  row = dict(backbone='grid', scene='a', seed=0, test_b=20., test_r1=21., val_gain=1.,
             se=0., views=3, tests=[20., 21., 23., 22.],
             later=[{'round': 2, 'gain': -.1, 'se': 0., 'test_gain': 2.},
                    {'round': 3, 'gain': 2.1, 'se': 0., 'test_gain': -1.}],
             **{f'take_{k:g}': True for k in sig.THRESHOLDS},
             **{f'sel_{k:g}': 1 for k in sig.THRESHOLDS})
  other = dict(row, seed=1, tests=[20., 19., 18., 17.], test_r1=19., val_gain=-1.,
               later=[{'round': 2, 'gain': .5, 'se': 0., 'test_gain': -1.}],
               **{f'take_{k:g}': False for k in sig.THRESHOLDS},
               **{f'sel_{k:g}': 0 for k in sig.THRESHOLDS})
  (scene,), overall = sig.summarize([row, other])
  assert scene['always'] == [20., 20., 20.5, 19.5]
  assert scene['oracle'] == (23. + 20.) / 2 and scene['auto_1'] == (21. + 20.) / 2
  assert scene['rounds_1'] == [1, 0]
  o = overall['all']
  assert o['later_pairs'] == 3
  assert o['r_later_rounds'] == pytest.approx(np.corrcoef([-.1, 2.1, .5], [2., -1., -1.])[0, 1])
  md = sig.markdown('m', [row, other], [scene], overall, 'cmd')
  assert '| grid | a | 0 | R3 | +2.10 +- 0.00 | -1.00 | 1 / 1 / 1 |' in md
  assert 'R2 20.50, R3 19.50; rounds kept [1, 0]' in md


def _fake_run(run, config, metrics):
  """A finished run directory as the tables leave it: config.json, and per round its
  result.json metrics and DONE marker."""
  run.mkdir(parents=True)
  (run / 'config.json').write_text(json.dumps(config))
  for r, m in enumerate(metrics):
    rdir = run / f'round_{r}'
    rdir.mkdir()
    (rdir / 'result.json').write_text(json.dumps({'metrics': dict(m, round=r)}))
    rundir.mark_done(str(rdir))


def test_leave_one_out_signal_from_probe_tables(tmp_path):
  """auto_rounds_signal --loo: each probe (a table made with Config.leave_out_view = j)
  gives R1 - B at its left-out view; the signal is their mean +- the standard error over
  the folds, paired with the full run of the same backbone, scene and seed; a folder of
  runs that are not probes is refused."""
  from experiments import auto_rounds_signal as sig  # pylint: disable=g-import-not-at-top
  for j, (b, r1) in enumerate([(20., 20.6), (18., 18.2), (21., 21.4)]):
    _fake_run(tmp_path / f'loo{j}' / 'fern' / 'Re-Nerfing' / 'seed0',
              {'backbone': 'nerf', 'leave_out_view': j},
              [{'val_psnr': b, 'cumulative_seconds': 10.},
               {'val_psnr': r1, 'cumulative_seconds': 30.}])
  _fake_run(tmp_path / 'loo9' / 'fern' / 'Re-Nerfing' / 'seed1',
            {'backbone': 'gaussians', 'leave_out_view': 0},
            [{'val_psnr': 1., 'cumulative_seconds': 1.}, {'val_psnr': 2., 'cumulative_seconds': 2.}])
  folds = sig.loo_folds([str(tmp_path / f'loo{j}') for j in (0, 1, 2, 9)])
  assert set(folds) == {('nerf', 'fern', 0), ('gaussians', 'fern', 1)}
  fern = folds[('nerf', 'fern', 0)]
  assert sorted(f['view'] for f in fern) == [0, 1, 2]
  assert sorted(f['gain'] for f in fern) == pytest.approx([.2, .4, .6])
  gain, se, take = sig.loo_signal(fern, 1.)
  assert gain == pytest.approx(.4) and se == pytest.approx(.2 / math.sqrt(3))
  assert take and not sig.loo_signal(fern, 4.)[2]  # 0.4 < 4 standard errors (0.46).
  assert not sig.loo_signal([dict(f, gain=-f['gain']) for f in fern], 0.)[2]
  _fake_run(tmp_path / 'full' / 'fern' / 'Re-Nerfing' / 'seed0', {'backbone': 'nerf'},
            [{'val_psnr': 1., 'cumulative_seconds': 1.}] * 2)
  with pytest.raises(SystemExit, match='not a leave-one-out probe'):
    sig.loo_folds([str(tmp_path / 'full')])
  row = dict(backbone='nerf', scene='fern', seed=0, test_b=20., test_r1=19.5, val_gain=.1,
             se=.1, views=4, loo_gain=gain, loo_se=se, loo_take=take, loo_folds=3,
             loo_views=[0, 1, 2], loo_seconds=90., round_seconds=60.,
             **{f'take_{k:g}': False for k in sig.THRESHOLDS})
  (scene,), overall = sig.summarize([row])
  assert (scene['auto_loo'], scene['loo_always_B'], scene['loo_cost']) == (19.5, 20., 1.5)
  assert overall['all']['worst_auto_loo_minus_B'] == -.5
  md = sig.markdown('m', [row], [scene], overall, 'cmd')
  assert '| nerf | fern | 0 | 3 | +0.40 +- 0.12 | -0.50 | yes | 1.50 |' in md


def test_a_b_without_per_view_psnrs_is_rendered_for_the_decision(tmp_path, monkeypatch):
  """Resuming as 'auto' a run whose B was trained before (its result.json has no
  val_psnr_views, as every run before 'auto' existed): round 1 renders B at the
  validation views and decides on that."""
  config, scene = _scene_and_config()
  calls = []
  monkeypatch.setattr(backbones, 'get_backbone', lambda cfg: fake_backbone(GAINS, calls))
  run = str(tmp_path / 'run')
  import dataclasses  # pylint: disable=g-import-not-at-top
  round_driver.run_rounds(dataclasses.replace(config, num_rounds=0), scene, run, False)
  path = tmp_path / 'run' / 'round_0' / 'result.json'
  result = json.loads(path.read_text())
  del result['metrics']['val_psnr_views']
  path.write_text(json.dumps(result))
  state = round_driver.run_rounds(dataclasses.replace(config, auto_max_rounds=1), scene,
                                  run, False)
  assert calls == [0, 1]
  d = state.metrics[1]['auto']
  assert d['take'] and d['gain'] == pytest.approx(np.mean(np.subtract(GAINS[1], GAINS[0])))


def test_the_table_scripts_refuse_auto(tmp_path):
  from experiments import tables  # pylint: disable=g-import-not-at-top
  config, scene = _scene_and_config()
  with pytest.raises(ConfigError, match="num_rounds='auto' is train.py's"):
    tables.run_seed(config, scene, str(tmp_path / 'run'))
  assert not (tmp_path / 'run').exists()
