import glob
import os

import pytest

from renerf_jax.configs import Config, load_config
from renerf_jax.errors import ConfigError

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.parametrize('path', sorted(glob.glob(os.path.join(REPO, 'gin_configs', '*.gin'))))
def test_every_gin_config_parses(path):
  config = load_config([path])
  assert isinstance(config, Config)


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


def test_small_configs_change_sizes_not_code_paths():
  base = load_config([os.path.join(REPO, 'gin_configs', 'llff3.gin')])
  for name in ('llff3_cpu.gin', 'demo.gin'):
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


def test_bindings_do_not_leak_and_config_gin_round_trips(tmp_path):
  from renerf_jax.configs import config_to_gin
  c = load_config([os.path.join(REPO, 'gin_configs', 'demo.gin')], ['Config.max_steps = 7'])
  assert Config().max_steps == 69768  # nothing of the parse leaks into later Configs
  path = tmp_path / 'config.gin'
  path.write_text(config_to_gin(c))
  assert load_config([str(path)]) == c


def test_renerf_configs_are_their_base_plus_three_rounds():
  import dataclasses
  for name, base_name, k in (('llff3_renerf.gin', 'llff3.gin', 5000),
                             ('llff3_cpu_renerf.gin', 'llff3_cpu.gin', 1000),
                             ('llff3_fast_renerf.gin', 'llff3_fast.gin', 400)):
    c = load_config([os.path.join(REPO, 'gin_configs', name)])
    base = load_config([os.path.join(REPO, 'gin_configs', base_name)])
    assert (c.num_rounds, c.interp_factors, c.pseudo_until) == (3, '7x', k)
    assert (c.renerf_init, c.pseudo_schedule) == ('reset', 'early')
    # K comes after the near/far annealing (when on), the depth-TV decay and the warm-up.
    assert k > max(c.anneal_nearfar_steps * c.anneal_nearfar, c.depth_tv_maxstep,
                   c.lr_delay_steps)
    assert dataclasses.replace(c, num_rounds=0) == dataclasses.replace(base, num_rounds=0)


def test_small_table_config_is_the_fast_one_smaller():
  """llff3_small_renerf.gin: the fast Re-Nerfing config at half resolution, with every
  schedule in steps scaled with max_steps (K at half the steps, as in the fast one) and
  RegNeRF's near/far annealing on."""
  import dataclasses
  small = load_config([os.path.join(REPO, 'gin_configs', 'llff3_small_renerf.gin')])
  fast = load_config([os.path.join(REPO, 'gin_configs', 'llff3_fast_renerf.gin')])
  assert small.image_downsample == 2 and fast.image_downsample == 1
  assert small.max_steps < fast.max_steps and small.batch_size < fast.batch_size
  for c in (small, fast):
    assert c.pseudo_until == c.max_steps // 2
    assert c.pseudo_until > max(c.depth_tv_maxstep, c.lr_delay_steps)
  assert (small.lr_delay_steps / small.max_steps) == pytest.approx(
      fast.lr_delay_steps / fast.max_steps, rel=0.3)
  assert small.anneal_nearfar and not fast.anneal_nearfar
  sizes = ('anneal_nearfar', 'image_downsample', 'batch_size', 'batch_size_random', 'max_steps',
           'anneal_nearfar_steps', 'lr_delay_steps', 'depth_tv_maxstep', 'pseudo_until',
           'eval_every', 'eval_stride', 'checkpoint_every', 'hessian_rays', 'lpips_nets')
  assert dataclasses.replace(small, **{k: getattr(fast, k) for k in sizes}) == fast


def test_tiny_table_config_is_the_small_one_at_quarter_resolution():
  """llff3_tiny_renerf.gin (the hour-budget tables): the small table config at a quarter of
  the resolution with half the rays per step and half the Hessian rays; the schedule, the
  regularisers and the Re-Nerfing settings are the small config's, and the cheap eval
  sees as many pixels per test view."""
  import dataclasses
  tiny = load_config([os.path.join(REPO, 'gin_configs', 'llff3_tiny_renerf.gin')])
  small = load_config([os.path.join(REPO, 'gin_configs', 'llff3_small_renerf.gin')])
  assert (tiny.image_downsample, small.image_downsample) == (4, 2)
  assert tiny.batch_size * 2 == small.batch_size
  assert tiny.hessian_rays * 2 == small.hessian_rays
  assert tiny.eval_stride * tiny.image_downsample == small.eval_stride * small.image_downsample
  sizes = ('image_downsample', 'batch_size', 'hessian_rays', 'eval_stride')
  assert dataclasses.replace(tiny, **{k: getattr(small, k) for k in sizes}) == small
