"""The paper-table machinery (experiments/tables.py) end to end on the embedded scene."""
import json
import subprocess
import sys

import imageio.v3 as iio
import numpy as np
import pytest

from conftest import REPO, tree_files
from experiments import renerf_scenes
from renerf_jax.configs import load_config
from renerf_jax.datasets import load_scene
from renerf_jax.round_driver import hardest_test_view

TINY = ['Config.procedural_size = (32, 40)', 'Config.max_steps = 12',
        'Config.batch_size = 64', 'Config.num_samples = 8', 'Config.net_depth = 2',
        'Config.net_width = 32', 'Config.skip_layer = 1', 'Config.net_width_viewdirs = 16',
        'Config.max_deg_point = 4', 'Config.deg_view = 2', 'Config.n_random_poses = 50',
        'Config.batch_size_random = 64', 'Config.patch_size = 4', 'Config.pseudo_until_frac = 0.5',
        'Config.anneal_nearfar_steps = 4', 'Config.lr_delay_steps = 4', 'Config.depth_tv_maxstep = 4',
        'Config.eval_every = 6', 'Config.eval_stride = 4', 'Config.checkpoint_every = 6',
        'Config.render_chunk = 512', "Config.lpips_nets = ('alex',)",
        "Config.interp_factors = '2x'"]


def assert_table_cells(md):
  """Every row of every markdown table has as many cells as its header."""
  width = None
  for line in md.splitlines():
    if not line.startswith('|'):
      width = None
      continue
    cells = line.count('|') - 1
    if width is None:
      width = cells
    assert cells == width, f'{cells} cells, header {width}: {line}'


def _run(module, out, *extra):
  cmd = ([sys.executable, '-m', f'experiments.{module}', '--config', 'gin_configs/demo_llff.gin',
          '--out', str(out), '--seeds', '0', '1'] + [f'--gin_bindings={b}' for b in TINY]
         + list(extra))
  res = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=600,
                       check=False)
  assert res.returncode == 0, res.stderr[-3000:]
  return res.stdout


def test_rounds_table_shares_baselines_and_trains_the_equal_time_control(tmp_path):
  out = tmp_path / 'results'
  _run('renerf_rounds', out, '--name', 't1', '--rounds', '1')
  t1 = json.loads((out / 't1.json').read_text())
  # The command recorded is the one that ran: the script as a module (python -m).
  assert t1['command'].startswith(
      'python -m experiments.renerf_rounds --config gin_configs/demo_llff.gin ')
  rows = t1['rows']
  assert [r['round'] for r in rows[:2]] == ['baseline', 'R1']
  eq = json.loads((out / 't1' / 'equal_time.json').read_text())
  # Two rounds of 12 steps plus pseudo-view synthesis: more than 24 steps' worth of time
  # for each seed (by how much depends on the machine's load; the rounded median may be 24).
  assert all(s > 24 for s in eq['per_seed_steps']) and len(eq['per_seed_steps']) == 2
  assert eq['max_steps'] == round(float(np.median(eq['per_seed_steps'])))
  assert rows[2]['round'] == f"{eq['max_steps']} steps"
  assert rows[0]['seeds'] == 2 and rows[0]['psnr_std'] > 0  # two different seeds
  assert (out / 't1.md').read_text().count('19.08') == 1  # the paper's baseline beside ours
  assert (out / 't1_time.png').stat().st_size > 0
  png = iio.imread(out / 't1_metrics_time.png')  # PSNR | SSIM | LPIPS-alex panels
  assert png.shape[1] > 2 * png.shape[0]

  # A masks-style ablation reusing t1's baselines: no baseline is trained again, and every
  # variant's round_0 is a bit-for-bit copy.
  stdout = _run('table_masks', out, '--name', 't4',
                '--baseline_from', str(out / 't1' / 'Re-Nerfing' / 'seed{seed}'),
                '--gin_bindings=Config.deform_log2_res = 2',
                '--gin_bindings=Config.hessian_rays = 256')
  t4 = json.loads((out / 't4.json').read_text())
  base = {s: (out / 't1' / 'Re-Nerfing' / f'seed{s}' / 'round_0' / 'params.msgpack')
          .read_bytes() for s in (0, 1)}
  for v in t4['variants']:
    assert all(c for c in v['baseline_copied_from'])
    for s, d in zip((0, 1), v['run_dirs']):
      assert (REPO / d / 'round_0' / 'params.msgpack').read_bytes() == base[s]
  assert [r['variant'] for r in t4['rows']] == [
      'augmented views', 'augmented views', 'stop aug. views', '+ masks']
  assert t4['rows'][0]['psnr'] == rows[0]['psnr']  # the same baselines
  masks_log = (out / 't4' / '+ masks' / 'seed0' / 'round_1' / 'pseudo_views' / 'timing.json')
  assert json.loads(masks_log.read_text())['hessian_seconds'] > 0.
  # 'stop aug. views' reuses the pseudo-views of 'augmented views' (same baseline, same
  # pseudo-view settings); '+ masks' renders its own.
  pv = lambda v, s: out / 't4' / v / f'seed{s}' / 'round_1' / 'pseudo_views'
  for s in (0, 1):
    assert (pv('stop aug. views', s) / 'views.npz').read_bytes() == (
        pv('augmented views', s) / 'views.npz').read_bytes()
    assert (pv('stop aug. views', s) / 'copied_from.json').is_file()
    assert not (pv('+ masks', s) / 'copied_from.json').exists()
  assert '| + masks | R1 |' in stdout
  # The camera-path video of the baseline against the last round.
  gif = out / 'video.gif'
  cmd = [sys.executable, '-m', 'experiments.render_video', '--run_dir',
         str(out / 't1' / 'Re-Nerfing' / 'seed0'), '--config', 'gin_configs/demo_llff.gin',
         '--frames', '4', '--out', str(gif)] + [f'--gin_bindings={b}' for b in TINY]
  res = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=300,
                       check=False)
  assert res.returncode == 0, res.stderr[-3000:]
  frames = iio.imread(gif, index=None)
  assert frames.shape == (4, 16, 2 * 20 + 4, 3)  # 32x40 at 1/2, two rounds side by side
  assert 'rounds 0 | 1' in res.stdout and (out / 'video_frame.png').is_file()
  # Uncertainty masks of the baseline's pseudo-views: panel PNG and Hessian share.
  run0 = out / 't1' / 'Re-Nerfing' / 'seed0'
  before = sorted(str(f) for f in run0.rglob('*'))
  cmd = [sys.executable, '-m', 'experiments.uncertainty_panel', '--run_dir', str(run0),
         '--config', 'gin_configs/demo_llff.gin', '--work_dir', str(tmp_path / 'masks'),
         '--views', '0', '1', '--out', str(out / 'unc')] + [
             f'--gin_bindings={b}' for b in TINY + ['Config.deform_log2_res = 2',
                                                   'Config.hessian_rays = 128']]
  res = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=300,
                       check=False)
  assert res.returncode == 0, res.stderr[-3000:]
  unc = json.loads((out / 'unc.json').read_text())
  assert unc['hessian_seconds'] > 0. and 0. < unc['hessian_share_of_round'] < 1.
  assert 0. <= unc['kept_fraction'] <= 1.
  panel = iio.imread(out / 'unc.png')
  assert panel.shape[:2] == (2 * 32 + 4, 3 * 40 + 8)  # 2 views; view | heat | masked
  assert sorted(str(f) for f in run0.rglob('*')) == before  # the run is not written to
  # Error against time of finished baselines (two 'backbones': the same runs here).
  runs = str(out / 't1' / 'Re-Nerfing' / 'seed*')
  cmd = [sys.executable, '-m', 'experiments.plot_backbones', '--name', 'bb', '--out', str(out),
         '--run', f'A={runs}', '--run', f'B={runs}', '--sec_per_step', 'A=0.5']
  res = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=120,
                       check=False)
  assert res.returncode == 0, res.stderr[-3000:]
  bb = json.loads((out / 'bb.json').read_text())
  a, b = bb['methods']
  assert a['curves']['seed0'][-1][0] == 0.5 * 12  # step x the given seconds per step
  assert b['curves']['seed0'] != a['curves']['seed0']  # B keeps the logged seconds
  bb_md = (out / 'bb.md').read_text()
  assert '| A | 2 | 12 | 6 |' in bb_md
  assert 'A: step x 0.5 s' in bb_md and 'B: seconds as logged' in bb_md
  assert (out / 'bb.png').stat().st_size > 0
  bad = subprocess.run(cmd[:-2] + ['--sec_per_step', 'C=1'], cwd=REPO, capture_output=True,
                       text=True, timeout=120, check=False)
  assert bad.returncode != 0 and 'unknown label' in bad.stderr


