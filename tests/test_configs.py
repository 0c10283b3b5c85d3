import dataclasses
import glob
import os
import re
import subprocess
import sys

import pytest

from renerf_jax.cli import default_run_dir
from renerf_jax.config_checks import pseudo_steps
from renerf_jax.configs import Config, load_config
from renerf_jax.errors import ConfigError

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
GIN = os.path.join(REPO, 'gin_configs')
TABLES = os.path.join(REPO, 'experiments', 'configs')
TOP_LEVEL = sorted(glob.glob(os.path.join(GIN, '*.gin')) + glob.glob(os.path.join(TABLES, '*.gin')))
MODIFIERS = sorted(glob.glob(os.path.join(GIN, 'modifiers', '*.gin')))


def _gin(*names):
  return load_config([n if os.path.isabs(n) else os.path.join(GIN, n) for n in names])


@pytest.mark.parametrize('path', TOP_LEVEL)
def test_every_gin_config_parses(path):
  config = load_config([path])
  assert isinstance(config, Config)


@pytest.mark.parametrize('path', MODIFIERS)
def test_every_modifier_stacks_on_llff3(path):
  assert isinstance(load_config([os.path.join(GIN, 'llff3.gin'), path]), Config)


def test_llff3_has_regnerf_values():
  c = load_config([os.path.join(REPO, 'gin_configs', 'llff3.gin')])
  assert (c.factor, c.n_input_views, c.max_steps, c.batch_size, c.num_samples) == (
      8, 3, 69768, 4096, 128)
  assert (c.lr_init, c.lr_final, c.lr_delay_steps, c.lr_delay_mult) == (2e-3, 2e-5, 512, .01)
  assert (c.grad_max_norm, c.grad_max_val, c.coarse_loss_mult) == (0.1, 0.1, 0.1)
  assert c.use_ndc and c.ray_shape == 'cylinder' and c.density_noise == 1.
  assert (c.net_depth, c.net_width, c.skip_layer, c.net_width_viewdirs, c.deg_view) == (
      8, 256, 4, 128, 4)
  assert (c.depth_tv_mult_start, c.depth_tv_mult_end, c.depth_tv_maxstep) == (400., .1, 512)
  assert (c.anneal_nearfar_steps, c.anneal_nearfar_perc, c.anneal_mid_perc) == (512, 1e-4, 1.)
  assert (c.n_random_poses, c.batch_size_random, c.patch_size) == (10000, 4096, 8)
  assert not c.freq_reg and c.occ_reg_mult == 0.


def _bindings(path):
  """{field: value text} of a gin file's own `Config.x = ...` lines (not its includes)."""
  with open(path) as f:
    return dict(re.findall(r'^Config\.(\w+)\s*=\s*(.+?)\s*$', f.read(), re.M))


def test_defaults_have_one_source():
  """The RegNeRF llff3 values live in Config only: llff3.gin, the data it shares with the
  Gaussians (llff3_data.gin) and renerf.gin bind nothing that equals a default (a restated
  default would be a second source of truth)."""
  for name in ('llff3.gin', 'llff3_data.gin', 'renerf.gin'):
    only = _gin(name)
    for field in _bindings(os.path.join(GIN, name)):
      assert getattr(only, field) != getattr(Config(), field), (name, field)
  assert set(_bindings(os.path.join(GIN, 'llff3.gin'))) == {'eval_every', 'checkpoint_every'}
  assert set(_bindings(os.path.join(GIN, 'llff3_data.gin'))) == {'data_dir'}
  assert _gin('llff3.gin') == dataclasses.replace(
      Config(), data_dir='../shared/data/nerf_llff_data', eval_every=5000,
      checkpoint_every=2500)


def test_config_comments_carry_no_measurements():
  """Measured results live in experiments/results/<question>/README.md, not in gin comments."""
  for path in TOP_LEVEL + MODIFIERS:
    with open(path) as f:
      text = f.read()
    assert not re.search(r'\d dB|\d+(\.\d+)? / 0\.\d', text), path


