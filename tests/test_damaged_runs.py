"""A run directory with damaged files (issue 63 item 4). A truncated or emptied training
checkpoint is set aside (renamed *.damaged, one warning line) and training resumes from
the checkpoint before it (a resumed run is bit for bit the uninterrupted one:
test_training.py); a damaged config.json or config.gin (or the two disagreeing), a
finished round's damaged params.msgpack or result.json, is one `error:` line and exit 2
from train.py, eval.py and the run summary, with nothing in the run directory changed."""
import dataclasses
import sys

import jax
import numpy as np
import pytest
from flax import serialization, struct

import eval as eval_py
import train
from conftest import tiny_config, tree_files
from experiments import run_summary
from renerf_jax import cli, rundir, run_contents
from renerf_jax.configs import config_to_gin
from renerf_jax.errors import RunDirError
from renerf_jax.round_driver import params_template


@struct.dataclass
class _State:
  step: np.ndarray
  w: np.ndarray


def _state(step, value):
  return _State(step=np.asarray(step, np.int32), w=np.full((3, 2), value, np.float32))


def _run_with_checkpoints(tmp_path):
  """A run directory: round 0 finished (files only), round 1 training with checkpoints at
  steps 4 and 8 (training keeps two) and a log to step 9."""
  run = tmp_path / 'run'
  r0 = rundir.round_dir(str(run), 0)
  rundir.mark_done(r0, {'round': 0})
  (run / 'round_0' / 'params.msgpack').write_bytes(b'B')
  out = rundir.train_dir(rundir.round_dir(str(run), 1))
  for step in (4, 8):
    rundir.save_training(out, _state(step, step), float(step))
  for step in range(1, 10):
    rundir.append_jsonl(rundir.log_path(out), {'step': step})
  return run, out


def _checkpoint(out, step):
  return rundir.checkpoint_path(rundir.checkpoints_dir(out), step)