def test_variant_labels_may_hold_an_equals_sign():
  from experiments import tables  # pylint: disable=g-import-not-at-top
  spec = "bg (acc <= 0.5)=Config.use_masks = True; Config.mask_threshold = 0.5"
  assert tables.variant_spec(spec) == ('bg (acc <= 0.5)', ['Config.use_masks = True',
                                                           ' Config.mask_threshold = 0.5'])
  assert tables.variant_spec('K 0=Config.pseudo_until_frac = 0.') == (
      'K 0', ['Config.pseudo_until_frac = 0.'])
  assert tables.variant_spec('plain=') == ('plain', [])
  assert tables.variant_spec('Re-Nerfing') == ('Re-Nerfing', [])  # as before: no bindings
  with pytest.raises(SystemExit, match='is not .LABEL=binding'):
    tables.variant_spec('=Config.seed = 1')


def test_metric_curves_follow_each_variant_over_its_rounds():
  from experiments import tables  # pylint: disable=g-import-not-at-top
  rows = lambda label, pts: [dict(variant=label, cumulative_seconds=t, psnr=p, psnr_std=.3,
                                  ssim=p / 40, lpips_alex=1 - p / 40) for t, p in pts]
  curves = tables.metric_curves({'Re-Nerfing': rows('Re-Nerfing', [(90, 19.), (220, 19.5)]),
                                 'baseline, 900 steps': rows('eq', [(230, 20.)])})
  assert list(curves) == ['PSNR', 'SSIM', 'LPIPS-alex']  # no LPIPS-vgg in these rows
  assert curves['PSNR'] == {'Re-Nerfing': [(90, 19., .3), (220, 19.5, .3)],
                            'baseline, 900 steps': [(230, 20., .3)]}
  assert curves['LPIPS-alex']['Re-Nerfing'][1] == (220, 1 - 19.5 / 40, 0.)