def test_bare_config_names_resolve_through_gin_configs(tmp_path, monkeypatch):
  """`--gin_configs=llff3.gin` (or `llff3`) works from any directory."""
  expected = load_config([os.path.join(GIN, 'llff3.gin')])
  monkeypatch.chdir(tmp_path)
  assert load_config(['llff3.gin']) == expected
  assert load_config(['llff3']) == expected
  assert load_config(['llff3_fast.gin', 'renerf.gin']) == _gin('llff3_fast.gin', 'renerf.gin')
  assert load_config(['llff3', 'modifiers/mipnerf']) == _gin('llff3.gin',
                                                             'modifiers/mipnerf.gin')
  # A file of that name in the working directory wins over gin_configs/.
  (tmp_path / 'llff3.gin').write_text('Config.max_steps = 7\n')
  assert load_config(['llff3.gin']).max_steps == 7
  # A config outside gin_configs/ can include gin_configs/ files by name.
  (tmp_path / 'mine.gin').write_text("include 'llff3_cpu.gin'\nConfig.seed = 3\n")
  assert load_config([str(tmp_path / 'mine.gin')]) == dataclasses.replace(
      _gin('llff3_cpu.gin'), seed=3)
  assert default_run_dir(['llff3']) == default_run_dir(['llff3.gin']) == os.path.join(
      'runs', 'llff3')
  # Stacked configs name the run after all of them: two bases never share a directory.
  assert default_run_dir(['gin_configs/llff3_cpu.gin', 'renerf.gin']) == os.path.join(
      'runs', 'llff3_cpu+renerf')


def test_unknown_bare_config_name_is_one_clear_error(tmp_path, monkeypatch):
  monkeypatch.chdir(tmp_path)
  with pytest.raises(ConfigError, match='no_such_config') as e:
    load_config(['no_such_config'])
  assert len(str(e.value).splitlines()) == 1 and 'gin_configs' in str(e.value)


def test_train_py_finds_a_bare_config_name():
  """The issue's `python train.py --gin_configs=llff3.gin` from the repository root gets
  past config parsing (stopped by a bad binding before anything is loaded or written)."""
  res = subprocess.run([sys.executable, 'train.py', '--gin_configs=llff3.gin',
                        '--gin_bindings=Config.max_steps = 0'], cwd=REPO,
                       capture_output=True, text=True, timeout=300, check=False)
  assert res.returncode == 2, res.stderr[-2000:]
  assert 'Config.max_steps=0 must be > 0' in res.stderr and 'not found' not in res.stderr


def test_small_configs_change_sizes_not_code_paths():
  base = load_config([os.path.join(REPO, 'gin_configs', 'llff3.gin')])
  for name in ('llff3_cpu.gin', 'demo_llff.gin'):
    c = load_config([os.path.join(REPO, 'gin_configs', name)])
    for field in ('use_ndc', 'ray_shape', 'num_levels', 'anneal_nearfar', 'depth_tv_decay',
                  'field', 'use_viewdirs', 'freq_reg', 'stop_level_grad'):
      assert getattr(c, field) == getattr(base, field), (name, field)


def test_unknown_binding_is_one_clear_error():
  with pytest.raises(ConfigError, match='Config.no_such_knob'):
    load_config([], ['Config.no_such_knob = 3'])


def test_missing_config_file():
  with pytest.raises(ConfigError, match='nope.gin'):
    load_config(['nope.gin'])


def test_bad_value_names_the_field():
  with pytest.raises(ConfigError, match='ray_shape'):
    load_config([], ["Config.ray_shape = 'sphere'"])
  for field in ('hessian_chunk', 'render_chunk'):
    with pytest.raises(ConfigError, match=f'Config.{field}=0 must be >= 1'):
      load_config([], [f'Config.{field} = 0'])
  with pytest.raises(ConfigError, match=r'Config.gs_init_views=4 must lie in \[0, '):
    load_config([], ["Config.backbone = 'gaussians'", 'Config.gs_init_views = 4'])