@pytest.mark.parametrize('damage', ['truncated', 'zero_bytes'])
def test_a_damaged_checkpoint_resumes_from_the_one_before(damage, tmp_path, capsys):
  run, out = _run_with_checkpoints(tmp_path)
  finished = tree_files(run / 'round_0')
  path = _checkpoint(out, 8)
  with open(path, 'rb') as f:
    data = f.read()
  with open(path, 'wb') as f:
    f.write(data[:len(data) // 2] if damage == 'truncated' else b'')
  state, seconds, _ = rundir.resume_training(out, _state(0, 0.))
  assert int(state.step) == 4 and seconds == 4. and float(state.w[0, 0]) == 4.
  err = capsys.readouterr().err
  assert err.startswith(f'warning: {path} is damaged (') and err.count('\n') == 1, err
  assert err.endswith('moved to checkpoint_00000008.msgpack.damaged, resuming from step 4\n')
  # Set aside (never read again, kept to look at); the log cut at the restored step; the
  # finished round untouched.
  assert [s for s, _ in rundir.list_checkpoints(rundir.checkpoints_dir(out))] == [4]
  with open(path + '.damaged', 'rb') as f:
    assert len(f.read()) == (len(data) // 2 if damage == 'truncated' else 0)
  assert [r['step'] for r in rundir.read_jsonl(rundir.log_path(out))] == [1, 2, 3, 4]
  assert tree_files(run / 'round_0') == finished


def test_no_good_checkpoint_left_starts_over(tmp_path, capsys):
  run, out = _run_with_checkpoints(tmp_path)
  for step in (4, 8):
    with open(_checkpoint(out, step), 'wb') as f:
      f.write(b'\x92')
  state, seconds, curve = rundir.resume_training(out, _state(0, 0.))
  assert int(state.step) == 0 and seconds == 0. and curve == []
  err = capsys.readouterr().err.splitlines()
  assert len(err) == 2 and err[-1].endswith('no checkpoint left: training starts over')
  assert rundir.list_checkpoints(rundir.checkpoints_dir(out)) == []
  assert rundir.read_jsonl(rundir.log_path(out)) == []


def test_a_checkpoint_of_another_model_is_one_line(tmp_path):
  _, out = _run_with_checkpoints(tmp_path)
  with pytest.raises(RunDirError) as e:
    rundir.resume_training(out, {'other': np.zeros(2)})
  assert str(e.value).startswith(f"{_checkpoint(out, 8)} does not fit this run's model (")
  assert '\n' not in str(e.value)


# ------------------------------------------------- config.json, config.gin, finished rounds

CONFIG = dict(procedural_size=(12, 16), procedural_views=9, lpips_nets=(),
              mask_keep_frac=0.5)


def _made_run(tmp_path):
  """A run directory as train.py makes it (config.json, config.gin) with round 0
  finished (its params at initialisation, a result.json), and the train.py / eval.py
  arguments that resume it."""
  config = tiny_config(**CONFIG)
  gin_file = tmp_path / 'tiny.gin'
  gin_file.write_text(config_to_gin(config))
  run = tmp_path / 'run'
  cli.check_run_dir(config, str(run), create=True)
  r0 = rundir.round_dir(str(run), 0)
  (run / 'round_0').mkdir()
  (run / 'round_0' / 'params.msgpack').write_bytes(
      serialization.to_bytes(params_template(config, 0)))
  (run / 'round_0' / 'result.json').write_text('{"metrics": {"cumulative_seconds": 1.0}, '
                                                '"curve": []}')
  rundir.mark_done(r0, {'round': 0})
  return config, run, [f'--gin_configs={gin_file}', f'--run_dir={run}']


def _cut_config_gin(text, config):
  """config.gin cut at a line boundary before mask_keep_frac (a field set away from its
  default): it still parses, the field takes its default."""
  del config
  return text.split('Config.mask_keep_frac')[0]


@pytest.mark.parametrize('name,damage,says', [
    ('config.json', lambda t, c: t[:len(t) // 2], 'is damaged (JSONDecodeError: '),
    ('config.json', lambda t, c: '[1, 2]', 'is damaged (not an object of Config fields)'),
    ('config.gin', lambda t, c: t.replace("'procedural'", "'procedur"),
     'is damaged (bad gin configuration ('),
    ('config.gin', _cut_config_gin, 'is damaged: its Config.mask_keep_frac differs from '),
])
def test_a_damaged_stored_config_is_one_line_for_train_eval_and_the_viewer(
    name, damage, says, tmp_path, capsys):
  config, run, argv = _made_run(tmp_path)
  path = run / name
  path.write_text(damage(path.read_text(), config))
  before = tree_files(run)
  for main in (train.main, eval_py.main):
    with pytest.raises(SystemExit) as e:
      main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and err.count('\n') == 1, err
    assert err.startswith(f'error: {path} {says}'), err
  with pytest.raises(RunDirError, match=f'^{path} '):
    run_contents.run_config(str(run))  # The viewer's reading of the run.
  assert tree_files(run) == before


def test_the_run_summary_refuses_a_damaged_config_gin_before_writing(tmp_path, capsys,
                                                                     monkeypatch):
  _, run, _ = _made_run(tmp_path)
  (run / 'config.gin').write_text('Config.seed = \n')
  out = tmp_path / 'summary' / 'baseline'
  monkeypatch.setattr(sys, 'argv', ['run_summary', f'--runs={run}', '--data_dir=x',
                                    f'--out={out}'])
  with pytest.raises(SystemExit) as e:
    run_summary.main()
  err = capsys.readouterr().err
  assert e.value.code == 2 and err.startswith(f'error: {run}/config.gin is damaged (')
  assert err.count('\n') == 1 and not (tmp_path / 'summary').exists()


@pytest.mark.parametrize('name,says', [('params.msgpack', 'is damaged (ValueError: '),
                                       ('result.json', 'is damaged (JSONDecodeError)')])
def test_a_finished_rounds_damaged_files_are_one_line(name, says, tmp_path, capsys):
  _, run, argv = _made_run(tmp_path)
  path = run / 'round_0' / name
  path.write_bytes(path.read_bytes()[:-5])
  before = tree_files(run)
  with pytest.raises(SystemExit) as e:
    eval_py.main(argv)
  err = capsys.readouterr().err
  assert e.value.code == 2 and err.count('\n') == 1, err
  assert err.startswith(f'error: {path} {says}') and 'round 0' in err, err
  assert 'move that round directory aside to train the round again' in err
  assert tree_files(run) == before


def test_an_intact_run_directory_still_resumes(tmp_path):
  """The checks pass on what train.py wrote, also with a resumable field changed."""
  config, run, _ = _made_run(tmp_path)
  cli.check_run_dir(dataclasses.replace(config, eval_every=7), str(run), create=True)
  assert run_contents.run_config(str(run)) == config


def test_the_viewer_shows_the_last_good_checkpoint_and_renames_nothing(tmp_path):
  config, run, _ = _made_run(tmp_path)
  ckpts = rundir.round_checkpoints_dir(str(run), 1)
  params = params_template(config, 1)
  for step in (4, 8):
    rundir.save_checkpoint(ckpts, {'state': {'params': params}}, step)
  with open(rundir.checkpoint_path(ckpts, 8), 'r+b') as f:
    f.truncate(100)
  before = tree_files(run)
  got, step = run_contents.load_params(config, str(run), 1)
  assert step == 4 and tree_files(run) == before
  for a, b in zip(*map(jax.tree_util.tree_leaves, (got, params))):
    np.testing.assert_array_equal(a, b)
