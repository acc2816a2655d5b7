"""One compiled training chunk (an rlkit "epoch"): collect, store, learn; Algorithm 1.

A chunk, for one seed (the caller runs it over the seed axis, `sharding.over_seeds`):
  1. `episodes_per_epoch` episodes of all envs (`collect.collect_episode`): the goal encoder
     observes each rendered frame, the policy acts (uniformly at random before learning
     starts), MJX steps; exploration goals from the chunk's prior bank (ROLL: the
     object-VAE prior through the LSTM), or Skew-Fit's skewed replay buffer
     (`her.fresh_goals`). The evaluation runs in the same env batch: test envs chase test
     goals with the deterministic policy the chunk starts from;
  2. per finished episode: the encoder's latents of its frames (segmented, object-VAE,
     LSTM), the whole trajectories with cached latents and Skew-Fit's log p(x) stored in the
     replay buffer;
  3. 2 SAC updates per collected transition on HER-relabelled batches (`her.sac_steps`;
     rlkit's order: collect the epoch's steps, then train; or inside the episode);
  4. scheduled scene-VAE training on Skew-Fit-skewed replay images and online LSTM training
     (auto-encoder + matching loss) on the buffer's cached frame latents, the cached goal
     latents recomputed on the refresh schedule (`online.train_encoders`).
How much of 3 and 4 happens is decided per chunk in Python (`state.plan_chunk`: the
schedules are functions of the env step) and passed in as un-batched scalars, so the chunk
compiles once. `--algo oracle` runs the same chunk with the state oracle as its goal encoder
(`encoders.oracle.StateOracle`).
"""

from __future__ import annotations

import collections
import functools

import jax
import jax.numpy as jnp

from configs.train import TrainConfig
from roll_jax.agents import her
from roll_jax.encoders.goal_encoding import Frozen, goal_encoder
from roll_jax.training import online
from roll_jax.training.collect import ChunkInputs, Collector, collect_episode
from roll_jax.training.compiler import chunk_compiler_options
from roll_jax.training.sharding import over_seeds
from roll_jax.training.state import (
    ChunkPlan,
    TrainState,
    lstm_params_of,
    skew_cdf_of,
    store_episodes,
    train_metric_keys,
)

TRACE_COUNTS: collections.Counter = collections.Counter()


def fresh_goals_of(cfg: TrainConfig, enc, state: TrainState, bank) -> her.FreshGoals:
    """Where fresh goals come from in the state's buffer: the chunk's `bank`, or Skew-Fit's
    CDF over the buffer (built once: the buffer does not change during the updates)."""
    return her.FreshGoals(bank=bank, cdf=skew_cdf_of(cfg, enc, state))


def sac_updates(cfg: TrainConfig, enc, state: TrainState, key, n_updates: int, bank=None):
    """`her.sac_steps` on the train state's buffer -> (state, mean metrics)."""
    new, metrics = her.sac_steps(cfg, enc, state.sac, state.buffer,
                                 fresh_goals_of(cfg, enc, state, bank), key, n_updates)
    return state.replace(sac=new), metrics


def evaluation(test: dict, train: dict) -> dict:
    """The chunk's evaluation from its episodes' test results [episodes, ...], beside the
    training metrics of the chunk that trained the evaluated policy."""
    dist = test["distances"].reshape(-1)  # [episodes * G]
    return {"final_distance": dist.mean(), "final_distance_median": jnp.median(dist),
            "start_distance": test["start_distances"].reshape(-1).mean(), "distances": dist,
            "video": test["video"][0], "goal_image": test["goal_image"][0], "train": train}