def test_equal_time_counts_each_round_at_its_own_pace(tmp_path):
  """A round run on a busier machine (every part slower alike) is worth the same steps:
  training seconds = round seconds - the synthesis seconds of its timing.json."""
  from experiments import tables  # pylint: disable=g-import-not-at-top
  from renerf_jax import report  # pylint: disable=g-import-not-at-top
  assert tables.round_step_equivalents(100, 120., 100.) == pytest.approx(120.)
  assert tables.round_step_equivalents(100, 360., 300.) == pytest.approx(120.)
  with pytest.raises(ValueError, match='train_seconds'):
    tables.round_step_equivalents(100, 10., 0.)

  class Cfg:  # equal_time_steps reads max_steps only
    max_steps = 100

  def fake_run(name, paces):  # per round: (round seconds, train seconds)
    run_dir = tmp_path / name
    for r, (total, train) in enumerate(paces[1:], start=1):
      d = run_dir / f'round_{r}' / 'pseudo_views'
      d.mkdir(parents=True)
      report.write_json(str(d / 'timing.json'), {'seconds': total - train})
    return [{'round': r, 'round_seconds': t} for r, (t, _) in enumerate(paces)], str(run_dir)

  # B idle (100 s), R1 three times slower (busy machine) with 20% synthesis on top.
  a, da = fake_run('a', [(100., 100.), (360., 300.)])
  b, db = fake_run('b', [(50., 50.), (130., 100.)])  # 130 steps' worth in round 1
  c, dc = fake_run('c', [(80., 80.), (110., 100.)])
  root = tmp_path / 'table'
  root.mkdir()
  assert tables.equal_time_steps(str(root), Cfg, [a, b, c], [da, db, dc]) == 220  # median
  saved = report.read_json(str(root / 'equal_time.json'))
  assert saved['per_seed_steps'] == pytest.approx([220., 230., 210.])
  # Computed once: a later call reuses it whatever the runs say.
  assert tables.equal_time_steps(str(root), Cfg, [b], [db]) == 220
  # One made with another rule is refused in one line, not silently reused.
  report.write_json(str(root / 'equal_time.json'), dict(saved, rule='old'))
  with pytest.raises(SystemExit, match='another rule'):
    tables.equal_time_steps(str(root), Cfg, [b], [db])
  # A round without its synthesis timing is named.
  (tmp_path / 'b' / 'round_1' / 'pseudo_views' / 'timing.json').unlink()
  with pytest.raises(SystemExit, match='timing.json not found'):
    tables.equal_time_steps(str(tmp_path / 'other'), Cfg, [b], [db])


