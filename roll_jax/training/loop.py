"""One compiled training chunk (an rlkit "epoch"): collect, store, learn; Algorithm 1.

A chunk, for one seed (the caller runs it over the seed axis, `sharding.over_seeds`):
  1. `episodes_per_epoch` x `horizon` steps of all envs in a `lax.scan`: scene-VAE encodes the
     rendered image, the policy acts (uniformly at random before learning starts), MJX steps,
     the renderer draws; exploration goals: ROLL from the object-VAE prior through the LSTM,
     Skew-Fit from the skewed replay distribution (`fresh_goals`). The evaluation runs in the
     same batch: `n_eval_goals` extra envs chase test goals with the deterministic policy
     (the policy does not change during collection, so this evaluates the policy the chunk
     starts from; one compiled env step serves both, see `collect_episode`);
  2. per finished episode: `segment` the frames, encode them (object-VAE, LSTM), store the
     whole trajectories with cached latents and Skew-Fit log p(x) in the replay buffer;
  3. 2 SAC updates per collected transition on HER-relabeled batches (rlkit's order: collect
     the epoch's steps, then train);
  4. scheduled scene-VAE training on Skew-Fit-skewed replay images (then the buffer's scene
     latents are recomputed) and online LSTM training (auto-encoder + matching loss) on the
     buffer's cached frame latents; the cached goal latents are recomputed from those on the
     refresh schedule (the frozen object-VAE's latents never change, so no image is
     re-encoded for them).
How much of 3 and 4 happens is decided per chunk in Python (schedules are functions of the
env step) and passed in as un-batched scalars, so the chunk compiles once. `--algo oracle`
runs the same chunk with true positions for latents (`oracle_obs`, `oracle_goal`).
"""

from __future__ import annotations

import collections
import functools
import os
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from configs.train import TrainConfig, vae_schedule
from roll_jax.agents import replay, sac, skewfit
from roll_jax.encoders import models, steps
from roll_jax.encoders.goal_encoding import Frozen, GoalEncoder, goal_encoder
from roll_jax.training import compiler, online
from roll_jax.training.sharding import over_seeds

TRACE_COUNTS: collections.Counter = collections.Counter()


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
    # The key of the test envs' starts and goals (`test_goals`): the same at every
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


# ----------------------------------------------------------------------------- init

def init_state(key, cfg: TrainConfig, env, scene_vae: steps.ModelState, lstm) -> TrainState:
    """A fresh seed: new SAC nets, given (pretrained) scene-VAE and LSTM, empty buffer."""
    enc = goal_encoder(cfg)
    k_sac, k_env, k_run, k_eval = jax.random.split(key, 4)
    obs_dim, goal_dim, frame_dim = latent_dims(enc, env)
    sac_state = sac.init_sac(k_sac, obs_dim, goal_dim, env.action_size, cfg.sac)
    # The oracle stores no images (a 1x1 placeholder keeps one buffer layout).
    image_shape = (1, 1, 3) if enc.oracle else cfg.scene.image_shape
    buffer = replay.init_buffer(cfg.sac.replay_capacity(cfg.horizon), cfg.horizon, image_shape,
                                env.action_size, obs_dim, goal_dim, frame_dim)
    starts = jax.vmap(env.reset)(jax.random.split(k_env, cfg.n_envs + cfg.n_eval_goals))
    return TrainState(sac=sac_state, scene_vae=scene_vae, lstm=lstm, buffer=buffer,
                      skew_log_p=jnp.zeros(buffer.images.shape[:2], jnp.float32),
                      env_state=jax.tree.map(lambda x: x[:cfg.n_envs], starts),
                      test_start=jax.tree.map(lambda x: x[cfg.n_envs:], starts),
                      last_train={k: jnp.zeros((), jnp.float32) for k in train_metric_keys(cfg)},
                      key=k_run, env_steps=jnp.zeros((), jnp.int32),
                      epoch=jnp.zeros((), jnp.int32), eval_key=k_eval)


