"""3DGS's schedules in steps of the run: learning rates and the SH degree (densification's
is the strategy's, strategy.py).

Intervals are fractions of Config.max_steps (3DGS's iteration counts over its 30k steps),
so a short run keeps the reference's proportions.
"""
import jax.numpy as jnp
import optax

from renerf_jax import schedules

ADAM_EPS = 1e-15  # 3DGS's Adam epsilon.
# Optimised fields: the Gaussians' float fields with the SH split into DC and the rest
# (their learning rates differ).
FIELDS = ('means', 'log_scales', 'quats', 'opacity_logits', 'sh_dc', 'sh_rest')


def means_lr(iteration, config, extent):
  """Position lr at a 1-based iteration: extent x log-linear gs_lr_means_init -> _final
  over max_steps (3DGS's get_expon_lr_func without delay)."""
  return extent * schedules.log_lerp(iteration, config.gs_lr_means_init,
                                        config.gs_lr_means_final, config.max_steps)


def base_learning_rates(config, extent):
  """{field: lr} at the start (the position lr is then set every step)."""
  return {'means': extent * config.gs_lr_means_init, 'log_scales': config.gs_lr_scales,
          'quats': config.gs_lr_quats, 'opacity_logits': config.gs_lr_opacity,
          'sh_dc': config.gs_lr_sh_dc, 'sh_rest': config.gs_lr_sh_rest}


def steps_of(frac, config, minimum=0):
  """round(frac * max_steps), at least `minimum`."""
  return max(int(round(frac * config.max_steps)), minimum)


def sh_interval(config):
  return steps_of(config.gs_sh_interval_frac, config, 1)


def sh_degree_at(iteration, config):
  """SH degree at a 1-based iteration: +1 every sh_interval iterations, at most 3 (works
  on Python ints and traced arrays)."""
  return jnp.minimum(iteration // sh_interval(config), 3)


def make_optimizer(config, extent):
  """Per-field Adam (optax.multi_transform), 3DGS's learning rates, eps 1e-15.

  Each group's lr is an injected hyperparameter; train_step sets the position's from the
  step (set_means_lr), so the decay follows the step even across skipped updates.
  """
  lrs = base_learning_rates(config, extent)
  groups = {k: optax.inject_hyperparams(optax.adam)(learning_rate=lrs[k], eps=ADAM_EPS)
            for k in FIELDS}
  return optax.multi_transform(groups, {k: k for k in FIELDS})


def set_means_lr(opt_state, lr):
  """The multi_transform state with the position group's learning rate set to lr."""
  masked = opt_state.inner_states['means']
  inject = masked.inner_state
  hp = dict(inject.hyperparams, learning_rate=jnp.asarray(
      lr, inject.hyperparams['learning_rate'].dtype))
  inner = dict(opt_state.inner_states, means=masked._replace(
      inner_state=inject._replace(hyperparams=hp)))
  return opt_state._replace(inner_states=inner)