def test_scenes_table_pairs_d_with_b_by_seed_against_2x_and_equal_time(tmp_path):
  """experiments/renerf_scenes.py: R1..R3, a masks row trained from the same B, B 2x
  longer and B at the rounds' total time, with paired deltas and win counts."""
  out = tmp_path / 'results'
  cmd = ([sys.executable, '-m', 'experiments.renerf_scenes', '--name', 's', '--config',
          'gin_configs/demo_llff.gin', '--out', str(out), '--seeds', '0', '1', '--scenes',
          'procedural', '--rounds_scenes', 'procedural', '--variant',
          'R1 + masks=Config.use_masks=True;Config.deform_log2_res=2;'
          'Config.hessian_rays=256', "--gin_bindings=Config.dataset_loader='procedural'"]
         + [f'--gin_bindings={b}' for b in TINY])
  res = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=900,
                       check=False)
  assert res.returncode == 0, res.stderr[-3000:]
  result = json.loads((out / 's.json').read_text())
  assert result['command'].startswith('python -m experiments.renerf_scenes --name s --config ')
  rows = result['rows']['procedural']
  eq = json.loads((out / 's' / 'procedural' / 'equal_time.json').read_text())
  assert set(rows) == {'B', 'R1', 'R2', 'R3', 'R1 + masks', 'B 2x steps',
                       'B equal time', renerf_scenes.CONTROL, renerf_scenes.CONTROL_2X}
  # The seed-matched controls are B's training at D's seed (Config.d_seed 'offset':
  # seed + 1000) at B's and at 2x B's steps, with no rounds.
  for label, steps in ((renerf_scenes.CONTROL, 12), (renerf_scenes.CONTROL_2X, 24)):
    for s in (0, 1):
      saved = json.loads((out / 's' / 'procedural' / label / f'seed{s}' /
                          'config.json').read_text())
      assert (saved['seed'], saved['max_steps'], saved['num_rounds']) == (s + 1000, steps, 0)
  ctrl = result['summary']['scenes']['procedural']['R1']['paired_ctrl']['psnr']
  assert ctrl['mean'] == pytest.approx(np.mean(
      [rows['R1'][str(s)]['psnr'] - rows[renerf_scenes.CONTROL][str(s)]['psnr']
       for s in (0, 1)]))
  assert set(ctrl) >= {'p', 'ci', 'shown'}
  assert {m['steps'] for m in rows['B equal time'].values()} == {eq['max_steps']}
  # The masks row is R1 trained from the same B: its round_0 is the Re-Nerfing run's.
  root = out / 's' / 'procedural'
  for s in (0, 1):
    assert ((root / 'R1 + masks' / f'seed{s}' / 'round_0' / 'params.msgpack').read_bytes()
            == (root / 'Re-Nerfing' / f'seed{s}' / 'round_0' / 'params.msgpack').read_bytes())
  # Paired deltas are D minus B of the same seed; wins count the pairs D beats B in.
  paired = result['summary']['scenes']['procedural']['R1']['paired']
  deltas = [rows['R1'][str(s)]['psnr'] - rows['B'][str(s)]['psnr'] for s in (0, 1)]
  assert paired['psnr']['mean'] == pytest.approx(np.mean(deltas))
  assert paired['psnr']['wins'] == sum(d > 0 for d in deltas) and paired['psnr']['n'] == 2
  assert result['summary']['mean']['B 2x steps']['pooled']['psnr']['n'] == 2
  # Rows other than B and R1 are also paired with R1 (masks on vs off, 2x vs R1).
  vs_r1 = result['summary']['scenes']['procedural']['R1 + masks']['paired_R1']
  assert vs_r1['psnr']['mean'] == pytest.approx(np.mean(
      [rows['R1 + masks'][str(s)]['psnr'] - rows['R1'][str(s)]['psnr'] for s in (0, 1)]))
  assert 'paired_R1' not in result['summary']['scenes']['procedural']['R1']
  md = (out / 's.md').read_text()
  assert 'B 2x steps' in md and 'wins' in md and (out / 's.png').stat().st_size > 0
  assert "dPSNR vs D's seed K 0" in md and 'paired t-test' in md
  assert_table_cells(md)
  assert f"| B equal time ({eq['max_steps']} steps) |" in md
  # --table: a subset of the same runs (reused, nothing trained) into other files.
  before = tree_files(out / 's')
  sub = subprocess.run(cmd + ['--table', 't', '--seeds', '0'], cwd=REPO, capture_output=True,
                       text=True, timeout=600, check=False)
  assert sub.returncode == 0, sub.stderr[-3000:]
  assert tree_files(out / 's') == before and (out / 's.md').read_text() == md
  sub_rows = json.loads((out / 't.json').read_text())['rows']['procedural']
  assert sub_rows['R1'] == {'0': rows['R1']['0']}
  # --scenes_2x given with no scene: the finished B 2x runs are not tabulated.
  sub = subprocess.run(cmd + ['--table', 'u', '--seeds', '0', '--scenes_2x'], cwd=REPO,
                       capture_output=True, text=True, timeout=600, check=False)
  assert sub.returncode == 0, sub.stderr[-3000:]
  assert 'B 2x steps' not in json.loads((out / 'u.json').read_text())['rows']['procedural']
  assert tree_files(out / 's') == before
  bad = subprocess.run(cmd + ['--scenes_2x', 'fern'], cwd=REPO, capture_output=True,
                       text=True, timeout=600, check=False)
  assert bad.returncode == 2
  assert 'error: --scenes_2x names fern, not in --scenes (procedural)' in bad.stderr
  # --no_r1 (the oracle table): B, the --variant rows and the control at D's seed (the
  # variants are D's), R1 left out even where it exists.
  i = cmd.index('--rounds_scenes')
  no_r1 = cmd[:i] + cmd[i + 2:] + ['--table', 'n', '--seeds', '0', '--no_r1', '--no_2x']
  sub = subprocess.run(no_r1, cwd=REPO, capture_output=True, text=True, timeout=600,
                       check=False)
  assert sub.returncode == 0, sub.stderr[-3000:]
  n_rows = json.loads((out / 'n.json').read_text())['rows']['procedural']
  assert set(n_rows) == {'B', 'R1 + masks', renerf_scenes.CONTROL}
  assert n_rows['B'] == {'0': rows['B']['0']}
  assert tree_files(out / 's') == before
  # --no_b2x: the more-compute control at D's seed without B 2x at B's seed.
  sub = subprocess.run(cmd + ['--table', 'b', '--seeds', '0', '--no_b2x'], cwd=REPO,
                       capture_output=True, text=True, timeout=600, check=False)
  assert sub.returncode == 0, sub.stderr[-3000:]
  b_rows = json.loads((out / 'b.json').read_text())['rows']['procedural']
  assert 'B 2x steps' not in b_rows
  assert b_rows[renerf_scenes.CONTROL_2X] == {'0': rows[renerf_scenes.CONTROL_2X]['0']}
  assert tree_files(out / 's') == before
  bad = subprocess.run(cmd + ['--no_r1'], cwd=REPO, capture_output=True, text=True,
                       timeout=600, check=False)
  assert bad.returncode == 2 and 'error: --no_r1 leaves no rounds' in bad.stderr
  # --merge: tables made apart (here seed 0 and seed 1) give the full table's rows and
  # summary, training nothing; tables of other settings or conflicting results fail.
  sub = subprocess.run(cmd + ['--table', 'v', '--seeds', '1'], cwd=REPO, capture_output=True,
                       text=True, timeout=600, check=False)
  assert sub.returncode == 0, sub.stderr[-3000:]
  merge = [sys.executable, '-m', 'experiments.renerf_scenes', '--name', 'w', '--out', str(out),
           '--merge', str(out / 't.json'), str(out / 'v.json')]
  sub = subprocess.run(merge, cwd=REPO, capture_output=True, text=True, timeout=600,
                       check=False)
  assert sub.returncode == 0, sub.stderr[-3000:]
  merged = json.loads((out / 'w.json').read_text())
  assert merged['rows'] == result['rows'] and merged['summary'] == result['summary']
  assert merged['seeds'] == [0, 1] and len(merged['sources']) == 2
  assert 'Merged from the tables of:' in (out / 'w.md').read_text()
  assert tree_files(out / 's') == before
  other = json.loads((out / 'v.json').read_text())
  other['command'] += ' --gin_bindings=Config.lr_init=1.0'
  (out / 'other.json').write_text(json.dumps(other))
  clash = json.loads((out / 'v.json').read_text())
  clash['rows']['procedural']['R1']['1']['psnr'] += 1.
  (out / 'clash.json').write_text(json.dumps(clash))
  for extra, message in ((['other.json'], 'other.json was made with --config/--gin_bindings'),
                         (['clash.json'], 'another result for procedural / R1 / seed 1'),
                         (['missing.json'], 'missing.json is not a renerf_scenes table')):
    bad = subprocess.run(merge + [str(out / e) for e in extra], cwd=REPO,
                         capture_output=True, text=True, timeout=300, check=False)
    assert bad.returncode != 0 and message in bad.stderr, bad.stderr[-2000:]
    assert 'Traceback' not in bad.stderr
  # experiments/test_renders.py: the photo | B | R1 | B 2x of the runs, from their PNGs.
  renders = [sys.executable, '-m', 'experiments.test_renders', '--runs', str(out / 's'),
             '--config', 'gin_configs/demo_llff.gin', '--scenes', 'procedural',
             "--gin_bindings=Config.dataset_loader='procedural'"] + [
                 f'--gin_bindings={b}' for b in TINY]
  sub = subprocess.run(renders + ['--seed', '1', '--out', str(out / 'renders.png')],
                       cwd=REPO, capture_output=True, text=True, timeout=300, check=False)
  assert sub.returncode == 0, sub.stderr[-3000:]
  assert (out / 'renders.png').stat().st_size > 0 and tree_files(out / 's') == before
  sub = subprocess.run(renders + ['--seed', '1', '--b2x', 'd_seed', '--out',
                                  str(out / 'renders_d.png')],
                       cwd=REPO, capture_output=True, text=True, timeout=300, check=False)
  assert sub.returncode == 0, sub.stderr[-3000:]
  assert (out / 'renders_d.png').read_bytes() != (out / 'renders.png').read_bytes()
  # photo | B | R1 | control of the test view farthest from the training cameras.
  sub = subprocess.run(renders + ['--seed', '1', '--b2x', 'control', '--test_view', 'farthest',
                                  '--out', str(out / 'renders_c.png')],
                       cwd=REPO, capture_output=True, text=True, timeout=300, check=False)
  assert sub.returncode == 0, sub.stderr[-3000:]
  scene = load_scene(load_config(['gin_configs/demo_llff.gin'],
                                 ["Config.dataset_loader='procedural'"] + TINY))
  k = hardest_test_view(scene)
  assert f'procedural: test view {k} of the split' in sub.stdout
  assert (out / 'renders_c.png').read_bytes() != (out / 'renders_d.png').read_bytes()
  bad = subprocess.run(renders + ['--test_view', '99', '--out', str(out / 'none.png')],
                       cwd=REPO, capture_output=True, text=True, timeout=300, check=False)
  assert bad.returncode == 1 and "error: --test_view 99: procedural has" in bad.stderr
  bad = subprocess.run(renders + ['--seed', '7', '--out', str(out / 'none.png')], cwd=REPO,
                       capture_output=True, text=True, timeout=300, check=False)
  assert bad.returncode == 1 and 'seed7/round_0/eval/test_' in bad.stderr
  assert 'Traceback' not in bad.stderr and not (out / 'none.png').exists()