def test_bindings_do_not_leak_and_config_gin_round_trips(tmp_path):
  from renerf_jax.configs import config_to_gin  # pylint: disable=g-import-not-at-top
  c = load_config([os.path.join(REPO, 'gin_configs', 'demo_llff.gin')],
                  ['Config.max_steps = 7', 'Config.num_rounds = 0'])
  assert Config().max_steps == 69768  # nothing of the parse leaks into later Configs
  path = tmp_path / 'config.gin'
  path.write_text(config_to_gin(c))
  assert load_config([str(path)]) == c


# The configs before the restructuring (commit 6bace58) and the files that replace them,
# with the fields that tell them apart. K is a fraction of max_steps now, with the
# paper's ray mix by default; the table configs keep the issue-7 mix and K.
OLD_TO_NEW = {
    'llff3_renerf.gin': (('llff3.gin', 'renerf.gin'),
                         dict(field='mlp', max_steps=69768, num_rounds=3, pseudo_until_frac=0.072,
                              pseudo_mix='pixels')),
    'llff3_cpu_renerf.gin': (('llff3_cpu.gin', 'renerf.gin'),
                             dict(field='mlp', max_steps=2000, num_rounds=3, pseudo_until_frac=0.072)),
    'llff3_fast_renerf.gin': (('llff3_fast.gin', 'renerf.gin'),
                              dict(field='grid', max_steps=800, num_rounds=3, pseudo_until_frac=0.27,
                                   anneal_nearfar=False)),
    'llff3_small_renerf.gin': ((os.path.join(TABLES, 'table_small.gin'),),
                               dict(field='grid', max_steps=400, batch_size=1024,
                                    image_downsample=2, anneal_nearfar=True, num_rounds=3,
                                    pseudo_until_frac=0.5, pseudo_mix='fraction', hessian_rays=16384, eval_stride=4,
                                    lpips_nets=('alex',), mask_signal='laplace')),
    'llff3_tiny_renerf.gin': ((os.path.join(TABLES, 'table_tiny.gin'),),
                              dict(field='grid', max_steps=400, batch_size=512,
                                   image_downsample=4, anneal_nearfar=True, num_rounds=3,
                                   pseudo_until_frac=0.5, pseudo_mix='fraction', hessian_rays=8192, eval_stride=2,
                                   lpips_nets=('alex',), mask_signal='laplace')),
}
# What every old *_renerf.gin set: the method's settings (Config's defaults) and 3 rounds.
RENERF = dict(num_rounds=3, interp_factors='7x', sequencing='position', pseudo_frac=0.5,
              pseudo_schedule='early', renerf_init='reset')


@pytest.mark.parametrize('old', sorted(OLD_TO_NEW))
def test_old_configs_map_to_new_files(old):
  new, expected = OLD_TO_NEW[old]
  c = _gin(*new)
  assert {k: getattr(c, k) for k in expected} == expected, (old, new)
  assert {k: getattr(c, k) for k in RENERF} == RENERF
  assert c.data_dir == '../shared/data/nerf_llff_data'


@pytest.mark.parametrize('base', ['llff3.gin', 'llff3_cpu.gin', 'llff3_fast.gin',
                                  os.path.join(TABLES, 'llff3_10min.gin'),
                                  'llff3_proposal.gin', 'llff3_freenerf.gin',
                                  'demo_llff.gin'] + [
                                      ('llff3.gin', m) for m in MODIFIERS])
def test_renerf_gin_on_any_base_adds_only_the_rounds(base):
  """renerf.gin stacked after a base changes num_rounds to 3 and nothing else; K
  (pseudo_until_frac) and the method's settings are the base's (Config's defaults)."""
  base = base if isinstance(base, tuple) else (base,)
  c, b = _gin(*base, 'renerf.gin'), _gin(*base)
  assert c.num_rounds == 3
  assert dataclasses.replace(c, num_rounds=b.num_rounds) == b
  # K comes after the near/far annealing (when on), the depth-TV decay and the warm-up.
  assert pseudo_steps(c) > max(c.anneal_nearfar_steps * c.anneal_nearfar,
                               c.depth_tv_maxstep, c.lr_delay_steps)