def make_chunk(cfg: TrainConfig, env, evaluate: bool = True):
    """chunk(state, frozen, plan) -> (state, {"train": this chunk's training metrics, "eval":
    the evaluation of the policy the chunk started from, with "train" = the metrics of the
    chunk that trained it}) for ONE seed; the caller runs it over the seeds (frozen and plan
    un-batched; `compile_chunk`) and jits. The policy after the last chunk is evaluated by
    one more chunk with `state.eval_only_plan()`.

    `evaluate` False: a chunk without the test envs and without "eval", for the chunks whose
    evaluation nobody logs (the test envs would otherwise step beside the training envs in
    every chunk); the training itself is the same."""
    enc = goal_encoder(cfg)
    collector = Collector(cfg, env, enc, evaluate)
    n_updates = cfg.epoch_env_steps * cfg.sac.updates_per_step

    def chunk(state: TrainState, frozen: Frozen, plan: ChunkPlan):
        TRACE_COUNTS["chunk"] += 1
        key, k_col, k_sac, k_vae, k_lstm, k_bank = jax.random.split(state.key, 6)
        bank = her.goal_prior(cfg, enc, env, state.buffer, k_bank, lstm_params_of(state))
        inputs = ChunkInputs(frozen=frozen, plan=plan, bank=bank,
                             eval_policy=state.sac.policy_params)

        def episode(s, k_i):
            ep = collect_episode(collector, inputs, s, *k_i)
            s = s.replace(sac=ep.sac, env_state=ep.env_state,
                          env_steps=s.env_steps + cfg.n_envs * cfg.horizon)
            return store_episodes(s, ep.traj, ep.log_p), (ep.metrics, ep.test)

        start_train = state.last_train
        state, (col_m, test) = jax.lax.scan(
            episode, state, (jax.random.split(k_col, cfg.episodes_per_epoch),
                             jnp.arange(cfg.episodes_per_epoch)))
        metrics = jax.tree.map(jnp.mean, col_m)
        if collector.interleaved:  # the updates ran inside the episodes
            metrics.update(metrics.pop("sac"))
        else:
            state, sac_m = jax.lax.cond(
                plan.learn, lambda s: sac_updates(cfg, enc, s, k_sac, n_updates, bank),
                lambda s: (s, her.zero_sac_metrics(cfg, enc, s.sac, s.buffer,
                                                   fresh_goals_of(cfg, enc, s, bank))), state)
            metrics.update(sac_m)
        state, enc_m = online.train_encoders(cfg, enc, frozen, state, plan, (k_vae, k_lstm))
        metrics.update(enc_m)
        state = state.replace(key=key, epoch=state.epoch + 1, last_train={
            k: metrics[k].astype(jnp.float32) for k in train_metric_keys(cfg)})
        out = {"train": metrics}
        if evaluate:
            out["eval"] = evaluation(test, start_train)
        return state, out

    return chunk


def compile_chunk(cfg: TrainConfig, env, n_devices: int = 1, seed_batch: int | None = None,
                  evaluate: bool = True):
    """jit of the chunk over the seed axis, state donated: vmapped over all seeds
    (`seed_batch` None), or each device's seeds in a lax.map over groups of `seed_batch`
    vmapped seeds (`sharding.over_seeds`; faster on a CPU), compiled with the chunk's own
    options (`compiler.chunk_compiler_options`). `evaluate`: `make_chunk`'s.

    One per (config, env, placement) in a process (`envs_mjx.make` gives one env per task):
    a second run of the same config, e.g. a resumed run or a grid cell, calls the programs
    this one traced and compiled. Retracing would not reliably find them in the persistent
    cache: JAX's bounded trace caches make the lowered module depend on what the process
    traced before (docs/training.md, "Compiling the chunk")."""
    return _compiled_chunk(cfg, env, int(n_devices), seed_batch, bool(evaluate))


@functools.lru_cache(maxsize=4)
def _compiled_chunk(cfg: TrainConfig, env, n_devices: int, seed_batch: int | None,
                    evaluate: bool):
    chunk = over_seeds(make_chunk(cfg, env, evaluate), cfg.seeds, n_devices, seed_batch)
    return jax.jit(chunk, donate_argnums=0, compiler_options=chunk_compiler_options())