def test_equal_time_comparison_takes_given_idle_rates_and_per_method_seeds(tmp_path):
  """experiments/compare_equal_time.py with --sec_per_step (no calibration: steps = budget /
  the given rate, curve time = step x rate) and --seeds_of; bad values fail in one line."""
  out = tmp_path / 'results'
  cmd = lambda *opts: ([sys.executable, '-m', 'experiments.compare_equal_time', '--name', 'eq',
                        '--base', 'gin_configs/demo_llff.gin', '--out', str(out), '--budget_s', '6',
                        '--seeds', '0', '1', '--method', 'A=', '--method',
                        'B=gin_configs/modifiers/no_depth_tv.gin', '--calib_steps', '2']
                       + [f'--gin_bindings={b}' for b in TINY] + list(opts))
  good = ['--sec_per_step', 'A=0.5', '--seeds_of', 'B=1']
  res = subprocess.run(cmd(*good), cwd=REPO, capture_output=True, text=True, timeout=600,
                       check=False)
  assert res.returncode == 0, res.stderr[-3000:]
  eq = json.loads((out / 'eq.json').read_text())
  a, b = eq['methods']
  assert a['sec_per_step'] == 0.5 and a['sec_per_step_given'] and a['max_steps'] == 12
  assert a['seeds'] == [0, 1] and [r['seed'] for r in a['runs']] == [0, 1]
  assert b['seeds'] == [1] and [r['seed'] for r in b['runs']] == [1]
  assert not b['sec_per_step_given'] and b['max_steps'] == max(int(6 / b['sec_per_step']), 1)
  calib = json.loads((out / 'eq' / 'A' / 'calibration.json').read_text())
  assert calib == {'sec_per_step': 0.5, 'source': '--sec_per_step'}
  md = (out / 'eq.md').read_text()
  assert '| A | 0, 1 | 12 | 0.500 (given) |' in md and '| B | 1 |' in md
  assert '"s / step (given)"' in md and (out / 'eq_curves.png').stat().st_size > 0
  # A rerun without the flags reuses the runs and keeps A's rate marked as given.
  before = tree_files(out / 'eq')
  res = subprocess.run(cmd('--seeds_of', 'B=1'), cwd=REPO, capture_output=True, text=True,
                       timeout=600, check=False)
  assert res.returncode == 0, res.stderr[-3000:]
  assert json.loads((out / 'eq.json').read_text())['methods'][0]['sec_per_step_given']
  assert tree_files(out / 'eq') == before
  # Bad values fail in one line, before anything trains.
  for opts, message in ((['--sec_per_step', 'A=0.25'], 'holds 0.5 s/step'),
                        (['--sec_per_step', 'C=1'], "no --method is labelled 'C'"),
                        (['--sec_per_step', 'B=-1'], 'not a positive number'),
                        (['--sec_per_step', 'A=1', '--sec_per_step', 'A=2'], 'given twice'),
                        (['--seeds_of', 'B=x'], 'not a comma-separated list'),
                        (['--seeds_of', 'B=1,1'], 'not a comma-separated list')):
    bad = subprocess.run(cmd(*opts), cwd=REPO, capture_output=True, text=True, timeout=300,
                         check=False)
    assert bad.returncode != 0 and message in bad.stderr, bad.stderr[-2000:]
    assert 'Traceback' not in bad.stderr


