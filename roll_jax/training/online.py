"""Online encoder training inside the chunk (Algorithm 1, appendix "Training schedules"):
the scene-VAE on Skew-Fit-skewed replay images, the LSTM on replay trajectories
(auto-encoder + matching loss), and the recomputation of the buffer's cached latents after
either. `state` is the chunk's `state.TrainState`; `train_encoders` is the chunk's round of
all three as its `ChunkPlan` schedules them."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from configs.train import TrainConfig
from roll_jax.agents import replay, skewfit
from roll_jax.encoders import models, steps
from roll_jax.encoders.goal_encoding import Frozen, GoalEncoder
from roll_jax.training.state import ChunkPlan, lstm_params_of


def train_scene_vae(cfg: TrainConfig, state, key, n_batches):
    """`n_batches` scene-VAE steps on replay images drawn with Skew-Fit weights (from the
    stored log p(x) under the current VAE; uniform until cfg.skew_start_epoch), then log p(x)
    of the buffer's filled episodes under the trained VAE (rlkit recomputes its priorities
    after training too)."""
    buf = state.buffer
    k_lp, k_train = jax.random.split(key)
    cdf = skewfit.skew_cdf_at(cfg, state.skew_log_p, buf.size, state.epoch)

    def body(i, carry):
        vs, loss = carry
        k_s, k_step = jax.random.split(jax.random.fold_in(k_train, i))
        imgs = skewfit.sample_images(buf, k_s, cfg.vae_online_batch, cdf)
        vs, m = steps.vae_train_step(vs, k_step, imgs, cfg.scene)
        return vs, loss + m["loss"]

    vs, loss_sum = jax.lax.fori_loop(0, n_batches, body, (state.scene_vae, jnp.float32(0)))
    log_p = replay.map_filled(lambda ep: skewfit.frame_log_p(cfg, vs.params, *ep),
                              (buf.images, jax.random.split(k_lp, buf.capacity)),
                              state.skew_log_p, buf.size, LOG_P_CHUNK)
    return (state.replace(scene_vae=vs, skew_log_p=log_p),
            {"vae_loss": loss_sum / jnp.maximum(n_batches, 1)})


def online_occlusion(cfg: TrainConfig, enc: GoalEncoder, frozen: Frozen, scene_params, key,
                     goal_images):
    """The occluded frame per trajectory of goal images [B, T, H, W, 3] that an online LSTM
    step's matching loss compares (steps.Occlusion, encoded now by the frame encoder);
    None when the matching loss is ablated. The clean frames' latents come from the buffer's
    cache (`frame_latents`)."""
    if not cfg.matching_loss:
        return None
    if enc.object_cfg is not None:
        params, frame_cfg = frozen.object_vae, enc.object_cfg
    else:
        params, frame_cfg = scene_params, enc.scene_cfg
    return steps.make_occlusion(key, params, frame_cfg, goal_images, cfg.lstm)


def train_lstm(cfg: TrainConfig, enc: GoalEncoder, frozen: Frozen, state, key,
               n_batches):
    """`n_batches` online LSTM steps on trajectories drawn uniformly from the buffer: the
    auto-encoder loss, plus the matching loss unless ablated."""

    def body(i, carry):
        s, loss = carry
        k_s, k_occ, k_step = jax.random.split(jax.random.fold_in(key, i), 3)
        tr = replay.sample_trajectories(s.buffer, k_s, cfg.lstm.online_batch_size)
        occ = online_occlusion(cfg, enc, frozen, s.scene_vae.params, k_occ, tr.object_images)
        ls, m = steps.lstm_train_step(s.lstm, k_step, tr.frame_latents, cfg.lstm, occ)
        return s.replace(lstm=ls), loss + m["loss"]

    state, loss_sum = jax.lax.fori_loop(0, n_batches, body, (state, jnp.float32(0)))
    return state, {"lstm_loss": loss_sum / jnp.maximum(n_batches, 1)}


REFRESH_CHUNK = 64  # episodes encoded at a time when the buffer's latents are recomputed
# about this many episodes per block of the goal-latent refresh (latents in, no images;
# `replay.recompute` rounds it to divide the buffer: a full 50k buffer's 1000 episodes go in
# blocks of 125): an LSTM step costs about the same at 64 and at 125 sequences on a CPU, so
# that refresh takes 223 ms against 413 ms in blocks of 64 (docs/training.md, "Cached latents")
GOAL_REFRESH_CHUNK = 128
# episodes per block of the buffer's log p(x): 4 x 51 frames x skew_num_latents decodes
LOG_P_CHUNK = 4


def refresh_scene(cfg: TrainConfig, enc: GoalEncoder, state):
    """After scene-VAE training: the buffer's scene latents, and its frame latents where the
    scene-VAE encodes the goal frames (the same images: no-object-VAE, Skew-Fit)."""
    params = state.scene_vae.params
    buf = replay.recompute(state.buffer, "obs_latents",
                           lambda x: models.encode_mean(params, cfg.scene, x),
                           state.buffer.images, REFRESH_CHUNK)
    if enc.object_cfg is None:
        buf = buf.replace(frame_latents=buf.obs_latents)
    return state.replace(buffer=buf)


def refresh_goals(enc: GoalEncoder, state):
    """The buffer's goal latents from its cached frame latents and segmented images
    (`enc.achieved` of each episode; no image is encoded: the frame latents change only with
    `refresh_scene`)."""
    lstm_params = lstm_params_of(state)
    buf = replay.recompute(state.buffer, "goal_latents",
                           lambda e: enc.achieved(lstm_params, *e),
                           (state.buffer.frame_latents, state.buffer.object_images),
                           GOAL_REFRESH_CHUNK)
    return state.replace(buffer=buf)


def train_encoders(cfg: TrainConfig, enc, frozen: Frozen, state, plan: ChunkPlan, keys):
    """The chunk's online encoder training after its collection, as `plan` schedules it:
    scene-VAE batches then the buffer's scene latents (`keys[0]`; never for the state
    oracle, nor with cfg.vae_schedule "none"), LSTM batches (`keys[1]`), the goal-latent
    refresh -> (state, {"vae_loss", "lstm_loss" with an LSTM})."""
    k_vae, k_lstm = keys
    metrics = {"vae_loss": jnp.float32(0)}
    if enc.from_pixels and cfg.vae_schedule != "none":
        def vae_round(s):
            s, m = train_scene_vae(cfg, s, k_vae, plan.vae_batches)
            return refresh_scene(cfg, enc, s), m

        state, metrics = jax.lax.cond(plan.vae_batches > 0, vae_round,
                                      lambda s: (s, {"vae_loss": jnp.float32(0)}), state)
    if enc.lstm:
        state, lstm_m = jax.lax.cond(
            plan.lstm_batches > 0,
            lambda s: train_lstm(cfg, enc, frozen, s, k_lstm, plan.lstm_batches),
            lambda s: (s, {"lstm_loss": jnp.float32(0)}), state)
        metrics = {**metrics, **lstm_m}
    if enc.from_pixels:
        state = jax.lax.cond(plan.refresh_goals, lambda s: refresh_goals(enc, s),
                             lambda s: s, state)
    return state, metrics
