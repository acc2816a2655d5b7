"""One episode of all envs inside the chunk: reset, act, step, observe; then the episode's
trajectories as the buffer stores them.

The E training envs chase fresh goals (`her.fresh_goals`) with the stochastic policy (uniform
random actions before learning starts). With `evaluate`, G = n_eval_goals test envs run in
the same env batch: they start from resets, chase test goals from the task's goal space with
the deterministic policy the chunk started from, and are neither stored nor learned from;
their starts and goals come from state.eval_key and the episode's index in its chunk, so
every evaluation of a seed sees the same ones (reset-free tasks restart them from their fixed
`test_start` states). Sharing the batch costs G more envs per step but no second compiled
copy of MJX's step (the largest compile), and one reset serves both; without the test envs
the training envs' keys, and so their episodes, are the same. Each frame is encoded once
(the policy's observation is the stored scene latent). The goal encoder decides what a step
observes and keeps (`GoalEncoder.observe` / `encode_episodes`, the oracle's true positions alike).

With cfg.sac_schedule "step" the plan's `learn` switches on n_envs x updates_per_step SAC
updates after every env step, on the buffer as it was at the episode's start.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from configs.train import TrainConfig
from roll_jax.agents import her, replay, sac, skewfit
from roll_jax.encoders.goal_encoding import Frozen
from roll_jax.training.state import ChunkPlan, TrainState, lstm_params_of, skew_cdf_of


@dataclasses.dataclass(frozen=True)
class Collector:
    """What a chunk program collects with (static): its config, env and goal encoder, and
    whether the test envs run beside the training envs."""

    cfg: TrainConfig
    env: Any
    enc: Any  # GoalEncoder or StateOracle
    evaluate: bool

    @property
    def interleaved(self) -> bool:
        """SAC updates inside the episode (cfg.sac_schedule "step")."""
        return self.cfg.sac_schedule == "step"


@struct.dataclass
class ChunkInputs:
    """What every episode of a chunk shares: the frozen encoders, the chunk's plan, its bank
    of prior goals (`her.goal_prior`; None for Skew-Fit) and the policy it started from (the
    test envs act with it)."""

    frozen: Frozen
    plan: ChunkPlan
    bank: Any
    eval_policy: Any


@struct.dataclass
class TestGoals:
    """The test envs' goals: env states [G], their images [G or 1, 48, 48, 3] (the oracle
    renders only the first, for the video), their latents [G, g]."""

    states: Any
    rgb: jax.Array
    latents: jax.Array


@struct.dataclass
class Rollout:
    """An episode's steps: final env states [E(+G)], the SAC state after them, per step the
    observations [T+1, E(+G), ds], what the encoder kept (`observe`), the test video
    [T+1, 48, 48, 3] (None without test envs), actions [T, E(+G), da] and the mean metrics of
    the updates inside (None without)."""

    env_state: Any
    sac: sac.SACState
    obs: jax.Array
    records: Any
    video: Any
    actions: jax.Array
    sac_metrics: Any


@struct.dataclass
class Episode:
    """What `collect_episode` returns: the training envs' states after it, the SAC state (with
    the updates inside the episode), the stored trajectories [E, ...] and their Skew-Fit log
    p(x) [E, T+1], the metrics to average over the chunk, and the test envs' results."""

    env_state: Any
    sac: sac.SACState
    traj: replay.Trajectory
    log_p: jax.Array
    metrics: dict
    test: Any  # dict or None


def needs_log_p(cfg: TrainConfig, enc) -> bool:
    """Whether Skew-Fit's log p(x) of stored frames is used: skewed goals, or online scene-VAE
    training on skewed replay images (static; the chunk skips the estimator otherwise)."""
    return enc.from_pixels and (enc.skewed_goals or cfg.vae_schedule != "none")


def _concat(a, b):
    return jax.tree.map(lambda x, y: jnp.concatenate([x, y]), a, b)


def start_states(c: Collector, state: TrainState, key, index):
    """(env states [E(+G)] at the episode's start: `reset_episode` of the training envs, then
    of the test envs; the key of the test goals, None without them)."""
    reset_keys = jax.random.split(key, c.cfg.n_envs)
    if not c.evaluate:
        return jax.vmap(c.env.reset_episode)(state.env_state, reset_keys), None
    k_test_reset, k_test = jax.random.split(jax.random.fold_in(state.eval_key, index))
    keys = jnp.concatenate([reset_keys, jax.random.split(k_test_reset, c.cfg.n_eval_goals)])
    return jax.vmap(c.env.reset_episode)(_concat(state.env_state, state.test_start), keys), k_test


def test_goals(c: Collector, frozen: Frozen, state: TrainState, key) -> TestGoals:
    """`n_eval_goals` test goals from the task's goal space, their images rendered at 48x48
    and encoded like any goal image."""
    states = jax.vmap(c.env.sample_goal)(jax.random.split(key, c.cfg.n_eval_goals))
    rgb = c.enc.test_goal_images(c.env, states)
    latents = c.enc.encode_goals(c.env, frozen, state.scene_vae.params, lstm_params_of(state),
                                 rgb, states)
    return TestGoals(states=states, rgb=rgb, latents=latents)


