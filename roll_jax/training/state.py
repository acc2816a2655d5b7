"""What a seed carries from chunk to chunk (`TrainState`), a fresh one (`init_state`), and
what Python decides per chunk from the schedules (`ChunkPlan`, `plan_chunk`)."""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from configs.train import TrainConfig, vae_schedule
from roll_jax.agents import replay, sac, skewfit
from roll_jax.encoders import steps
from roll_jax.encoders.goal_encoding import goal_encoder


@struct.dataclass
class TrainState:
    """Everything one seed carries from chunk to chunk (checkpointed whole)."""

    sac: sac.SACState
    scene_vae: steps.ModelState
    lstm: Any  # steps.ModelState, or None without LSTM
    buffer: replay.ReplayBuffer
    # float32 [N, T+1]: Skew-Fit's log p(x) of every stored scene image under the current
    # scene-VAE (written with each episode, recomputed after each scene-VAE training), so that
    # skewed sampling never runs the VAE; unfilled slots are ignored (buffer.size).
    skew_log_p: jax.Array
    env_state: Any  # EnvState batched over envs [E]
    # [G = n_eval_goals] reset states the test envs start each episode from (through
    # env.reset_episode, like the training envs: a fresh reset, or t = 0 for reset-free tasks)
    test_start: Any
    # The training metrics of the last chunk (`train_metric_keys`; zeros before the first):
    # the next chunk reports them beside its evaluation of the policy they produced.
    last_train: dict
    key: jax.Array
    env_steps: jax.Array  # int32, per seed
    epoch: jax.Array  # int32
    # The key of the test envs' starts and goals (`collect.test_goals`): the same at every
    # evaluation of a seed, so that a learning curve compares one policy against the next on
    # the same goals (how far a goal lies from its start varies more than the policy does).
    eval_key: jax.Array


@struct.dataclass
class ChunkPlan:
    """Un-batched per-chunk switches computed in Python from the schedules."""

    learn: jax.Array  # bool: SAC updates on (learning_starts reached)
    act_random: jax.Array  # bool: uniform random actions (before learning_starts)
    vae_batches: jax.Array  # int32: scene-VAE batches after collection (0 = none)
    lstm_batches: jax.Array  # int32: LSTM batches after collection (0 = none)
    refresh_goals: jax.Array  # bool: recompute the buffer's cached goal latents (LSTM outputs)


def eval_only_plan() -> ChunkPlan:
    """A chunk that learns nothing: run after the last epoch for the final evaluation."""
    return ChunkPlan(learn=jnp.bool_(False), act_random=jnp.bool_(False),
                     vae_batches=jnp.int32(0), lstm_batches=jnp.int32(0),
                     refresh_goals=jnp.bool_(False))


def train_metric_keys(cfg: TrainConfig) -> tuple[str, ...]:
    """The chunk's training metrics kept in TrainState.last_train (and written to metrics.csv)."""
    keys = ("q_loss", "policy_loss", "alpha", "alpha_loss", "entropy", "q_mean", "reward",
            "vae_loss", "rollout_latent_dist")
    return keys + (("lstm_loss",) if goal_encoder(cfg).lstm else ())


def _lstm_batches(cfg: TrainConfig, epoch: int) -> int:
    if not goal_encoder(cfg).lstm:
        return 0
    start = epoch * cfg.epoch_env_steps
    every, batches = cfg.lstm.online_batches(start)
    # Train when the epoch crosses a multiple of `every` env steps.
    return batches if (start + cfg.epoch_env_steps) // every > start // every else 0


def plan_chunk(cfg: TrainConfig, epoch: int) -> ChunkPlan:
    """The schedules of Skew-Fit (scene-VAE) and ROLL (LSTM, appendix "Training schedules"),
    and of the goal-latent refresh: every `refresh_every_epochs` epochs when the LSTM trained
    since the last one, and whenever the scene-VAE trained where it encodes the goal frames."""
    start = epoch * cfg.epoch_env_steps
    end = start + cfg.epoch_env_steps
    # "epoch": the updates follow the collection, so the epoch that reaches learning_starts
    # learns; "step": they run during it, on the buffer as the epoch found it.
    learn = (end if cfg.sac_schedule == "epoch" else start) >= cfg.sac.learning_starts
    vae_batches = vae_schedule(cfg.vae_schedule, epoch)
    k = cfg.refresh_every_epochs
    lstm_trained = any(_lstm_batches(cfg, e) for e in range(max(0, epoch - k + 1), epoch + 1))
    refresh = ((epoch + 1) % k == 0 and lstm_trained) or (
        vae_batches > 0 and goal_encoder(cfg).object_cfg is None)
    return ChunkPlan(learn=jnp.bool_(learn), act_random=jnp.bool_(start < cfg.sac.learning_starts),
                     vae_batches=jnp.int32(vae_batches),
                     lstm_batches=jnp.int32(_lstm_batches(cfg, epoch)),
                     refresh_goals=jnp.bool_(refresh))


def init_state(key, cfg: TrainConfig, env, scene_vae: steps.ModelState, lstm) -> TrainState:
    """A fresh seed: new SAC nets, given (pretrained) scene-VAE and LSTM, empty buffer."""
    enc = goal_encoder(cfg)
    k_sac, k_env, k_run, k_eval = jax.random.split(key, 4)
    obs_dim, goal_dim, frame_dim = enc.latent_dims(env)
    sac_state = sac.init_sac(k_sac, obs_dim, goal_dim, env.action_size, cfg.sac)
    buffer = replay.init_buffer(cfg.sac.replay_capacity(cfg.horizon), cfg.horizon,
                                enc.image_shape, env.action_size, obs_dim, goal_dim, frame_dim)
    starts = jax.vmap(env.reset)(jax.random.split(k_env, cfg.n_envs + cfg.n_eval_goals))
    return TrainState(sac=sac_state, scene_vae=scene_vae, lstm=lstm, buffer=buffer,
                      skew_log_p=jnp.zeros(buffer.images.shape[:2], jnp.float32),
                      env_state=jax.tree.map(lambda x: x[:cfg.n_envs], starts),
                      test_start=jax.tree.map(lambda x: x[cfg.n_envs:], starts),
                      last_train={k: jnp.zeros((), jnp.float32) for k in train_metric_keys(cfg)},
                      key=k_run, env_steps=jnp.zeros((), jnp.int32),
                      epoch=jnp.zeros((), jnp.int32), eval_key=k_eval)


def lstm_params_of(state: TrainState):
    """The LSTM's parameters of a train state (None without an LSTM)."""
    return None if state.lstm is None else state.lstm.params


def skew_cdf_of(cfg: TrainConfig, enc, state: TrainState):
    """Skew-Fit's sampling CDF over the state's buffer (`skewfit.skew_cdf_at`); None where
    fresh goals do not come from the buffer."""
    if not enc.skewed_goals:
        return None
    return skewfit.skew_cdf_at(cfg, state.skew_log_p, state.buffer.size, state.epoch)


def store_episodes(state: TrainState, traj: replay.Trajectory, log_p) -> TrainState:
    """Add E episodes to the buffer and their log p(x) [E, T+1] to the same ring slots."""
    e = traj.actions.shape[0]
    slots = (state.buffer.insert_pos + jnp.arange(e, dtype=jnp.int32)) % state.buffer.capacity
    return state.replace(buffer=replay.add_trajectories(state.buffer, traj),
                         skew_log_p=state.skew_log_p.at[slots].set(log_p.astype(jnp.float32)))
