"""What the policy sees and what the reward compares, per algorithm and ablation.

ROLL (paper Fig. 1): obs = scene-VAE(I); goal/achieved = LSTM(object-VAE(segment(I))).
Ablations (paper "Ablations"): no LSTM -> object-VAE latents directly; no object-VAE -> the
scene-VAE encodes the (unsegmented) image for the LSTM; no matching loss -> same encoders,
trained without it, neither the LSTM's nor the object-VAE's ("does not add the matching loss
to the LSTM output or the object-VAE latent embedding"); no LSTM also drops the object-VAE's
matching loss (the paper's "ROLL without LSTM and matching loss"). Skew-Fit: the scene-VAE
encodes everything and goals come from the skewed replay buffer (agents/her.py). The state
oracle (`--algo oracle`) is another encoder with the same contract: `oracle.StateOracle`.

`GoalEncoder` is a static description (built from the config, hashable); its methods are pure
functions of explicit parameters so that the loop, evaluation and analysis share them. What
the training loop calls: `observe` (each step), `encode_episodes` (each finished episode),
`goal_bank` (each chunk's prior goals), `test_goal_images` / `encode_goals` (test goals).
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar

import jax
import jax.numpy as jnp
from flax import struct

from configs.encoders import VAEConfig
from roll_jax.encoders import models
from roll_jax.encoders.models import lstm_encode
from roll_jax.encoders.oracle import StateOracle
from roll_jax.segmentation import pipeline

# ROLL's prior goals per chunk: N(0, I) samples through the LSTM, drawn once per chunk (the
# LSTM does not change while a chunk collects and updates SAC). Encoding 128 fresh ones for
# each of the chunk's updates cost as much as the SAC update itself (1.3 ms per update on a
# 2-core CPU); each update now draws its rows from this bank.
PRIOR_BANK = 4096


@struct.dataclass
class Frozen:
    """Parameters fixed during RL, shared by all seeds: segmentation and the object-VAE."""

    seg: Any  # pipeline.SegParams or None (Skew-Fit, no-object-VAE)
    object_vae: Any  # object-VAE params or None


# --- achieved goals: how an episode's frames become the reward's achieved side -------------

@dataclasses.dataclass(frozen=True)
class SequenceAchieved:
    """The LSTM run over the episode so far (the paper's z_t = g(z_hat_1..t))."""
    name: ClassVar[str] = "sequence"

    def __call__(self, enc: "GoalEncoder", lstm_params, frame_latents, object_images):
        del object_images
        return enc.sequence(lstm_params, frame_latents)


@dataclasses.dataclass(frozen=True)
class SingleAchieved:
    """Each frame alone, one LSTM step from the zero state: the goal images' function (the
    reference code's refresh_latents)."""
    name: ClassVar[str] = "single"

    def __call__(self, enc: "GoalEncoder", lstm_params, frame_latents, object_images):
        del object_images
        return enc.single(lstm_params, frame_latents)


@dataclasses.dataclass(frozen=True)
class HeldAchieved:
    """`SingleAchieved`, except that a frame whose segmented image shows fewer than
    `min_pixels` object pixels (the object hidden by the arm) keeps the achieved goal of the
    last frame that showed it (the episode's first frame keeps its own): the memory the LSTM
    is meant to give, made exact, so hiding the object earns what leaving it in view does."""
    min_pixels: int
    name: ClassVar[str] = "held"

    def __call__(self, enc: "GoalEncoder", lstm_params, frame_latents, object_images):
        single = enc.single(lstm_params, frame_latents)
        visible = object_pixels(object_images) >= self.min_pixels  # [T]

        def step(last, x):
            z, seen = x
            z = jnp.where(seen, z, last)
            return z, z

        _, held = jax.lax.scan(step, single[0], (single, visible))
        return held


def object_pixels(object_images):
    """Pixels [...] of segmented images [..., H, W, 3] (rgb * mask) that show the object."""
    return jnp.any(object_images > 0, axis=-1).sum(axis=(-2, -1))


def achieved_encoding(cfg) -> SequenceAchieved | SingleAchieved | HeldAchieved:
    """The achieved-goal strategy a TrainConfig names (`achieved_encoding`)."""
    if cfg.achieved_encoding == "held":
        return HeldAchieved(cfg.held_min_pixels)
    return {"sequence": SequenceAchieved, "single": SingleAchieved}[cfg.achieved_encoding]()


@dataclasses.dataclass(frozen=True)
class GoalEncoder:
    """How images become goal/achieved latents (the reward space)."""

    scene_cfg: VAEConfig
    object_cfg: VAEConfig | None  # None: the scene-VAE encodes goal frames (no-object-VAE, Skew-Fit)
    segment: bool  # segment images before the frame encoder
    lstm: bool  # run the LSTM over the per-frame latents
    # Fresh goals (exploration, HER's fresh share) from the replay buffer skewed by p(x)^alpha
    # (Skew-Fit) instead of the prior (ROLL's Algorithm 1); see her.fresh_goals.
    skewed_goals: bool = False
    # How an episode's frames become achieved goals (TrainConfig.achieved_encoding).
    achieved_by: SequenceAchieved | SingleAchieved | HeldAchieved = SequenceAchieved()
    from_pixels: ClassVar[bool] = True  # (the state oracle's is False)

    @property
    def image_shape(self) -> tuple[int, ...]:
        """The replay buffer's image shape: the scene images."""
        return self.scene_cfg.image_shape

    def latent_dims(self, env) -> tuple[int, int, int]:
        """(observation, goal, per-frame) latent sizes."""
        del env
        return self.scene_cfg.latent_dim, self.goal_dim, self.frame_dim

    @property
    def frame_dim(self) -> int:
        return (self.object_cfg or self.scene_cfg).latent_dim

    @property
    def goal_dim(self) -> int:
        return self.frame_dim  # the LSTM output reconstructs its input

    def goal_images(self, frozen: Frozen, rgb):
        """What the frame encoder sees: the segmented image (rgb * object mask) or rgb."""
        if not self.segment:
            return rgb
        return pipeline.segmented_image(rgb, pipeline.segment(frozen.seg, rgb))

    def frame_latents(self, frozen: Frozen, scene_params, goal_images):
        """Per-frame latent means [..., frame_dim] of goal images (output of goal_images)."""
        if self.object_cfg is None:
            return models.encode_mean(scene_params, self.scene_cfg, goal_images)
        return models.encode_mean(frozen.object_vae, self.object_cfg, goal_images)

    def sequence(self, lstm_params, frame_latents):
        """Latents [T, d] of one episode -> achieved goals [T, goal_dim] (LSTM from a zero state)."""
        if not self.lstm:
            return frame_latents
        return lstm_encode(lstm_params, frame_latents)

    def achieved(self, lstm_params, frame_latents, object_images):
        """Achieved goals [T, goal_dim] of one episode's latents [T, d] and its segmented
        images [T, H, W, 3], as `achieved_by` encodes them."""
        return self.achieved_by(self, lstm_params, frame_latents, object_images)

    def single(self, lstm_params, frame_latents):
        """Goals from single frames [..., d] (a goal image, or a prior sample): one LSTM step
        from the zero state, as the paper encodes z_g = g(z_hat_g)."""
        if not self.lstm:
            return frame_latents
        flat = frame_latents.reshape((-1, 1, frame_latents.shape[-1]))
        return lstm_encode(lstm_params, flat)[:, 0].reshape(frame_latents.shape[:-1] + (-1,))

    def encode_goal_images(self, frozen: Frozen, scene_params, lstm_params, rgb):
        """Goal latents [..., goal_dim] of goal images rgb [..., 48, 48, 3], as the paper
        encodes a test goal: segment (ROLL) -> frame encoder -> one LSTM step."""
        return self.single(lstm_params,
                           self.frame_latents(frozen, scene_params, self.goal_images(frozen, rgb)))

    def prior_goals(self, key, lstm_params, n: int, stats=None):
        """n goals from the frame encoder's prior N(0, I) (or N(mean, std) with
        `stats` = (mean, std)), encoded like a goal frame."""
        z = jax.random.normal(key, (n, self.frame_dim), jnp.float32)
        if stats is not None:
            z = stats[0] + stats[1] * z
        return self.single(lstm_params, z)

    # --- what the training loop and the evaluation call (StateOracle has the same) -----------

    def observe(self, env, scene_params, states, show=None):
        """(the policy's observations [N, ds]: scene-VAE means of the rendered frames, what
        an episode keeps of the step: the frames [N, 48, 48, 3], the frames of the envs
        `show` picks: None, an index or a slice) of env states [N]."""
        rgb = jax.vmap(env.render)(states)
        z = models.encode_mean(scene_params, self.scene_cfg, rgb)
        return z, rgb, None if show is None else rgb[show]

    def encode_episodes(self, frozen, scene_params, lstm_params, records):
        """(images, goal images, frame latents, achieved goals) of episodes whose steps kept
        `records`: their frames [E, T+1, 48, 48, 3], segmented (`goal_images`) and encoded
        (`frame_latents`, `achieved`)."""
        goal_imgs = self.goal_images(frozen, records)
        frame_lat = self.frame_latents(frozen, scene_params, goal_imgs)
        achieved = jax.vmap(lambda f, o: self.achieved(lstm_params, f, o))(frame_lat, goal_imgs)
        return records, goal_imgs, frame_lat, achieved

    def goal_bank(self, env, key, lstm_params, stats=None):
        """What a chunk's prior goals are drawn from: PRIOR_BANK `prior_goals`; None for
        Skew-Fit (its goals come from the buffer)."""
        del env
        if self.skewed_goals:
            return None
        return self.prior_goals(key, lstm_params, PRIOR_BANK, stats)

    def test_goal_images(self, env, states):
        """The goal images [G, 48, 48, 3] of goal env states [G]."""
        return jax.vmap(env.render)(states)

    def encode_goals(self, env, frozen, scene_params, lstm_params, rgb, states):
        """The goals [G, goal_dim] of goal images rgb [G, 48, 48, 3] (`encode_goal_images`;
        their env `states` are not used: a user's goal image has none)."""
        del env, states
        return self.encode_goal_images(frozen, scene_params, lstm_params, rgb)


def goal_encoder(cfg) -> GoalEncoder | StateOracle:
    """The GoalEncoder of a TrainConfig (algo + ablation flags); the state oracle's."""
    if cfg.algo == "oracle":
        return StateOracle()
    if cfg.algo == "skewfit":
        return GoalEncoder(cfg.scene, None, segment=False, lstm=False, skewed_goals=True)
    if not cfg.use_object_vae:
        return GoalEncoder(cfg.scene, None, segment=False, lstm=True,
                           achieved_by=achieved_encoding(cfg))
    object_cfg = cfg.object_vae
    if not (cfg.matching_loss and cfg.use_lstm):
        # Pretraining fits the object-VAE from this config, so the ablation reaches it too.
        object_cfg = dataclasses.replace(object_cfg, matching_coef=0.0)
    return GoalEncoder(cfg.scene, object_cfg, segment=True, lstm=cfg.use_lstm,
                       achieved_by=achieved_encoding(cfg))
