"""What the policy sees and what the reward compares, per algorithm and ablation.

ROLL (paper Fig. 1): obs = scene-VAE(I); goal/achieved = LSTM(object-VAE(segment(I))).
Ablations (paper "Ablations"): no LSTM -> object-VAE latents directly; no object-VAE -> the
scene-VAE encodes the (unsegmented) image for the LSTM; no matching loss -> same encoders,
trained without it, neither the LSTM's nor the object-VAE's ("does not add the matching loss
to the LSTM output or the object-VAE latent embedding"); no LSTM also drops the object-VAE's
matching loss (the paper's "ROLL without LSTM and matching loss"). Skew-Fit: the scene-VAE
encodes everything and goals come from the skewed replay buffer (loop.fresh_goals).

`GoalEncoder` is a static description (built from the config, hashable); its methods are pure
functions of explicit parameters so that the loop, evaluation and analysis share them.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from configs.encoders import VAEConfig
from roll_jax.encoders import models
from roll_jax.encoders.models import lstm_encode
from roll_jax.segmentation import pipeline


@struct.dataclass
class Frozen:
    """Parameters fixed during RL, shared by all seeds: segmentation and the object-VAE."""

    seg: Any  # pipeline.SegParams or None (Skew-Fit, no-object-VAE)
    object_vae: Any  # object-VAE params or None


@dataclasses.dataclass(frozen=True)
class GoalEncoder:
    """How images become goal/achieved latents (the reward space)."""

    scene_cfg: VAEConfig
    object_cfg: VAEConfig | None  # None: the scene-VAE encodes goal frames (no-object-VAE, Skew-Fit)
    segment: bool  # segment images before the frame encoder
    lstm: bool  # run the LSTM over the per-frame latents
    # Fresh goals (exploration, HER's fresh share) from the replay buffer skewed by p(x)^alpha
    # (Skew-Fit) instead of the prior (ROLL's Algorithm 1); see loop.fresh_goals.
    skewed_goals: bool = False
    # The state oracle: true hand and object positions instead of latents, the true distance as
    # reward, nothing rendered for learning (loop.oracle_obs / oracle_goal).
    oracle: bool = False
    # Achieved goals frame by frame (one LSTM step from the zero state, like a goal image)
    # instead of the LSTM over the episode (TrainConfig.achieved_encoding).
    achieved_single: bool = False

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

    def achieved(self, lstm_params, frame_latents):
        """Achieved goals [T, goal_dim] of one episode's latents [T, d]: `sequence`, or with
        `achieved_single` each frame by `single`, as a goal image is encoded."""
        if self.achieved_single:
            return self.single(lstm_params, frame_latents)
        return self.sequence(lstm_params, frame_latents)

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


def goal_encoder(cfg) -> GoalEncoder:
    """The GoalEncoder of a TrainConfig (algo + ablation flags)."""
    if cfg.algo == "oracle":
        return GoalEncoder(cfg.scene, None, segment=False, lstm=False, oracle=True)
    if cfg.algo == "skewfit":
        return GoalEncoder(cfg.scene, None, segment=False, lstm=False, skewed_goals=True)
    if not cfg.use_object_vae:
        return GoalEncoder(cfg.scene, None, segment=False, lstm=True,
                           achieved_single=cfg.achieved_encoding == "single")
    object_cfg = cfg.object_vae
    if not (cfg.matching_loss and cfg.use_lstm):
        # Pretraining fits the object-VAE from this config, so the ablation reaches it too.
        object_cfg = dataclasses.replace(object_cfg, matching_coef=0.0)
    return GoalEncoder(cfg.scene, object_cfg, segment=True, lstm=cfg.use_lstm,
                       achieved_single=cfg.achieved_encoding == "single")