# ----------------------------------------------------------------------------- pieces

ORACLE_SCALE = 0.1  # metres per oracle latent unit: positions enter the networks / 0.1 m


@functools.lru_cache(maxsize=None)
def oracle_centre(env) -> np.ndarray:
    """The mean (hand position, object state) of 256 goal states (a fixed draw): the origin
    of the oracle's coordinates, so that the networks see centred inputs."""
    def mean_position(key):
        states = jax.vmap(env.sample_goal)(jax.random.split(key, 256))
        pos = jnp.concatenate([jax.vmap(env.hand_pos)(states),
                               jax.vmap(env.object_state)(states)], -1)
        return jnp.mean(pos, 0)

    # One compiled program, run now even when called while a chunk is traced (op by op, the
    # 256 MJX placements dispatch hundreds of small programs: ~11 s on 2 cores).
    key = np.zeros(2, np.uint32)  # jax.random.PRNGKey(0), as numpy: no tracer when traced
    return np.asarray(jax.jit(mean_position).lower(key).compile()(key))


def oracle_obs(env, state):
    """The oracle's observation of one env state: hand position and object state, centred
    (`oracle_centre`), / 0.1 m."""
    pos = jnp.concatenate([env.hand_pos(state), env.object_state(state)])
    return (pos - oracle_centre(env)) / ORACLE_SCALE


def oracle_goal(env, state):
    """The oracle's goal / achieved goal of one env state: its object part of `oracle_obs`."""
    return (env.object_state(state) - oracle_centre(env)[3:]) / ORACLE_SCALE


def lstm_params_of(state: TrainState):
    """The LSTM's parameters of a train state (None without an LSTM)."""
    return None if state.lstm is None else state.lstm.params


def latent_dims(enc: GoalEncoder, env) -> tuple[int, int, int]:
    """(observation, goal, per-frame) latent sizes."""
    if enc.oracle:
        return 3 + env.object_size, env.object_size, env.object_size
    return enc.scene_cfg.latent_dim, enc.goal_dim, enc.frame_dim


def scene_latents(cfg: TrainConfig, params, images):
    return models.encode_mean(params, cfg.scene, images)


def needs_log_p(cfg: TrainConfig, enc: GoalEncoder) -> bool:
    """Whether Skew-Fit's log p(x) of stored frames is used: skewed goals, or online scene-VAE
    training on skewed replay images (static; the chunk skips the estimator otherwise)."""
    return not enc.oracle and (enc.skewed_goals or cfg.vae_schedule != "none")


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


# ROLL's prior goals per chunk: N(0, I) samples through the LSTM, drawn once per chunk (the
# LSTM does not change while a chunk collects and updates SAC). Encoding 128 fresh ones for
# each of the chunk's updates cost as much as the SAC update itself (1.3 ms per update on a
# 2-core CPU); each update now draws its rows from this bank.
PRIOR_BANK = 4096


def goal_prior(cfg: TrainConfig, enc: GoalEncoder, env, buffer, key, lstm_params=None):
    """What a chunk's prior goals are drawn from (`fresh_goals`): the oracle's bank of
    goal-space object states; for ROLL a bank of `PRIOR_BANK` goals from the frame encoder's
    prior N(0, I) (Algorithm 1), or N(mean, std) of the buffer's frame latents for
    cfg.prior_goals "buffer", through the LSTM; None for Skew-Fit (goals from the buffer)."""
    if enc.oracle:
        return goal_bank(env, key)
    if enc.skewed_goals:
        return None
    stats = frame_stats(buffer) if cfg.prior_goals == "buffer" else None
    return enc.prior_goals(key, lstm_params, PRIOR_BANK, stats)


def goal_bank(env, key, n: int = 1024):
    """The oracle's prior goals: n object states drawn from the task's goal space."""
    return jax.vmap(lambda k: oracle_goal(env, env.sample_goal(k)))(jax.random.split(key, n))