def rollout(c: Collector, inputs: ChunkInputs, state: TrainState, start, goals,
            source: her.FreshGoals, key) -> Rollout:
    """`horizon` steps of the envs from `start` towards `goals` [E(+G), g]."""
    cfg, env, enc = c.cfg, c.env, c.enc
    n_train, scene_params = cfg.n_envs, state.scene_vae.params
    video_env = n_train if c.evaluate else None
    is_test = (jnp.arange(goals.shape[0]) >= n_train)[:, None]
    zero_sac = (her.zero_sac_metrics(cfg, enc, state.sac, state.buffer, source)
                if c.interleaved else None)
    n_per_step = cfg.n_envs * cfg.sac.updates_per_step

    def step(carry, k):
        es, z, sac_s = carry
        k_pol, k_rand, k_upd = jax.random.split(k, 3)
        a_pol = sac.select_action(sac_s.policy_params, z, goals, k_pol, cfg=cfg.sac)
        a_rand = jax.random.uniform(k_rand, a_pol.shape, minval=-1.0, maxval=1.0)
        a = jnp.where(inputs.plan.act_random, a_rand, a_pol)
        if c.evaluate:
            a_det = sac.select_action(inputs.eval_policy, z, goals, None, deterministic=True,
                                      cfg=cfg.sac)
            a = jnp.where(is_test, a_det, a)
        es = jax.vmap(env.step)(es, a)
        z, rec, frame = enc.observe(env, scene_params, es, video_env)
        sac_m = None
        if c.interleaved:
            sac_s, sac_m = jax.lax.cond(
                inputs.plan.learn, lambda s_: her.sac_steps(cfg, enc, s_, state.buffer, source,
                                                            k_upd, n_per_step),
                lambda s_: (s_, zero_sac), sac_s)
        return (es, z, sac_s), (z, rec, frame, a, sac_m)

    z0, rec0, frame0 = enc.observe(env, scene_params, start, video_env)
    (es, _, sac_state), (zs, recs, frames, actions, sac_ms) = jax.lax.scan(
        step, (start, z0, state.sac), jax.random.split(key, cfg.horizon))
    first = lambda x0, xs: jnp.concatenate([x0[None], xs], 0)  # noqa: E731
    return Rollout(env_state=es, sac=sac_state, obs=first(z0, zs),
                   records=jax.tree.map(first, rec0, recs),
                   video=None if frame0 is None else first(frame0, frames), actions=actions,
                   sac_metrics=None if sac_ms is None else jax.tree.map(jnp.mean, sac_ms))


def trajectories(c: Collector, frozen: Frozen, state: TrainState, run: Rollout, goals, key):
    """(the training envs' trajectories [E, ...] as the buffer stores them, their log p(x)
    [E, T+1] (zeros when unused, `needs_log_p`)) of a rollout towards `goals` [E, g]."""
    n_train = c.cfg.n_envs
    episode_major = lambda x: x[:, :n_train].swapaxes(0, 1)  # noqa: E731  [E, T+1, ...]
    images, goal_imgs, frame_lat, achieved = c.enc.encode_episodes(
        frozen, state.scene_vae.params, lstm_params_of(state),
        jax.tree.map(episode_major, run.records))
    traj = replay.Trajectory(
        images=images, object_images=goal_imgs, actions=episode_major(run.actions),
        obs_latents=episode_major(run.obs), frame_latents=frame_lat, goal_latents=achieved,
        rollout_goals=goals)
    if needs_log_p(c.cfg, c.enc):
        log_p = skewfit.frame_log_p(c.cfg, state.scene_vae.params, images, key)
    else:
        log_p = jnp.zeros(images.shape[:2], jnp.float32)
    return traj, log_p


def collect_episode(c: Collector, inputs: ChunkInputs, state: TrainState, key,
                    index) -> Episode:
    """One episode of the E training envs (and, with c.evaluate, of the G test envs beside
    them); `index`: the episode's place in its chunk."""
    k_reset, k_goal, k_act, k_lp = jax.random.split(key, 4)
    start, k_test = start_states(c, state, k_reset, index)
    # The buffer is fixed for the whole episode: Skew-Fit's CDF is built once.
    source = her.FreshGoals(bank=inputs.bank, cdf=skew_cdf_of(c.cfg, c.enc, state))
    goals = her.fresh_goals(c.enc, state.buffer, source, k_goal, c.cfg.n_envs)
    test = None
    if c.evaluate:
        test = test_goals(c, inputs.frozen, state, k_test)
        goals = jnp.concatenate([goals, test.latents])
    run = rollout(c, inputs, state, start, goals, source, k_act)
    goals = goals[:c.cfg.n_envs]
    traj, log_p = trajectories(c, inputs.frozen, state, run, goals, k_lp)
    final_dist = jnp.sum(jnp.square(traj.goal_latents[:, -1] - goals), -1)
    metrics = {"rollout_latent_dist": final_dist.mean()}
    if c.interleaved:
        metrics["sac"] = run.sac_metrics
    results = None
    if c.evaluate:
        begin, final = (jax.tree.map(lambda x: x[c.cfg.n_envs:], es)
                        for es in (start, run.env_state))
        results = {"distances": jax.vmap(c.env.goal_distance)(final, test.states),
                   "start_distances": jax.vmap(c.env.goal_distance)(begin, test.states),
                   "video": run.video, "goal_image": test.rgb[0]}
    return Episode(env_state=jax.tree.map(lambda x: x[:c.cfg.n_envs], run.env_state),
                   sac=run.sac, traj=traj, log_p=log_p, metrics=metrics, test=results)