def test_scenes_table_of_gaussians_names_the_papers_3dgs_delta_and_merges_its_backbone(
    tmp_path):
  """renerf_scenes.py on the Gaussians backbone: the paper's 3DGS delta (mip-NeRF 360,
  +0.81 dB) beside ours, and --merge keeps the backbone from the tables' JSON."""
  from experiments import renerf_scenes  # pylint: disable=g-import-not-at-top
  m = lambda p: {'psnr': p, 'ssim': 0.5, 'lpips_alex': 0.3, 'cumulative_seconds': 10.}
  rows = {'fern': {'B': {0: m(14.), 1: m(15.)}, 'R1': {0: m(14.5), 1: m(14.9)}}}
  summary = renerf_scenes.summarize(rows, ['fern'], [0, 1])
  got = summary['scenes']['fern']['R1']['paired']['psnr']
  assert (got['mean'], got['std'], got['wins']) == pytest.approx(
      (0.2, np.std([0.5, -0.1], ddof=1), 1))
  assert summary['mean']['R1']['pooled_2x'] == {}  # no B 2x row: nothing to pair with
  with_2x = dict(rows['fern'], **{'B 2x steps': {0: m(14.2), 1: m(15.4)}})
  s2 = renerf_scenes.summarize({'fern': with_2x}, ['fern'], [0, 1])
  # R1 - B 2x per seed: +0.3 and -0.5; one pair of two beats the longer B.
  got = s2['mean']['R1']['pooled_2x']['psnr']
  assert (got['mean'], got['std'], got['wins']) == pytest.approx(
      (-0.1, np.std([0.3, -0.5], ddof=1), 1))
  assert s2['mean']['B 2x steps']['pooled_2x'] == {}
  assert '| -0.10 +- 0.57 (1/2), p 0.84, Holm 0.84, [' in renerf_scenes.markdown(s2, ['fern'],
                                                                              'cmd')
  gs = renerf_scenes.markdown(summary, ['fern'], 'cmd', backbone='gaussians')
  assert_table_cells(gs)
  assert_table_cells(renerf_scenes.markdown(s2, ['fern'], 'cmd'))
  assert '| paper R1 - 3DGS (mip-NeRF 360, 30 views: no LLFF 3DGS rows) | | +0.81 |' in gs
  assert 'paper R1 - 3DGS' not in renerf_scenes.markdown(summary, ['fern'], 'cmd')
  assert 'are the paper\'s LLFF deltas on its NeRF backbone' in gs  # fern has a paper row
  lego = renerf_scenes.markdown(renerf_scenes.summarize({'lego': rows['fern']}, ['lego'], [0, 1]),
                                ['lego'], 'cmd', backbone='gaussians')
  assert 'Backbone: 3D Gaussian Splatting.' in lego and 'RegNeRF' not in lego
  paths = []
  # Commands as recorded before the scripts ran as modules, and since.
  for seed, script in ((0, 'experiments/renerf_scenes.py'), (1, '-m experiments.renerf_scenes')):
    path = tmp_path / f't{seed}.json'
    path.write_text(json.dumps({
        'command': f'python {script} --name x --config c.gin',
        'backbone': 'gaussians',
        'rows': {'fern': {k: {str(seed): v[seed]} for k, v in rows['fern'].items()}}}))
    paths.append(str(path))
  merged, seeds, _, _, backbone = renerf_scenes.merged_rows(paths)
  assert backbone == 'gaussians' and seeds == [0, 1]
  assert merged['fern']['R1'] == rows['fern']['R1']


def test_scenes_table_holm_adjusts_each_column_and_refresh_rewrites_a_table(tmp_path):
  """Issue 62: each column of a scene's table (the rows compared with one reference) is
  one Holm family; "shown" uses the Holm p; over one scene the pooled table repeats the
  scene's Holm p; over several it is a family of its own. --refresh rebuilds a table's
  statistics and markdown from its rows and keeps its command."""
  from experiments import paired  # pylint: disable=g-import-not-at-top
  m = lambda p: {'psnr': p, 'ssim': 0.5, 'lpips_alex': 0.3, 'cumulative_seconds': 10.}
  b = [20., 21., 19.5, 20.5, 20.2]
  gains = {'R1': [0.3, 0.9, 0.4, 1.2, 0.2],  # p 0.036 alone: shown; not in a family of 3
           renerf_scenes.CONTROL: [0.5, -0.6, 0.2, -0.3, 0.1],
           renerf_scenes.TWO_X: [0.1, 0.3, -0.2, 0.2, 0.4]}
  rows = {'lego': dict({'B': {s: m(v) for s, v in enumerate(b)}},
                       **{lb: {s: m(v + d) for s, (v, d) in enumerate(zip(b, g))}
                          for lb, g in gains.items()})}
  summary = renerf_scenes.summarize(rows, ['lego'], list(range(5)))
  alone = {lb: paired.paired_summary(g) for lb, g in gains.items()}
  assert alone['R1']['shown']
  want = paired.holm_adjust([alone[lb]['p'] for lb in gains])
  res = summary['scenes']['lego']
  for lb, w in zip(gains, want):
    got = res[lb]['paired']['psnr']
    assert got['p'] == pytest.approx(alone[lb]['p']) and got['p_holm'] == pytest.approx(w)
    assert got['family'] == 3
  assert not res['R1']['paired']['psnr']['shown']
  assert summary['mean']['R1']['pooled']['psnr'] == res['R1']['paired']['psnr']
  md = renerf_scenes.markdown(summary, ['lego'], 'cmd')
  assert '| R1 | 20.84 +- 0.90 | ' in md
  assert '| +0.60 +- 0.43 (5/5), p 0.036, Holm 0.11, [+0.28, +0.94] |' in md  # not bold
  assert 'the Holm p < 0.05' in md
  assert_table_cells(md)
  # Two scenes: the pooled column is a family of its own (R1, control, B 2x pooled).
  two = renerf_scenes.summarize({'lego': rows['lego'], 'fox': rows['lego']}, ['lego', 'fox'],
                                list(range(5)))
  assert two['mean']['R1']['pooled']['psnr']['family'] == 3
  assert two['mean']['R1']['pooled']['psnr']['n'] == 10
  # --refresh: an old table's summary and markdown are rewritten, its command kept.
  path = tmp_path / 'old.json'
  path.write_text(json.dumps({'command': 'python -m experiments.renerf_scenes --name old',
                              'rows': {'lego': {lb: {str(s): v for s, v in by.items()}
                                                for lb, by in rows['lego'].items()}},
                              'summary': {'scenes': {}, 'mean': {}}, 'seeds': [0]}))
  renerf_scenes.main(['--name', 'x', '--refresh', str(path)])
  table = json.loads(path.read_text())
  assert table['command'] == 'python -m experiments.renerf_scenes --name old'
  assert table['summary']['scenes']['lego']['R1']['paired']['psnr']['p_holm'] == (
      pytest.approx(want[0]))
  text = (tmp_path / 'old.md').read_text()
  assert text == renerf_scenes.markdown(summary, ['lego'], table['command'])
  assert not (tmp_path / 'old.png').exists()
  (tmp_path / 'bad.json').write_text('{"rows": {}}')
  with pytest.raises(SystemExit, match='bad.json is not a renerf_scenes table'):
    renerf_scenes.main(['--name', 'x', '--refresh', str(tmp_path / 'bad.json')])