def test_goals(cfg: TrainConfig, env, enc: GoalEncoder, frozen: Frozen, scene_params,
               lstm_params, key):
    """`n_eval_goals` test goals from the task's goal space: (goal env states, their goal
    images rendered at 48x48, their latents: segmented and encoded like any goal image)."""
    states = jax.vmap(env.sample_goal)(jax.random.split(key, cfg.n_eval_goals))
    if enc.oracle:  # only the first goal image is shown (the evaluation video)
        rgb = env.render(jax.tree.map(lambda x: x[0], states))[None]
        return states, rgb, jax.vmap(lambda st: oracle_goal(env, st))(states)
    rgb = jax.vmap(env.render)(states)
    latents = enc.encode_goal_images(frozen, scene_params, lstm_params, rgb)
    return states, rgb, latents


def _concat(a, b):
    return jax.tree.map(lambda x, y: jnp.concatenate([x, y]), a, b)


def collect_episode(cfg: TrainConfig, env, enc: GoalEncoder, frozen: Frozen, state: TrainState,
                    key, act_random, prior=None, learn=None, eval_policy=None,
                    episode_index=0, evaluate: bool = True):
    """One episode of all E training envs and, in the same env batch, of G = n_eval_goals
    test envs -> (env_state, replay.Trajectory [E, ...], Skew-Fit log p(x) of its scene
    images [E, T+1] (zeros when unused, `needs_log_p`), metrics incl. the test envs' final
    distances [G], a video of test env 0 [T+1, H, W, 3] and its goal image).

    The test envs start from resets, chase test goals (`test_goals`) with the deterministic
    policy and are neither stored nor learned from; starts and goals come from
    state.eval_key and `episode_index` (the episode's place in its chunk), so every
    evaluation of a seed sees the same ones (reset-free tasks restart them from their fixed
    `test_start` states). Sharing the batch costs G
    more envs per step but no second compiled copy of MJX's step (the largest compile), and
    one reset serves both. Each frame is encoded once (the policy's observation is the
    stored scene latent). `prior`: what prior goals are drawn from (`goal_prior`).

    With cfg.sac_schedule "step", `learn` (bool) switches on n_envs x updates_per_step SAC
    updates after every env step (on the buffer as it was at the episode's start); the test
    envs then act with `eval_policy` (the policy the chunk started from) and the new SAC state
    and its mean metrics come back in the metrics ("sac_state", "sac").

    `evaluate` False (static) leaves the test envs out of the batch (no test metrics): the
    training envs' keys, and so their episodes, are the same either way."""
    k_reset, k_goal, k_act, k_lp = jax.random.split(key, 4)
    k_test_reset, k_test = jax.random.split(jax.random.fold_in(state.eval_key, episode_index))
    interleave = cfg.sac_schedule == "step"
    eval_policy = state.sac.policy_params if eval_policy is None else eval_policy
    lstm_params = lstm_params_of(state)
    scene_params = state.scene_vae.params
    n_train = cfg.n_envs
    reset_keys = jax.random.split(k_reset, n_train)
    cdf = _skew_cdf_of(cfg, enc, state)  # the buffer is fixed for the whole episode
    goals = fresh_goals(enc, state.buffer, cdf, k_goal, n_train, prior)
    if evaluate:
        env_state = jax.vmap(env.reset_episode)(
            _concat(state.env_state, state.test_start),
            jnp.concatenate([reset_keys, jax.random.split(k_test_reset, cfg.n_eval_goals)]))
        test_begin = jax.tree.map(lambda x: x[n_train:], env_state)
        test_states, test_rgb, test_lat = test_goals(cfg, env, enc, frozen, scene_params,
                                                     lstm_params, k_test)
        goals = jnp.concatenate([goals, test_lat])
    else:
        env_state = jax.vmap(env.reset_episode)(state.env_state, reset_keys)
    is_test = (jnp.arange(goals.shape[0]) >= n_train)[:, None]
    test0 = lambda es: jax.tree.map(lambda x: x[n_train], es)  # noqa: E731

    def observe(es):
        """(what the step records, the policy's observation [E(+G), ds]) of the env states."""
        if enc.oracle:
            obs = jax.vmap(lambda st: oracle_obs(env, st))(es)
            video = env.render(test0(es)) if evaluate else None
            rec = (obs, jax.vmap(lambda st: oracle_goal(env, st))(es), video)
            return rec, obs
        rgb = jax.vmap(env.render)(es)
        z = scene_latents(cfg, scene_params, rgb)
        return (rgb, z), z

    zero_sac = zero_sac_metrics(cfg, enc, state, prior) if interleave else None
    n_per_step = cfg.n_envs * cfg.sac.updates_per_step

    def step(carry, k):
        es, z, sac_s = carry
        k_pol, k_rand, k_upd = jax.random.split(k, 3)
        a_pol = sac.select_action(sac_s.policy_params, z, goals, k_pol, cfg=cfg.sac)
        a_rand = jax.random.uniform(k_rand, a_pol.shape, minval=-1.0, maxval=1.0)
        a = jnp.where(act_random, a_rand, a_pol)
        if evaluate:
            a_det = sac.select_action(eval_policy, z, goals, None, deterministic=True,
                                      cfg=cfg.sac)
            a = jnp.where(is_test, a_det, a)
        es = jax.vmap(env.step)(es, a)
        rec, z = observe(es)
        sac_m = None
        if interleave:
            sac_s, sac_m = jax.lax.cond(
                learn, lambda s_: sac_steps(cfg, enc, s_, state.buffer, cdf,
                                            k_upd, n_per_step, prior),
                lambda s_: (s_, zero_sac), sac_s)
        return (es, z, sac_s), (rec, a, sac_m)

    rec0, z0 = observe(env_state)
    (env_state, _, sac_state), (recs, actions, sac_ms) = jax.lax.scan(
        step, (env_state, z0, state.sac), jax.random.split(k_act, cfg.horizon))
    # Episode-major [.., T+1, ...] records of the training envs (and test env 0's video).
    rec = jax.tree.map(lambda x0, xs: jnp.concatenate([x0[None], xs], 0), rec0, recs)
    test_final = jax.tree.map(lambda x: x[n_train:], env_state) if evaluate else None
    env_state = jax.tree.map(lambda x: x[:n_train], env_state)
    goals = goals[:n_train]
    if enc.oracle:
        obs, achieved, video = rec
        obs, achieved = obs[:, :n_train].swapaxes(0, 1), achieved[:, :n_train].swapaxes(0, 1)
        images = jnp.zeros(achieved.shape[:2] + state.buffer.images.shape[2:], jnp.uint8)
        goal_imgs, frame_lat = images, achieved
    else:
        rgbs, z = rec
        video = rgbs[:, n_train] if evaluate else None
        images = rgbs[:, :n_train].swapaxes(0, 1)  # [E, T+1, H, W, 3]
        obs = z[:, :n_train].swapaxes(0, 1)
        goal_imgs = enc.goal_images(frozen, images)
        frame_lat = enc.frame_latents(frozen, scene_params, goal_imgs)
        achieved = jax.vmap(lambda f: enc.achieved(lstm_params, f))(frame_lat)
    traj = replay.Trajectory(
        images=images, object_images=goal_imgs, actions=actions[:, :n_train].swapaxes(0, 1),
        obs_latents=obs, frame_latents=frame_lat, goal_latents=achieved, rollout_goals=goals)
    if needs_log_p(cfg, enc):
        log_p = skewfit.frame_log_p(cfg, scene_params, images, k_lp)
    else:
        log_p = jnp.zeros(images.shape[:2], jnp.float32)
    final_dist = jnp.sum(jnp.square(achieved[:, -1] - goals), -1)
    metrics = {"rollout_latent_dist": final_dist.mean()}
    if evaluate:
        metrics.update({
            "test_distances": jax.vmap(env.goal_distance)(test_final, test_states),
            "test_start_distances": jax.vmap(env.goal_distance)(test_begin, test_states),
            "test_video": video, "test_goal_image": test_rgb[0]})
    if interleave:
        metrics["sac_state"] = sac_state
        metrics["sac"] = jax.tree.map(jnp.mean, sac_ms)
    return env_state, traj, log_p, metrics


