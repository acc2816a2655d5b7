"""Brax's trainers on the Playground-style envs, without MuJoCo Playground installed.

`brax.training.agents.{sac,ppo}.train(environment=env, wrap_env_fn=wrap_for_brax_training,
...)` trains on an `envs_mjx.standard.RollEnv`. The wrapper stack is Brax's own `VmapWrapper`
and `EpisodeWrapper` (time limit, `info["truncation"]`, episode metrics) under a full reset on
`done`: Brax's `AutoResetWrapper` would put every env back into its *first* state, i.e. the same
start and the same goal for the whole run, and it reads `state.pipeline_state`, which a
Playground-style State calls `data`. Playground's `wrap_for_brax_training(full_reset=True)`
does the same as this module; it is written here because that package pulls warp-lang
(~400 MB) for one wrapper.

Requires `pip install -e ".[brax]"`. docs/environments.md has the measured learning curve.
"""

from __future__ import annotations

from typing import Callable

import jax
import jax.numpy as jnp
from brax.envs.base import Wrapper
from brax.envs.wrappers.training import EpisodeWrapper, VmapWrapper



def _restore_device_put_replicated() -> None:
    """brax 0.14.2 (the newest release) replicates its training state with
    `jax.device_put_replicated`, which jax 0.10 removed. Stand in the replication its pmapped
    functions take (a leading device axis); a no-op on a jax that still has it."""
    try:
        jax.device_put_replicated  # noqa: B018
    except AttributeError:
        jax.device_put_replicated = lambda x, devices: jax.tree.map(
            lambda a: jnp.stack([jnp.asarray(a)] * len(devices)), x)


_restore_device_put_replicated()

# info keys the Brax wrappers own; every other info key belongs to the env and is reset
_WRAPPER_INFO = ("steps", "truncation", "episode_done", "episode_metrics", "reset_rng")


class FullResetWrapper(Wrapper):
    """Resets a done env with a fresh key (a new start and a new goal), batched envs only."""

    def reset(self, rng: jax.Array):
        state = self.env.reset(rng)
        state.info["reset_rng"] = rng
        return state

    def step(self, state, action: jax.Array):
        steps = jnp.where(state.done, jnp.zeros_like(state.info["steps"]), state.info["steps"])
        state.info.update(steps=steps)
        state = self.env.step(state.replace(done=jnp.zeros_like(state.done)), action)
        keys = jax.vmap(jax.random.split)(state.info["reset_rng"])
        fresh = self.env.reset(keys[:, 1])
        done = state.done

        def where_done(new, old):
            mask = jnp.reshape(done, done.shape + (1,) * (old.ndim - done.ndim))
            return jnp.where(mask > 0, new, old)

        info = dict(state.info)
        for key, value in fresh.info.items():
            if key not in _WRAPPER_INFO:
                info[key] = jax.tree.map(where_done, value, state.info[key])
        info["reset_rng"] = keys[:, 0]
        return state.replace(data=jax.tree.map(where_done, fresh.data, state.data),
                             obs=jax.tree.map(where_done, fresh.obs, state.obs), info=info)


def wrap_for_brax_training(env, episode_length: int = 50, action_repeat: int = 1,
                           randomization_fn: Callable | None = None):
    """Brax's `wrap_env_fn`: vmap, a time limit of `episode_length`, full resets on done.
    The env should be built with `done_at_horizon=False` (the EpisodeWrapper ends episodes)."""
    if randomization_fn is not None:
        raise ValueError("domain randomization is not supported by the ROLL scenes "
                         f"(got randomization_fn={randomization_fn!r})")
    if getattr(env, "config", None) is not None and env.config.done_at_horizon:
        raise ValueError(f"{env!r} ends its own episodes; build it with done_at_horizon=False "
                         "so that Brax's EpisodeWrapper truncates them (info['truncation'])")
    if getattr(env, "episode_length", episode_length) != episode_length:
        raise ValueError(f"Brax's episode_length={episode_length} differs from the env's "
                         f"episode_length={env.episode_length} (which its final_goal_distance "
                         "metric reads); load the env with the same episode_length")
    return FullResetWrapper(VmapWrapper(EpisodeWrapper(env, episode_length, action_repeat)))
