"""Schedules both backbones' optimisers share (a function of the step, jit-friendly)."""
import jax.numpy as jnp


def log_lerp(step, start, end, max_steps):
  """exp((1 - t) log(start) + t log(end)), t = clip(step / max_steps, 0, 1)."""
  t = jnp.clip(step / max(max_steps, 1), 0., 1.)
  return jnp.exp(jnp.log(start) * (1. - t) + jnp.log(end) * t)