def test_table_configs_include_a_base_renerf_and_modifiers_only():
  """No include chains: each table config includes a gin_configs/ base (a user config)
  and, for the Re-Nerfing tables, renerf.gin (the Gaussians' base holds its Re-Nerfing
  protocol itself), then at most gin_configs/modifiers/ files, which include nothing,
  and states its own differences."""
  bases = {os.path.basename(p) for p in glob.glob(os.path.join(GIN, '*.gin'))} - {
      'renerf.gin'}
  for path in glob.glob(os.path.join(TABLES, '*.gin')):
    with open(path) as f:
      includes = re.findall(r"^include '(.+)'", f.read(), re.M)
    assert includes[:1] and includes[0] in bases, path
    n = 2 if includes[1:2] == ['renerf.gin'] else 1
    assert all(i.startswith('modifiers/') for i in includes[n:]), path
    for i in includes[n:]:
      with open(os.path.join(GIN, i)) as f:
        assert not re.search(r"^include ", f.read(), re.M), i
    assert all(os.path.isfile(os.path.join(GIN, i)) for i in includes)


def test_small_table_config_is_the_fast_one_smaller():
  """table_small.gin: the fast Re-Nerfing config at half resolution, with every
  schedule in steps scaled with max_steps (K at half the steps, as in the fast one) and
  RegNeRF's near/far annealing on."""
  small = load_config([os.path.join(TABLES, 'table_small.gin')])
  fast = _gin('llff3_fast.gin', 'renerf.gin')
  assert small.image_downsample == 2 and fast.image_downsample == 1
  assert small.max_steps < fast.max_steps and small.batch_size < fast.batch_size
  assert pseudo_steps(small) == small.max_steps // 2 and small.pseudo_mix == 'fraction'
  for c in (small, fast):
    assert pseudo_steps(c) > max(c.depth_tv_maxstep, c.lr_delay_steps)
  assert (small.lr_delay_steps / small.max_steps) == pytest.approx(
      fast.lr_delay_steps / fast.max_steps, rel=0.3)
  assert small.anneal_nearfar and not fast.anneal_nearfar
  sizes = ('anneal_nearfar', 'image_downsample', 'batch_size', 'batch_size_random', 'max_steps',
           'anneal_nearfar_steps', 'lr_delay_steps', 'depth_tv_maxstep', 'pseudo_until_frac',
           'pseudo_mix', 'mask_signal',
           'eval_every', 'eval_stride', 'checkpoint_every', 'hessian_rays', 'lpips_nets')
  assert dataclasses.replace(small, **{k: getattr(fast, k) for k in sizes}) == fast


def test_tiny_table_config_is_the_small_one_at_quarter_resolution():
  """table_tiny.gin (the hour-budget tables): the small table config at a quarter of
  the resolution with half the rays per step and half the Hessian rays; the schedule, the
  regularisers and the Re-Nerfing settings are the small config's, and the cheap eval
  sees as many pixels per test view."""
  tiny = load_config([os.path.join(TABLES, 'table_tiny.gin')])
  small = load_config([os.path.join(TABLES, 'table_small.gin')])
  assert (tiny.image_downsample, small.image_downsample) == (4, 2)
  assert tiny.batch_size * 2 == small.batch_size
  assert tiny.hessian_rays * 2 == small.hessian_rays
  assert tiny.eval_stride * tiny.image_downsample == small.eval_stride * small.image_downsample
  sizes = ('image_downsample', 'batch_size', 'hessian_rays', 'eval_stride')
  assert dataclasses.replace(tiny, **{k: getattr(small, k) for k in sizes}) == small


