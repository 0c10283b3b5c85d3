"""The densification strategy: when and how the Gaussians grow, are pruned and have
their opacities reset (3DGS's adaptive density control), in one object.

After gsplat's `Strategy` (gsplat/strategy/default.py): a frozen dataclass of the
thresholds and the schedule, built from the Config (`DensityStrategy.of`), with its own
state, the per-slot gradient statistics (density.DensityStats, held in the train
state's `stats` and checkpointed with it). The training loop only calls it:

  strategy.initialize_state(n)         fresh statistics for n slots (init_state);
  strategy.update_state(stats, ...)    inside the jitted step, after the backward pass:
                                       the screen-space gradients of the step's view
                                       (they never leave the step, so this part of
                                       gsplat's step_post_backward runs in it);
  strategy.step_post_backward(state, done, extent, key)
                                       between steps: grow (clone / split) and prune,
                                       reset the opacities, when the schedule says so.

Growing and the opacity reset are jitted functions of the whole train state with the
strategy static; the scene keeps its fixed capacity (new Gaussians fill free slots), so
no shape changes and nothing recompiles. The math is density.py's. The schedule, in
3DGS's 1-based iterations `done` (steps of the run, from Config fractions of max_steps):

  * statistics are gathered while the iteration is < refine_stop;
  * densify when refine_start < done < refine_stop and done % refine_every == 0, also
    pruning by screen and world size once done > reset_every (after the first reset);
  * reset the opacities when done < refine_stop and done % reset_every == 0.
"""
import dataclasses
import functools

import jax
import jax.numpy as jnp

from renerf_jax.gaussians import density
from renerf_jax.gaussians.schedule import steps_of


@dataclasses.dataclass(frozen=True)
class DensityStrategy:
  """3DGS's densification: thresholds (Config.gs_*) and schedule (steps of the run)."""
  grad_threshold: float  # Densify slots whose mean NDC gradient is >= this.
  percent_dense: float  # Clone / split boundary as a fraction of the scene extent.
  min_opacity: float  # Prune opacities below this.
  refine_start: int  # Densify after this iteration ...
  refine_stop: int  # ... and before this one (statistics stop here too).
  refine_every: int  # Densify every this many iterations.
  reset_every: int  # Reset the opacities every this many iterations.

  @classmethod
  def of(cls, config):
    """The strategy of a Config (gs_grad_threshold, gs_percent_dense, gs_min_opacity,
    gs_densify_from_frac, gs_densify_until_frac, gs_densify_every_frac,
    gs_opacity_reset_every_frac)."""
    return cls(grad_threshold=config.gs_grad_threshold,
               percent_dense=config.gs_percent_dense, min_opacity=config.gs_min_opacity,
               refine_start=steps_of(config.gs_densify_from_frac, config),
               refine_stop=steps_of(config.gs_densify_until_frac, config),
               refine_every=steps_of(config.gs_densify_every_frac, config, 1),
               reset_every=steps_of(config.gs_opacity_reset_every_frac, config, 1))

  def initialize_state(self, n):
    """Zero statistics (density.DensityStats) for n slots."""
    return density.init_stats(n)

  def update_state(self, stats, grad2d, radius, height, width, iteration, on):
    """Adds one view's screen-space gradients to the statistics (jittable).

    Args:
      stats: density.DensityStats.
      grad2d: [N, 2] d loss / d means2d in pixels. radius: [N] screen radii of the view.
      height, width: image size.
      iteration: the step's 1-based iteration (traced int).
      on: bool (traced): whether the step was applied.

    Returns:
      density.DensityStats, unchanged from refine_stop on or when `on` is False.
    """
    return density.accumulate(stats, grad2d, radius, height, width,
                              on=on & (iteration < self.refine_stop))

  def step_post_backward(self, state, done, extent, key):
    """Densifies and resets the opacities between steps, as the schedule says.

    Args:
      state: a train state with params, opt_state, stats (this strategy's state) and
        dropped fields (gaussians.training.GaussianTrainState); donated when changed.
      done: the 1-based iteration just taken (Python int).
      extent: scene extent (float32 scalar array).
      key: the step's PRNG key; a densification draws its split samples from
        jax.random.split(key)[1] (the step itself draws from split(key)[0]).

    Returns:
      The train state.
    """
    if done >= self.refine_stop:
      return state
    if done > self.refine_start and done % self.refine_every == 0:
      state, _ = self.densify(state, extent, jax.random.split(key)[1],
                              jnp.asarray(done > self.reset_every))
    if done % self.reset_every == 0:
      state = self.reset_opacity(state)
    return state

  def densify(self, state, extent, key, prune_big):
    """density.densify_and_prune on a train state (donated): new slots get zero Adam
    moments, the statistics restart from zero, candidates without a free slot are added
    to state.dropped.

    Args:
      state: see step_post_backward. extent: scene extent. key: PRNG key of the split
        samples. prune_big: bool array: also prune by screen and world size.

    Returns:
      (state, info dict of density.densify_and_prune).
    """
    return _densify(self, state, extent, key, prune_big)

  def reset_opacity(self, state):
    """density.reset_opacity on a train state (donated), with the opacity's Adam moments
    zeroed for every slot."""
    return _reset_opacity(state)


@functools.partial(jax.jit, static_argnums=(0,), donate_argnums=(1,))
def _densify(strategy, state, extent, key, prune_big):
  g, reset, info = density.densify_and_prune(
      state.params, state.stats, key, strategy.grad_threshold, strategy.percent_dense,
      extent, strategy.min_opacity, prune_big)
  opt_state = density.reset_adam_moments(state.opt_state, reset)
  return state.replace(params=g, opt_state=opt_state,
                       stats=strategy.initialize_state(g.means.shape[0]),
                       dropped=state.dropped + info['dropped']), info


@functools.partial(jax.jit, donate_argnums=(0,))
def _reset_opacity(state):
  n = state.params.means.shape[0]
  opt_state = density.reset_adam_moments(state.opt_state, jnp.ones((n,), bool),
                                         fields=('opacity_logits',))
  return state.replace(params=density.reset_opacity(state.params), opt_state=opt_state)
