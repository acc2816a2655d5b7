"""Fresh goals and the SAC updates on HER batches that relabel with them.

Fresh goals are each episode's exploration goal and the fresh-goal share of HER's relabelling
(`replay.relabel`). ROLL (Algorithm 1) draws them from the chunk's bank of prior goals
(`GoalEncoder.goal_bank`: N(0, I) through the LSTM, or N(mean, std) of the stored frame
latents, `frame_stats`, with cfg.prior_goals "buffer"); the state oracle from its bank of
goal-space object states; Skew-Fit (rlkit's `custom_goal_sampler`) from the buffer's
achieved-goal latents drawn with probability p(x)^alpha (`FreshGoals.cdf`, skewfit.py; the
cached latents are refreshed with the VAE), the scene-VAE prior while the buffer is empty.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from configs.train import TrainConfig
from roll_jax.agents import replay, sac, skewfit


@struct.dataclass
class FreshGoals:
    """Where fresh goals come from: a bank of goals [n, g] (ROLL, the oracle), or Skew-Fit's
    sampling CDF over the buffer's frames (`skewfit.skew_cdf`)."""

    bank: Any = None
    cdf: Any = None


def frame_stats(buffer: replay.ReplayBuffer):
    """(mean, std) [d] of the stored frame latents per dimension: the data's latent
    distribution (rlkit's dist_mu / dist_std); (0, 1) while the buffer is empty."""
    lat = buffer.frame_latents
    w = (jnp.arange(lat.shape[0]) < buffer.size).astype(jnp.float32)[:, None, None]
    count = jnp.maximum(jnp.sum(w) * lat.shape[1], 1.0)
    mean = jnp.sum(lat * w, (0, 1)) / count
    var = jnp.sum(jnp.square(lat - mean) * w, (0, 1)) / count
    empty = buffer.size == 0
    return jnp.where(empty, 0.0, mean), jnp.where(empty, 1.0, jnp.sqrt(var))


def goal_prior(cfg: TrainConfig, enc, env, buffer: replay.ReplayBuffer, key, lstm_params=None):
    """A chunk's bank of prior goals (`enc.goal_bank`; None for Skew-Fit), from N(mean, std)
    of the buffer's frame latents for cfg.prior_goals "buffer"."""
    stats = frame_stats(buffer) if cfg.prior_goals == "buffer" else None
    return enc.goal_bank(env, key, lstm_params, stats)


def fresh_goals(enc, buffer: replay.ReplayBuffer, source: FreshGoals, key, n: int):
    """n fresh goals: uniformly from `source.bank`, or for Skew-Fit from the buffer's
    achieved-goal latents by `source.cdf` (the scene-VAE prior N(0, I) while it is empty)."""
    if not enc.skewed_goals:
        return source.bank[jax.random.randint(key, (n,), 0, source.bank.shape[0])]
    k_prior, k_buf = jax.random.split(key)
    flat = skewfit.sample_frames(k_buf, source.cdf, n)
    t1 = buffer.goal_latents.shape[1]
    replay_goals = buffer.goal_latents[flat // t1, flat % t1]
    # (Skew-Fit has no LSTM: its prior goals are the scene-VAE prior samples themselves.)
    return jnp.where(buffer.size > 0, replay_goals, enc.prior_goals(k_prior, None, n))


def sac_steps(cfg: TrainConfig, enc, sac_state: sac.SACState, buffer: replay.ReplayBuffer,
              source: FreshGoals, key, n_updates: int):
    """`n_updates` SAC updates on HER batches from `buffer` -> (SAC state, mean metrics); the
    fresh-goal share is drawn per batch by `fresh_goals`."""

    def body(s, k):
        k_goal, k_batch, k_upd = jax.random.split(k, 3)
        fresh = fresh_goals(enc, buffer, source, k_goal, cfg.sac.batch_size)
        batch = replay.sample_transitions(buffer, k_batch, cfg.sac.batch_size, fresh,
                                          cfg.sac.goal_fracs, cfg.reward_norm)
        s, m = sac.sac_update(s, k_upd, batch, cfg.sac)
        m["reward"] = batch.reward.mean()
        return s, m

    new, metrics = jax.lax.scan(body, sac_state, jax.random.split(key, n_updates))
    return new, jax.tree.map(jnp.mean, metrics)


def zero_sac_metrics(cfg: TrainConfig, enc, sac_state: sac.SACState,
                     buffer: replay.ReplayBuffer, source: FreshGoals):
    """`sac_steps`' metrics where nothing learns: zeros, "finite" true (no update, nothing
    non-finite)."""
    m = jax.tree.map(jnp.zeros_like, jax.eval_shape(
        lambda s: sac_steps(cfg, enc, s, buffer, source, jax.random.PRNGKey(0), 1)[1],
        sac_state))
    m["finite"] = jnp.ones_like(m["finite"])
    return m