def test_scenes_table_with_d_sharing_b_seed_copies_b_as_its_controls(tmp_path):
  """Config.d_seed = 'same': the seed-matched controls are B and B 2x themselves, copied
  bit for bit (nothing trained), and R1 is paired with them."""
  out = tmp_path / 'results'
  cmd = ([sys.executable, '-m', 'experiments.renerf_scenes', '--name', 'same', '--config',
          'gin_configs/demo_llff.gin', '--out', str(out), '--seeds', '0', '--scenes',
          'procedural', "--gin_bindings=Config.dataset_loader='procedural'",
          "--gin_bindings=Config.d_seed='same'"] + [f'--gin_bindings={b}' for b in TINY])
  res = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=900,
                       check=False)
  assert res.returncode == 0, res.stderr[-3000:]
  root = out / 'same' / 'procedural'
  params = lambda label, r=0: (root / label / 'seed0' / f'round_{r}' /
                               'params.msgpack').read_bytes()
  assert params(renerf_scenes.CONTROL) == params('Re-Nerfing')
  assert params(renerf_scenes.CONTROL_2X) == params(renerf_scenes.TWO_X)
  assert params('Re-Nerfing', 1) != params('Re-Nerfing')  # D trained on pseudo-views
  rows = json.loads((out / 'same.json').read_text())['rows']['procedural']
  assert rows[renerf_scenes.CONTROL]['0']['psnr'] == rows['B']['0']['psnr']


def test_seed_spread_reports_each_rows_spread_and_the_views_that_spread(tmp_path):
  """experiments/seed_spread.py on a synthetic table and two synthetic runs."""
  from experiments import seed_spread  # pylint: disable=g-import-not-at-top
  from renerf_jax import report  # pylint: disable=g-import-not-at-top
  m = lambda p: {'psnr': p, 'ssim': 0.5, 'lpips_alex': 0.2}
  report.write_json(str(tmp_path / 't.json'),
                    {'rows': {'lego': {'B': {'0': m(20.), '1': m(22.), '2': m(21.)}}}})
  runs = []
  for i, psnrs in enumerate(([20., 25.], [20.5, 15.])):
    d = tmp_path / f'run{i}' / 'round_0' / 'eval'
    d.mkdir(parents=True)
    report.write_json(str(d / 'metrics.json'), {'per_image': [
        {'name': f'test_{j}', 'psnr': p} for j, p in enumerate(psnrs)]})
    runs.append(str(tmp_path / f'run{i}'))
  seed_spread.main(['--tables', str(tmp_path / 't.json'), '--runs', 'B=' + ','.join(runs),
                    '--out', str(tmp_path / 's')])
  out = json.loads((tmp_path / 's.json').read_text())
  b = out['tables']['t']['lego']['B']
  assert b['seeds'] == [0, 1, 2] and b['psnr']['mean'] == pytest.approx(21.)
  assert b['psnr']['std'] == pytest.approx(1.) and (b['psnr']['min'], b['psnr']['max']) == (20., 22.)
  views = out['views']['B']
  assert [v['name'] for v in views] == ['test_1', 'test_0']  # the spread one first
  assert views[0]['std'] == pytest.approx(np.std([25., 15.], ddof=1))
  md = (tmp_path / 's.md').read_text()
  assert '| t | lego | B | 3 | 21.00 +- 1.00 [20.00, 22.00] |' in md
  assert_table_cells(md)
  with pytest.raises(SystemExit, match='not LABEL=DIR'):
    seed_spread.main(['--tables', str(tmp_path / 't.json'), '--runs', 'B', '--out',
                      str(tmp_path / 'x')])


