"""Trajectory replay buffer in pure JAX with RIG-style hindsight goal relabeling.

Whole episodes are stored at fixed shapes [n_traj, T(+1), ...] in a ring of trajectories, so
that (a) the LSTM can be trained on and re-run over whole trajectories, (b) the cached latents
of every stored image can be recomputed after the scene-VAE / LSTM change (`recompute`),
and (c) 'future' goals come from later steps of the same episode. Why not flashbax:
docs/training.md ("Replay buffer and HER").

Every function is pure and jittable (donate the buffer when jitting `add_trajectories` and
`recompute`: the image arrays are the big part of the train state).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp
from flax import struct

from roll_jax.agents.sac import Transition


@struct.dataclass
class Trajectory:
    """E whole episodes (leading axis E), as collected by E envs; also what the buffer holds."""
    images: jax.Array  # uint8 [E, T+1, H, W, 3] scene images
    object_images: jax.Array  # uint8 [E, T+1, H, W, 3] segmented object images (rgb * mask)
    actions: jax.Array  # float32 [E, T, A]
    obs_latents: jax.Array  # float32 [E, T+1, ds] scene-VAE latents (cache)
    # float32 [E, T+1, df] per-frame latents the LSTM runs on (object-VAE means; cache: they
    # change only with the encoder that made them, never for the frozen object-VAE)
    frame_latents: jax.Array
    goal_latents: jax.Array  # float32 [E, T+1, dg] achieved object latents, LSTM output (cache)
    rollout_goals: jax.Array  # float32 [E, dg] the goal the episode was collected with


@struct.dataclass
class ReplayBuffer:
    images: jax.Array  # uint8 [N, T+1, H, W, 3]
    object_images: jax.Array  # uint8 [N, T+1, H, W, 3]
    actions: jax.Array  # float32 [N, T, A]
    obs_latents: jax.Array  # float32 [N, T+1, ds]
    frame_latents: jax.Array  # float32 [N, T+1, df]
    goal_latents: jax.Array  # float32 [N, T+1, dg]
    rollout_goals: jax.Array  # float32 [N, dg]
    insert_pos: jax.Array  # int32: next trajectory slot to write
    size: jax.Array  # int32: number of stored trajectories (saturates at N)

    @property
    def capacity(self) -> int:
        return self.actions.shape[0]

    @property
    def horizon(self) -> int:
        return self.actions.shape[1]


@struct.dataclass
class SampleIndices:
    """Where a relabeled batch comes from (all int32 [B])."""
    traj: jax.Array  # trajectory slot
    t: jax.Array  # transition (t -> t+1), 0 <= t < T
    future_t: jax.Array  # 'future' goal step, t < future_t <= T (used by the future rows only)


_TRAJ_FIELDS = ("images", "object_images", "actions", "obs_latents", "frame_latents",
                "goal_latents", "rollout_goals")


def init_buffer(capacity_traj: int, horizon: int, image_shape: Sequence[int], action_dim: int,
                obs_dim: int, goal_dim: int, frame_dim: int | None = None) -> ReplayBuffer:
    """Empty buffer of `capacity_traj` episodes of `horizon` steps (SACConfig.replay_capacity);
    frame_dim defaults to goal_dim (the LSTM reconstructs its input)."""
    if capacity_traj <= 0 or horizon <= 0:
        raise ValueError(f"capacity_traj and horizon must be positive, got {capacity_traj}, {horizon}")
    n, t1 = capacity_traj, horizon + 1
    return ReplayBuffer(
        images=jnp.zeros((n, t1, *image_shape), jnp.uint8),
        object_images=jnp.zeros((n, t1, *image_shape), jnp.uint8),
        actions=jnp.zeros((n, horizon, action_dim), jnp.float32),
        obs_latents=jnp.zeros((n, t1, obs_dim), jnp.float32),
        frame_latents=jnp.zeros((n, t1, goal_dim if frame_dim is None else frame_dim), jnp.float32),
        goal_latents=jnp.zeros((n, t1, goal_dim), jnp.float32),
        rollout_goals=jnp.zeros((n, goal_dim), jnp.float32),
        insert_pos=jnp.zeros((), jnp.int32),
        size=jnp.zeros((), jnp.int32),
    )


def add_trajectories(buffer: ReplayBuffer, traj: Trajectory) -> ReplayBuffer:
    """Write E episodes at insert_pos, insert_pos+1, ... (mod capacity), oldest overwritten first."""
    e = traj.actions.shape[0]
    if e > buffer.capacity:
        raise ValueError(f"cannot add {e} trajectories to a buffer of capacity {buffer.capacity}")
    for name in _TRAJ_FIELDS:
        want, got = getattr(buffer, name).shape[1:], getattr(traj, name).shape[1:]
        if want != got:
            raise ValueError(f"Trajectory.{name} has per-episode shape {got}, buffer expects {want}")
    idx = (buffer.insert_pos + jnp.arange(e, dtype=jnp.int32)) % buffer.capacity
    new = {name: getattr(buffer, name).at[idx].set(getattr(traj, name).astype(getattr(buffer, name).dtype))
           for name in _TRAJ_FIELDS}
    return buffer.replace(
        **new,
        insert_pos=(buffer.insert_pos + e) % buffer.capacity,
        size=jnp.minimum(buffer.size + e, buffer.capacity).astype(jnp.int32),
    )


def map_filled(fn: Callable, source, old: jax.Array, size, chunk: int) -> jax.Array:
    """new[i] = fn(source[i]) for the filled episode slots i < size, old[i] for the others:
    `source` a pytree of per-episode arrays [N, ...], `old` [N, ...]. Runs over blocks of
    about `chunk` episodes (fn vmapped inside a lax.map, so peak memory is one block of
    activations), and skips the blocks wholly past `size` (a buffer fills over the run, and
    a refresh of the empty part would cost as much as of the filled one)."""
    n = old.shape[0]
    c = max(d for d in range(1, min(chunk, n) + 1) if n % d == 0)  # blocks tile the slots
    blocks = lambda x: x.reshape((n // c, c) + x.shape[1:])  # noqa: E731

    def block(args):
        i, src, prev = args
        return jax.lax.cond(i * c < size, lambda: jax.vmap(fn)(src).astype(prev.dtype),
                            lambda: prev)

    new = jax.lax.map(block, (jnp.arange(n // c), jax.tree.map(blocks, source), blocks(old)))
    new = new.reshape(old.shape)
    filled = (jnp.arange(n) < size).reshape((-1,) + (1,) * (old.ndim - 1))
    return jnp.where(filled, new, old)


def recompute(buffer: ReplayBuffer, field: str, fn: Callable, source: jax.Array,
              chunk: int) -> ReplayBuffer:
    """buffer.<field>[i] = fn(source[i]) for every filled episode slot i (`source`: one of the
    buffer's per-episode arrays, e.g. buffer.images), about `chunk` episodes at a time
    (`map_filled`). Unfilled slots keep their values."""
    return buffer.replace(**{field: map_filled(fn, source, getattr(buffer, field), buffer.size,
                                               chunk)})


def goal_counts(batch_size: int, fracs: Sequence[float]) -> tuple[int, int, int]:
    """Rows of a batch that keep the rollout goal / take a prior goal / take a future goal."""
    n_rollout = round(fracs[0] * batch_size)
    n_prior = min(round(fracs[1] * batch_size), batch_size - n_rollout)
    return n_rollout, n_prior, batch_size - n_rollout - n_prior


def draw_indices(buffer: ReplayBuffer, key, batch_size: int) -> SampleIndices:
    """Uniform transitions among stored ones, and a uniform future step in (t, T] for each."""
    k_traj, k_t, k_future = jax.random.split(key, 3)
    horizon = buffer.horizon
    # Every stored episode has T transitions, so uniform (episode, t) = uniform transition.
    traj = jax.random.randint(k_traj, (batch_size,), 0, jnp.maximum(buffer.size, 1))
    t = jax.random.randint(k_t, (batch_size,), 0, horizon)
    future_t = jax.random.randint(k_future, (batch_size,), t + 1, horizon + 1)
    return SampleIndices(traj=traj.astype(jnp.int32), t=t.astype(jnp.int32),
                         future_t=future_t.astype(jnp.int32))


def relabel(buffer: ReplayBuffer, idx: SampleIndices, prior_goals, fracs: Sequence[float],
            reward_norm: str = "squared") -> Transition:
    """Build the relabeled batch at `idx` (deterministic given the draws).

    Rows [0, n_rollout) keep the episode's rollout goal, the next n_prior rows take
    `prior_goals` ([B, dg], sampled by the caller from the object-VAE prior and encoded by the
    LSTM; only those rows are read), the rest the achieved goal at `future_t` of the same episode.
    The draws are i.i.d., so assigning sources by row position is as good as at random.
    Reward r = -||goal_latents[t+1] - g||^2 (reward_norm "squared") or -||.|| ("l2"), unscaled
    (SAC applies reward_scale). done = 0: the
    episodes end by time limit, so the critic bootstraps through the last step (as rlkit).
    """
    b = idx.t.shape[0]
    n_rollout, n_prior, _ = goal_counts(b, fracs)
    if prior_goals.shape[0] != b:
        raise ValueError(f"prior_goals must have {b} rows (one per sample), got {prior_goals.shape}")
    row = jnp.arange(b)
    rollout_g = buffer.rollout_goals[idx.traj]
    future_g = buffer.goal_latents[idx.traj, idx.future_t]
    goal = jnp.where((row < n_rollout)[:, None], rollout_g,
                     jnp.where((row < n_rollout + n_prior)[:, None], prior_goals.astype(jnp.float32),
                               future_g))
    achieved_next = buffer.goal_latents[idx.traj, idx.t + 1]
    sq = jnp.sum(jnp.square(achieved_next - goal), axis=-1)
    if reward_norm == "squared":
        reward = -sq
    elif reward_norm == "l2":
        reward = -jnp.sqrt(sq)
    else:
        raise ValueError(f"reward_norm must be 'squared' or 'l2', got {reward_norm!r}")
    return Transition(
        obs=buffer.obs_latents[idx.traj, idx.t],
        goal=goal,
        action=buffer.actions[idx.traj, idx.t],
        reward=reward,
        next_obs=buffer.obs_latents[idx.traj, idx.t + 1],
        done=jnp.zeros((b,), jnp.float32),
    )


def sample_transitions(buffer: ReplayBuffer, key, batch_size: int, prior_goals,
                       fracs: Sequence[float], reward_norm: str = "squared") -> Transition:
    """HER batch: `draw_indices` then `relabel`. fracs = (rollout, prior, future), e.g.
    SACConfig.goal_fracs. Needs a non-empty buffer (the loop samples after learning_starts)."""
    return relabel(buffer, draw_indices(buffer, key, batch_size), prior_goals, fracs, reward_norm)


def sample_trajectories(buffer: ReplayBuffer, key, n: int) -> Trajectory:
    """n stored episodes drawn uniformly with replacement (online LSTM training)."""
    traj = jax.random.randint(key, (n,), 0, jnp.maximum(buffer.size, 1))
    return Trajectory(**{name: getattr(buffer, name)[traj] for name in _TRAJ_FIELDS})