def test_bad_ray_mix_or_k_is_one_config_error():
  with pytest.raises(ConfigError, match='pseudo_mix'):
    load_config([], ["Config.pseudo_mix = 'half'"])
  for k in (-0.1, 1.5):
    with pytest.raises(ConfigError, match=r'pseudo_until_frac=.* must lie in \[0, 1\]'):
      load_config([], [f'Config.pseudo_until_frac = {k}'])
  # K before the near/far annealing ends (llff3: 512 steps) is refused with rounds on ...
  with pytest.raises(ConfigError, match='before the near/far annealing ends') as e:
    load_config(['llff3.gin', 'renerf.gin'], ['Config.pseudo_until_frac = 0.007'])
  assert '\n' not in str(e.value) and '0.0073' in str(e.value)
  # ... and accepted where it cannot matter: no rounds, no annealing, or K unused.
  load_config(['llff3.gin'], ['Config.pseudo_until_frac = 0.007'])
  load_config(['llff3.gin', 'renerf.gin'], ['Config.pseudo_until_frac = 0.007',
                                            'Config.anneal_nearfar = False'])
  load_config(['llff3.gin', 'renerf.gin'], ['Config.pseudo_until_frac = 0.007',
                                            "Config.pseudo_schedule = 'all'"])
  assert pseudo_steps(load_config(['llff3.gin', 'renerf.gin'])) == 5023  # 7.2% of 69768


# ------------------------------------------------------------------ fields by backbone


def _other_value(value):
  """A value unlike `value` of the same kind (a field set away from its default)."""
  if isinstance(value, bool):
    return not value
  if isinstance(value, (int, float)):
    return value + 1
  if isinstance(value, str):
    return value + 'x'
  return tuple(value) + (value[:1] or ('x',))


def test_every_field_declares_its_concern_and_backbone():
  from renerf_jax import config_fields  # pylint: disable=g-import-not-at-top
  for f in dataclasses.fields(Config):
    assert f.metadata['backbone'] in ('nerf', 'gaussians', 'both'), f.name
    assert f.metadata['group'] in config_fields.GROUPS, f.name
    assert f.metadata['affects'] in config_fields.AFFECTS, f.name
    # A NeRF or Gaussians concern is read by that backbone alone.
    if f.metadata['group'] in ('nerf', 'gaussians'):
      assert f.metadata['backbone'] == f.metadata['group'], f.name
    assert (f.metadata['backbone'] == 'gaussians') == f.name.startswith('gs_'), f.name
  # Fields the code reads on both paths (datasets, pseudo-view poses, the round driver,
  # the run directory, evaluation) or on the NeRF's alone.
  for name in ('data_dir', 'use_ndc', 'white_bkgd', 'seed', 'init_seed', 'max_steps',
               'random_pose_spread', 'pseudo_until_frac', 'renerf_init', 'use_masks',
               'mask_signal', 'mask_keep_frac', 'eval_every', 'eval_stride', 'lpips_nets'):
    assert config_fields.field_backbone(Config, name) == 'both', name
  for name in ('batch_size', 'lr_init', 'anneal_nearfar', 'pseudo_mix', 'pseudo_frac',
               'hessian_rays', 'render_chunk', 'near_camera_loss_mult', 'grid_box'):
    assert config_fields.field_backbone(Config, name) == 'nerf', name


def test_a_nerf_setting_on_the_gaussians_is_one_clear_error():
  with pytest.raises(ConfigError) as e:
    load_config(['gaussians_llff3.gin'], ['Config.lr_init = 0.01'])
  assert str(e.value) == ("Config.lr_init=0.01 is a NeRF setting; "
                          "Config.backbone='gaussians' ignores it")
  with pytest.raises(ConfigError, match=r"^Config.anneal_nearfar=False is a NeRF setting; "
                                        r"Config.backbone='gaussians' ignores it$"):
    load_config(['gaussians_llff3_cpu.gin', 'modifiers/no_anneal.gin'])
  gaussians = load_config(['gaussians_llff3.gin'])
  with pytest.raises(ConfigError, match='Config.near_camera_loss_mult=1.0 is a NeRF setting'):
    dataclasses.replace(gaussians, near_camera_loss_mult=1.)
  # Every NeRF field, alone away from its default, is named.
  for f in dataclasses.fields(Config):
    if f.metadata['backbone'] == 'nerf':
      value = _other_value(f.default)
      with pytest.raises(ConfigError, match=rf'^Config\.{f.name}=.* is a NeRF setting; '):
        dataclasses.replace(gaussians, **{f.name: value})