def test_seed_spread_compares_two_spreads_with_an_f_test(tmp_path):
  """--f_test: the PSNRs of one or more rows pooled per group, both stds and the
  two-sided F-test's p (issue 62: a spread claim needs a variance test)."""
  import scipy.stats  # pylint: disable=g-import-not-at-top
  from experiments import seed_spread  # pylint: disable=g-import-not-at-top
  from renerf_jax import report  # pylint: disable=g-import-not-at-top
  m = lambda p: {'psnr': p, 'ssim': 0.5, 'lpips_alex': 0.2}
  wide = [20., 22., 21., 23., 19.]
  narrow = [21., 21.2, 20.9, 21.1]
  report.write_json(str(tmp_path / 'a.json'), {'rows': {'lego': {
      'B': {str(i): m(v) for i, v in enumerate(wide[:3])},
      'C': {str(i): m(v) for i, v in enumerate(wide[3:])}}}})
  report.write_json(str(tmp_path / 'b.json'), {'rows': {'lego': {
      'B': {str(i): m(v) for i, v in enumerate(narrow)}}}})
  a, b = tmp_path / 'a.json', tmp_path / 'b.json'
  seed_spread.main(['--tables', str(a), str(b), '--f_test', f'wide={a}:lego:B;{a}:lego:C',
                    f'narrow={b}:lego:B', '--out', str(tmp_path / 's')])
  [t] = json.loads((tmp_path / 's.json').read_text())['f_tests']
  ratio = np.var(wide, ddof=1) / np.var(narrow, ddof=1)
  assert (t['n_a'], t['n_b']) == (5, 4) and t['ratio'] == pytest.approx(ratio)
  assert t['p'] == pytest.approx(2 * scipy.stats.f.sf(ratio, 4, 3), rel=1e-9)
  assert t['shown'] == (t['p'] < 0.05)
  md = (tmp_path / 's.md').read_text()
  assert f"| wide | 5 | {np.std(wide, ddof=1):.2f} | narrow | 4 | " in md
  assert_table_cells(md)
  with pytest.raises(SystemExit, match="has no row 'X'"):
    seed_spread.main(['--tables', str(a), '--f_test', f'x={a}:lego:X', f'y={a}:lego:B',
                      '--out', str(tmp_path / 'x')])
  with pytest.raises(SystemExit, match='not LABEL=TABLE:SCENE:ROW'):
    seed_spread.main(['--tables', str(a), '--f_test', 'x', f'y={a}:lego:B', '--out',
                      str(tmp_path / 'x')])


def test_compare_tables_pairs_rows_of_two_tables_by_scene_and_seed(tmp_path):
  """experiments/compare_tables.py: row of one table minus a row of another, paired by
  (scene, seed) over the common ones; a file that is no table is one clear error."""
  from experiments import compare_tables  # pylint: disable=g-import-not-at-top
  m = lambda p, s, l: {'psnr': p, 'ssim': s, 'lpips_alex': l}
  a = {'rows': {'fern': {'B': {'0': m(20., .6, .2), '1': m(21., .7, .1), '2': m(9., .1, .9)}},
                'room': {'B': {'0': m(18., .5, .3)}}}}
  b = {'rows': {'fern': {'B': {'0': m(19., .5, .3), '1': m(20.5, .75, .1)}},
                'room': {'B': {'0': m(18.5, .5, .2)}}, 'trex': {'B': {'0': m(1., 0., 1.)}}}}
  for name, t in (('a', a), ('b', b)):
    (tmp_path / f'{name}.json').write_text(json.dumps(t))
  out = tmp_path / 'res' / 'cmp'
  compare_tables.main(['--a', str(tmp_path / 'a.json'), '--a_label', 'drop',
                       '--b', str(tmp_path / 'b.json'), '--b_label', 'plain',
                       '--out', str(out)])
  res = json.loads((tmp_path / 'res' / 'cmp.json').read_text())
  assert [tuple(p) for p in res['pairs']] == [('fern', 0), ('fern', 1), ('room', 0)]
  np.testing.assert_allclose(res['scenes']['fern']['psnr']['mean'], 0.75)
  assert res['scenes']['fern']['psnr']['wins'] == 2
  assert res['scenes']['fern']['lpips_alex']['wins'] == 1  # -0.1 better, 0 not.
  np.testing.assert_allclose(res['pooled']['psnr']['mean'], (1. + .5 - .5) / 3)
  assert res['pooled']['psnr']['n'] == 3 and res['pooled']['psnr']['wins'] == 2
  np.testing.assert_allclose(res['means']['b']['psnr'], (19. + 20.5 + 18.5) / 3)
  md = (tmp_path / 'res' / 'cmp.md').read_text()
  assert '| **all** | +0.33 +- 0.76 (2/3)' in md and 'compare_tables --a' in md
  # One Holm family per column: fern (2 pairs) and the pooled row (room's 1 pair has no p).
  fern, pooled = res['scenes']['fern']['psnr'], res['pooled']['psnr']
  assert fern['family'] == pooled['family'] == 2 and res['scenes']['room']['psnr']['p'] is None
  from experiments import paired  # pylint: disable=g-import-not-at-top
  want = paired.holm_adjust([fern['p'], pooled['p']])
  assert [fern['p_holm'], pooled['p_holm']] == pytest.approx(want)
  assert f"Holm {pooled['p_holm']:.2g}" in md
  # Over one scene the pooled row is that scene's test, not a second one.
  compare_tables.main(['--a', str(tmp_path / 'a.json'), '--a_label', 'drop', '--b',
                       str(tmp_path / 'b.json'), '--b_label', 'plain', '--out', str(out)])
  one = compare_tables.compare({'fern': a['rows']['fern']}, 'B', {'fern': b['rows']['fern']}, 'B')
  assert one['pooled']['psnr'] == one['scenes']['fern']['psnr']
  assert one['pooled']['psnr']['p_holm'] == pytest.approx(one['pooled']['psnr']['p'])
  (tmp_path / 'bad.json').write_text('{"name": 1}')
  with pytest.raises(SystemExit, match='bad.json: not a renerf_scenes table'):
    compare_tables.main(['--a', str(tmp_path / 'bad.json'), '--a_label', 'x',
                         '--b', str(tmp_path / 'b.json'), '--b_label', 'y',
                         '--out', str(out)])
  with pytest.raises(SystemExit, match="no \\(scene, seed\\) has both row 'R1'"):
    compare_tables.main(['--a', str(tmp_path / 'a.json'), '--a_row', 'R1', '--a_label',
                         'x', '--b', str(tmp_path / 'b.json'), '--b_label', 'y',
                         '--out', str(out)])