def store_episodes(state: TrainState, traj: replay.Trajectory, log_p) -> TrainState:
    """Add E episodes to the buffer and their log p(x) [E, T+1] to the same ring slots."""
    e = traj.actions.shape[0]
    slots = (state.buffer.insert_pos + jnp.arange(e, dtype=jnp.int32)) % state.buffer.capacity
    return state.replace(buffer=replay.add_trajectories(state.buffer, traj),
                         skew_log_p=state.skew_log_p.at[slots].set(log_p.astype(jnp.float32)))


def sac_steps(cfg: TrainConfig, enc: GoalEncoder, sac_state: sac.SACState,
              buffer: replay.ReplayBuffer, cdf, key, n_updates: int, prior=None):
    """`n_updates` SAC updates on HER batches from `buffer` -> (SAC state, mean metrics); the
    fresh-goal share is drawn per batch by `fresh_goals` (`cdf`: Skew-Fit's, or None)."""

    def body(s, k):
        k_goal, k_batch, k_upd = jax.random.split(k, 3)
        fresh = fresh_goals(enc, buffer, cdf, k_goal, cfg.sac.batch_size, prior)
        batch = replay.sample_transitions(buffer, k_batch, cfg.sac.batch_size, fresh,
                                          cfg.sac.goal_fracs, cfg.reward_norm)
        s, m = sac.sac_update(s, k_upd, batch, cfg.sac)
        m["reward"] = batch.reward.mean()
        return s, m

    new, metrics = jax.lax.scan(body, sac_state, jax.random.split(key, n_updates))
    return new, jax.tree.map(jnp.mean, metrics)


