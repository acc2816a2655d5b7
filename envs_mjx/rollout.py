"""Open-loop rollouts as one `lax.scan` (scripts, random-policy data, tests, benchmarks)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from envs_mjx.env import Env, EnvState


@struct.dataclass
class Trajectory:
    """Per-step records after each action: [T, ...] (with a leading batch axis if vmapped)."""

    hand: jax.Array  # float32[T, 3]
    mocap: jax.Array  # float32[T, 3]
    obj: jax.Array | None = None  # float32[T, k]; None for an empty scene
    rgb: jax.Array | None = None  # uint8[T, H, W, 3] when rendered
    labels: jax.Array | None = None  # int32[T, H, W] when rendered


def rollout(env: Env, state: EnvState, actions, render: bool = False, width: int = 48,
            height: int = 48) -> tuple[EnvState, Trajectory]:
    """Apply actions[T, A] from `state`; pure, jit/vmap it at the call site."""

    def body(s, a):
        s = env.step(s, a)
        rec = {"hand": env.hand_pos(s), "mocap": s.data.mocap_pos[0]}
        if env.with_object:
            rec["obj"] = env.object_state(s)
        if render:
            rec["rgb"], rec["labels"] = env.render_both(s, width, height)
        return s, rec

    state, rec = jax.lax.scan(body, state, jnp.asarray(actions, jnp.float32))
    return state, Trajectory(**rec)


def random_actions(key, n_steps: int, action_size: int):
    """Uniform actions in [-1, 1]: the random policy of the paper's data collection."""
    return jax.random.uniform(key, (n_steps, action_size), minval=-1.0, maxval=1.0)