def test_a_gaussians_setting_on_the_nerf_is_one_clear_error():
  with pytest.raises(ConfigError) as e:
    load_config(['llff3.gin'], ['Config.gs_capacity = 100'])
  assert str(e.value) == ("Config.gs_capacity=100 is a Gaussians setting; "
                          "Config.backbone='nerf' ignores it")
  nerf = load_config(['llff3_fast.gin'])
  for f in dataclasses.fields(Config):
    if f.metadata['backbone'] == 'gaussians':
      with pytest.raises(ConfigError, match=rf'^Config\.{f.name}=.* is a Gaussians setting; '
                                            r"Config.backbone='nerf' ignores it"):
        dataclasses.replace(nerf, **{f.name: _other_value(f.default)})
  # A setting at its default is no setting: either backbone takes it, lists as tuples.
  assert load_config(['gaussians_llff3.gin'], ['Config.lr_init = 2e-3',
                                               'Config.grid_box = [[-1, -1, -1], [1, 1, 1]]'])
  assert load_config(['llff3.gin'], ['Config.gs_background = [0, 0, 0]'])


def test_every_shipped_config_loads_and_binds_only_what_its_backbone_reads():
  """Every config of gin_configs/ and experiments/configs/ loads (no field its backbone
  ignores away from its default, through its includes too); the Gaussian ones and the
  NeRF ones share the LLFF data through llff3_data.gin."""
  from renerf_jax.config_fields import ignored_settings  # pylint: disable=g-import-not-at-top
  backbones = {}
  for path in TOP_LEVEL:
    c = load_config([path])
    assert not ignored_settings(c), path
    backbones.setdefault(c.backbone, []).append(os.path.basename(path))
  assert {'gaussians_llff3.gin', 'table_gaussians.gin'} <= set(backbones['gaussians'])
  assert {'llff3.gin', 'fox12.gin', 'table_converged2.gin'} <= set(backbones['nerf'])
  for name in ('llff3.gin', 'gaussians_llff3.gin'):
    with open(os.path.join(GIN, name)) as f:
      assert re.findall(r"^include '(.+)'", f.read(), re.M) == ['llff3_data.gin'], name
  data = _gin('llff3_data.gin')
  for name in ('llff3.gin', 'gaussians_llff3.gin', 'gaussians_llff3_cpu.gin'):
    c = _gin(name)
    assert (c.data_dir, c.dataset_loader, c.factor, c.n_input_views, c.llffhold) == (
        data.data_dir, 'llff', 8, 3, 8), name
  # The lego configs of both backbones share lego8_data.gin's data and split the same way.
  fields = ('dataset_loader', 'data_dir', 'scene', 'n_input_views', 'test_stride',
            'white_bkgd', 'use_ndc', 'near', 'far', 'blender_split')
  # So do the fox configs with fox12_data.gin (the Gaussians' also undistort the photos).
  fields += ('image_downsample', 'normalize_poses', 'llffhold')
  for data_gin, names in (('lego8_data.gin', ('lego8.gin', 'gaussians_lego8.gin')),
                          ('fox12_data.gin', ('fox12.gin', 'gaussians_fox12.gin'))):
    data = _gin(data_gin)
    for name in names:
      with open(os.path.join(GIN, name)) as f:
        assert data_gin in re.findall(r"^include '(.+)'", f.read(), re.M), name
      c = _gin(name)
      assert [getattr(c, k) for k in fields] == [getattr(data, k) for k in fields], name
  lego = _gin('lego8_data.gin')
  assert (lego.scene, lego.n_input_views, lego.blender_split) == ('lego', 8, 'standard')
  assert (data.scene, data.n_input_views, data.normalize_poses) == ('fox', 12, True)
  assert _gin('gaussians_fox12.gin').undistort and not _gin('fox12.gin').undistort
  # Both wide-baseline Gaussian configs take their recipe and protocol from one file and
  # restate none of it.
  with open(os.path.join(GIN, 'gaussians_wide_recipe.gin')) as f:
    recipe = re.findall(r'^Config\.(\w+) = ', f.read(), re.M)
  assert {'backbone', 'max_steps', 'pseudo_until_frac', 'use_masks'} <= set(recipe)
  for name in ('gaussians_lego8.gin', 'gaussians_fox12.gin'):
    with open(os.path.join(GIN, name)) as f:
      text = f.read()
    assert 'gaussians_wide_recipe.gin' in re.findall(r"^include '(.+)'", text, re.M), name
    assert not set(re.findall(r'^Config\.(\w+) = ', text, re.M)) & set(recipe), name
    c, r = _gin(name), _gin('gaussians_wide_recipe.gin')
    assert [getattr(c, k) for k in recipe] == [getattr(r, k) for k in recipe], name