def _skew_cdf_of(cfg: TrainConfig, enc: GoalEncoder, state: TrainState):
    if not enc.skewed_goals:
        return None
    return skewfit.skew_cdf_at(cfg, state.skew_log_p, state.buffer.size, state.epoch)


def sac_updates(cfg: TrainConfig, enc: GoalEncoder, state: TrainState, key, n_updates: int,
                prior=None):
    """`sac_steps` on the train state's buffer (which does not change during the updates, so
    the Skew-Fit sampling CDF is built once)."""
    new, metrics = sac_steps(cfg, enc, state.sac, state.buffer, _skew_cdf_of(cfg, enc, state),
                             key, n_updates, prior)
    return state.replace(sac=new), metrics


def zero_sac_metrics(cfg: TrainConfig, enc: GoalEncoder, state: TrainState, prior=None):
    """`sac_updates`' metrics of the branch that does not learn: zeros, "finite" true (no
    update, nothing non-finite)."""
    m = jax.tree.map(jnp.zeros_like, jax.eval_shape(
        lambda s: sac_updates(cfg, enc, s, jax.random.PRNGKey(0), 1, prior)[1], state))
    m["finite"] = jnp.ones_like(m["finite"])
    return m


def fresh_goals(enc: GoalEncoder, buffer: replay.ReplayBuffer, cdf, key, n: int, prior=None):
    """n goals for exploration and for the fresh-goal share of HER relabeling.

    ROLL (Algorithm 1): the object-VAE prior N(0, I) through the LSTM, drawn uniformly from
    the chunk's bank of such goals (`prior`, from `goal_prior`; with cfg.prior_goals "buffer"
    the prior is N(mean, std) of the stored frame latents). The oracle: object states of the
    task's goal space (`prior`, from `goal_bank`).
    Skew-Fit (rlkit's `custom_goal_sampler`): achieved-goal latents of buffer frames drawn
    with probability p(x)^alpha (`cdf` from `skew_cdf`; the cached latents are refreshed with
    the VAE); the scene-VAE prior N(0, I) while the buffer is still empty.
    """
    if not enc.skewed_goals:
        return prior[jax.random.randint(key, (n,), 0, prior.shape[0])]
    k_prior, k_buf = jax.random.split(key)
    flat = skewfit.sample_frames(k_buf, cdf, n)
    t1 = buffer.goal_latents.shape[1]
    replay_goals = buffer.goal_latents[flat // t1, flat % t1]
    # (Skew-Fit has no LSTM: its prior goals are the scene-VAE prior samples themselves.)
    return jnp.where(buffer.size > 0, replay_goals, enc.prior_goals(k_prior, None, n))


# ----------------------------------------------------------------------------- the chunk

def make_chunk(cfg: TrainConfig, env, evaluate: bool = True):
    """chunk(state, frozen, plan) -> (state, {"train": this chunk's training metrics, "eval":
    the evaluation of the policy the chunk started from, with "train" = the metrics of the
    chunk that trained it}) for ONE seed; the caller runs it over the seeds (frozen and plan
    un-batched; `compile_chunk`) and jits. The policy after the last chunk is evaluated by
    one more chunk with `eval_only_plan()`.

    `evaluate` False: a chunk without the test envs and without "eval", for the chunks whose
    evaluation nobody logs (the test envs would otherwise step beside the training envs in
    every chunk); the training itself is the same."""
    enc = goal_encoder(cfg)
    n_updates = cfg.epoch_env_steps * cfg.sac.updates_per_step

    def chunk(state: TrainState, frozen: Frozen, plan: ChunkPlan):
        TRACE_COUNTS["chunk"] += 1
        key, k_col, k_sac, k_vae, k_lstm, k_bank = jax.random.split(state.key, 6)
        prior = goal_prior(cfg, enc, env, state.buffer, k_bank, lstm_params_of(state))

        interleave = cfg.sac_schedule == "step"
        eval_policy = state.sac.policy_params

        def episode(s, k_i):
            k, i = k_i
            es, traj, log_p, m = collect_episode(cfg, env, enc, frozen, s, k, plan.act_random,
                                                 prior, plan.learn, eval_policy, i, evaluate)
            if interleave:
                s = s.replace(sac=m.pop("sac_state"))
            s = store_episodes(s, traj, log_p).replace(
                env_state=es, env_steps=s.env_steps + cfg.n_envs * cfg.horizon)
            return s, m

        start_train = state.last_train
        state, col_m = jax.lax.scan(
            episode, state, (jax.random.split(k_col, cfg.episodes_per_epoch),
                             jnp.arange(cfg.episodes_per_epoch)))
        out = {}
        if evaluate:
            dist = col_m.pop("test_distances").reshape(-1)  # [episodes * G]
            start = col_m.pop("test_start_distances").reshape(-1)
            out["eval"] = {"final_distance": dist.mean(),
                           "final_distance_median": jnp.median(dist),
                           "start_distance": start.mean(),
                           "distances": dist, "video": col_m.pop("test_video")[0],
                           "goal_image": col_m.pop("test_goal_image")[0], "train": start_train}
        metrics = jax.tree.map(jnp.mean, col_m)
        if interleave:  # the updates ran inside the episodes
            metrics.update(metrics.pop("sac"))
        else:
            state, sac_m = jax.lax.cond(
                plan.learn, lambda s: sac_updates(cfg, enc, s, k_sac, n_updates, prior),
                lambda s: (s, zero_sac_metrics(cfg, enc, s, prior)), state)
            metrics.update(sac_m)

        if enc.oracle or cfg.vae_schedule == "none":  # no online scene-VAE training
            metrics["vae_loss"] = jnp.float32(0)
        else:
            def vae_round(s):
                s, m = online.train_scene_vae(cfg, s, k_vae, plan.vae_batches)
                return online.refresh_scene(cfg, enc, s), m

            state, vae_m = jax.lax.cond(plan.vae_batches > 0, vae_round,
                                        lambda s: (s, {"vae_loss": jnp.float32(0)}), state)
            metrics.update(vae_m)
        if enc.lstm:
            state, lstm_m = jax.lax.cond(
                plan.lstm_batches > 0,
                lambda s: online.train_lstm(cfg, enc, frozen, s, k_lstm, plan.lstm_batches),
                lambda s: (s, {"lstm_loss": jnp.float32(0)}), state)
            metrics.update(lstm_m)
        if not enc.oracle:
            state = jax.lax.cond(plan.refresh_goals, lambda s: online.refresh_goals(enc, s),
                                 lambda s: s, state)
        state = state.replace(key=key, epoch=state.epoch + 1, last_train={
            k: metrics[k].astype(jnp.float32) for k in train_metric_keys(cfg)})
        return state, {"train": metrics, **out}

    return chunk


def compile_chunk(cfg: TrainConfig, env, n_devices: int = 1, seed_batch: int | None = None,
                  evaluate: bool = True):
    """jit of the chunk over the seed axis, state donated: vmapped over all seeds
    (`seed_batch` None), or each device's seeds in a lax.map over groups of `seed_batch`
    vmapped seeds (`sharding.over_seeds`; faster on a CPU). `evaluate`: `make_chunk`'s.

    One per (config, env, placement) in a process (`envs_mjx.make` gives one env per task):
    a second run of the same config, e.g. a resumed run or a grid cell, calls the programs
    this one traced and compiled. Retracing would not reliably find them in the persistent
    cache: JAX's bounded trace caches make the lowered module depend on what the process
    traced before (docs/training.md)."""
    return _compiled_chunk(cfg, env, int(n_devices), seed_batch, bool(evaluate))


# XLA:CPU options for the chunk alone: XLA's older elemental emitters and LLVM at -O1 compile
# the cpu preset's chunk in 29.6 s instead of 47.6 s on a 2-core Xeon, and it runs faster
# (4.21 against 4.58 s). Without the YNNPACK fusions (XLA:CPU's default library for dots) its
# SAC updates run ~20% faster (1.5 instead of 1.9 ms each) and its online LSTM steps slower;
# the chunk 4% faster in all (bench/chunk_options.py, bench/sac_parts.py, docs/training.md).
# Other programs keep XLA's defaults (the VAE and U-Net train steps run slower with the
# emitters and without YNNPACK).
CHUNK_CPU_COMPILER_OPTIONS = (("xla_cpu_use_fusion_emitters", False),
                              ("xla_backend_optimization_level", 1),
                              ("xla_cpu_experimental_ynn_fusion_type", ""))


def chunk_compiler_options() -> dict | None:
    """The chunk's `compiler_options`: CHUNK_CPU_COMPILER_OPTIONS on a CPU backend (where the
    installed jaxlib accepts them), XLA's defaults elsewhere. An option the process's
    XLA_FLAGS sets is left to XLA_FLAGS (a per-program option would override it)."""
    if jax.default_backend() != "cpu":
        return None
    flags = os.environ.get("XLA_FLAGS", "")
    options = tuple((k, v) for k, v in CHUNK_CPU_COMPILER_OPTIONS if f"--{k}" not in flags)
    return compiler.accepted_options(options) if options else None


@functools.lru_cache(maxsize=4)
def _compiled_chunk(cfg: TrainConfig, env, n_devices: int, seed_batch: int | None,
                    evaluate: bool):
    chunk = over_seeds(make_chunk(cfg, env, evaluate), cfg.seeds, n_devices, seed_batch)
    return jax.jit(chunk, donate_argnums=0, compiler_options=chunk_compiler_options())