def test_the_near_far_annealing_bounds_k_of_the_nerf_only():
  """K before the annealing ends is refused with the NeRF; the Gaussians have no
  annealing (their 750-step table config puts K at step 202)."""
  c = load_config([os.path.join(TABLES, 'table_gaussians.gin')], ['Config.num_rounds = 1'])
  assert pseudo_steps(c) == 202 and c.anneal_nearfar == Config().anneal_nearfar
  with pytest.raises(ConfigError, match='before the near/far annealing ends'):
    load_config(['llff3.gin', 'renerf.gin'], ['Config.max_steps = 750',
                                              'Config.pseudo_until_frac = 0.27'])


def test_runs_saved_with_an_ignored_setting_still_resume_and_load(tmp_path):
  """A Gaussian run made before the check (its config.json / config.gin with the old
  gaussians_llff3.gin's anneal_nearfar = False) compares equal to today's config and
  loads as a run directory; a field the backbone reads still differs."""
  from renerf_jax.configs import config_differences, config_to_gin  # pylint: disable=g-import-not-at-top
  from renerf_jax.report import to_jsonable  # pylint: disable=g-import-not-at-top
  c = load_config(['gaussians_llff3_cpu.gin'])
  saved = dict(to_jsonable(dataclasses.asdict(c)), anneal_nearfar=False)
  assert config_differences(c, saved) == []
  assert config_differences(c, dict(saved, gs_min_opacity=0.5)) == ['gs_min_opacity']
  assert config_differences(c, dict(saved, backbone='nerf')) == ['backbone']
  old = tmp_path / 'config.gin'
  old.write_text(config_to_gin(c) + 'Config.anneal_nearfar = False\n')
  with pytest.raises(ConfigError, match='anneal_nearfar=False is a NeRF setting'):
    load_config([str(old)])
  assert load_config([str(old)], reset_ignored=True) == c
  # A config.gin written now reads back identically, in the declaration order.
  new = tmp_path / 'new.gin'
  new.write_text(config_to_gin(c))
  assert load_config([str(new)]) == load_config([str(new)], reset_ignored=True) == c
  assert [line.split(' = ')[0][len('Config.'):] for line in config_to_gin(c).splitlines()] == [
      f.name for f in dataclasses.fields(Config)]


def test_docs_list_every_field_under_its_concern_and_backbone():
  """docs/configs.md, "Config fields by concern": one section per concern, the fields of
  each backbone tag on lines starting 'both backbones', 'NeRF only', 'Gaussians only'."""
  from renerf_jax.config_fields import GROUPS, fields_by_group  # pylint: disable=g-import-not-at-top
  with open(os.path.join(REPO, 'docs', 'configs.md')) as f:
    text = f.read().split('## Config fields by concern')[1].split('\n## ')[0]
  labels = {'both backbones': 'both', 'NeRF only': 'nerf', 'Gaussians only': 'gaussians'}
  sections = re.split(r'^### ', text, flags=re.M)[1:]
  want = fields_by_group(Config)
  assert len(sections) == len(want)
  for (group, by_tag), section in zip(want.items(), sections):
    assert section.startswith(GROUPS[group]), (group, section[:60])
    assert section.startswith(f'{GROUPS[group]}: {sum(map(len, by_tag.values()))} fields')
    got = {}
    for label, names in re.findall(r'^- ([^:(]+?)(?: \(.*?\))?: (.+)$', section, re.M):
      got.setdefault(labels[label], []).extend(re.findall(r'`(\w+)`', names))
    assert {k: tuple(v) for k, v in got.items()} == by_tag, group
