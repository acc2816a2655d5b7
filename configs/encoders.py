"""Scene-VAE, object-VAE and LSTM configs (paper appendix "Implementation details").

Table 2 = "Task specific hyper-parameters", Table 3 = "Scene-VAE, object-VAE and LSTM training
hyper-parameters for all tasks"; "Training schedules" and "Network Architectures" are the
appendix subsections of those names. Values marked "reference code" come from the authors'
release (github.com/yufeiwang63/ROLL), where the paper is silent.
"""

from __future__ import annotations

import dataclasses

TASKS = ("puck_push", "hurdle_bottom", "hurdle_top", "door_open", "pickup")
ALGOS = ("roll", "skewfit")

# Table 2, one entry per task in TASKS order.
_SCENE_BETA = dict(zip(TASKS, (20.0, 20.0, 20.0, 20.0, 30.0)))  # Table 2: beta for scene-VAE
_SCENE_LATENT = {
    "skewfit": dict(zip(TASKS, (4, 6, 6, 16, 16))),  # Table 2: latent size in Skew-Fit
    "roll": dict(zip(TASKS, (6, 6, 6, 16, 16))),  # Table 2: latent size in ROLL
}
_VAE_MATCHING_COEF = dict(zip(TASKS, (400.0, 400.0, 800.0, 50.0, 50.0)))  # Table 2
# Not in the paper: the reference code's launch files (occlusion_prob) occlude this share of
# the object pre-training images (push and both hurdles 0.3, door and pickup 0).
_PRETRAIN_OCCLUDED_FRACTION = dict(zip(TASKS, (0.3, 0.3, 0.3, 0.0, 0.0)))
# Not in the paper: the reference code's hurdle object-VAE / LSTM images move the hand out of
# view (ROLL/generate_LSTM_vae_only_dataset.py); the other tasks' show it.
_PRETRAIN_HAND = dict(zip(TASKS, ("random", "away", "away", "random", "random")))
# Not in the paper: puck_push's, the door's and pickup's object-VAE / LSTM images are their
# goal images, the reference code's (set-to-goal data; door_original_dataset.npy,
# pickup-original-dataset.npy); the hurdles' are placements over the corridor.
_PRETRAIN_GOAL_SHARE = dict(zip(TASKS, (1.0, 0.0, 0.0, 1.0, 1.0)))
PRETRAIN_HANDS = ("random", "away")

SCENE_FEATURE_DIM = 576  # "Network Architectures": final encoder feature vector of size 576
OBJECT_FEATURE_DIM = 6  # "Network Architectures": object-VAE feature vector of size 6


def _check_task(task: str) -> None:
    if task not in TASKS:
        raise ValueError(f"unknown task {task!r}; expected one of {TASKS}")


def _check_positive(obj, names) -> None:
    cls = type(obj).__name__
    for name in names:
        value = getattr(obj, name)
        if not value > 0:
            raise ValueError(f"{cls}.{name} must be positive, got {value!r}")


CONV_IMPLS = ("matmul", "matmul_patches", "lax")
DECODERS = ("deconv", "broadcast")  # roll_jax.encoders.models.DECODERS


# The VAE matching loss's occlusions (roll_jax.encoders.losses.OCCLUSIONS implements each).
OCCLUSION_SHAPES = ("pixels", "edge")
# The occlusion retrieval analysis (roll_jax.analysis.occlusion; `roll-analysis occlusion`).
OCCLUSION_DROP = 0.85  # Appendix A: "removing 85% of the pixels"
HURDLE_TASKS = ("hurdle_bottom", "hurdle_top")  # with a path around a wall (scenes.hurdle_path)


@dataclasses.dataclass(frozen=True)
class VAEConfig:
    """One beta-VAE (scene or object): architecture, loss weights and pre-training schedule."""

    latent_dim: int
    beta: float
    feature_dim: int  # 576 scene-VAE, 6 object-VAE ("Network Architectures")
    matching_coef: float = 0.0  # Table 2 for the object-VAE; the scene-VAE has none
    batch_size: int = 64  # Table 3: scene 64, object 128
    lr: float = 1e-3  # "Training schedules": learning rate 1e-3 (both VAEs)
    epochs: int = 2000  # "Training schedules": 2000 pre-training epochs
    batches_per_epoch: int = 25  # "Training schedules": 25 batches per epoch
    n_pretrain_images: int = 2000  # "Training schedules": 2000 images
    occlusion_drop: float = 0.5  # "Training schedules": drop 50% of the object's pixels
    # Not in the paper: which pixels the VAE matching loss drops. "pixels": each object pixel
    # independently (the reference code's); "edge": the share beyond a random straight edge,
    # as the arm hides one side of the object (losses.occlude_edge).
    occlusion_shape: str = "pixels"
    # Not in the paper. The reference code (ROLL/generate_LSTM_vae_only_dataset.py with the
    # launch files' occlusion_prob / occlusion_level) stores this share of the object
    # pre-training images with each pixel dropped with probability `pretrain_occluded_drop`,
    # once, when the dataset is made; the VAE (reconstruction, KL and matching) and the LSTM
    # then train on them like on the others. Per task: object_vae_config.
    pretrain_occluded_fraction: float = 0.0
    pretrain_occluded_drop: float = 0.5
    # Share of the object pre-training images that show states set to goals (`env.sample_goal`:
    # the hand placed at the object, on pickup mostly holding it in the air); the rest show the
    # object and the hand placed independently. The reference code pretrains on "set to goal"
    # images only (1.0); 0 keeps every placement of the goal space equally likely.
    pretrain_goal_share: float = 0.0
    # Where the hand is in the other object pre-training images: "random" (uniform in its
    # box, beside the object placed where it can be) or "away" (out of the camera's view: the
    # reference code's hurdle object-VAE / LSTM data, ROLL/generate_LSTM_vae_only_dataset.py,
    # hand at (-0.2, 0.2)). Per task: object_vae_config.
    pretrain_hand: str = "random"
    # Not in the paper: a second matching loss, between the codes of two renderings of one
    # pre-training object state with the hand at two random places in its box (the arm hides
    # the object as it does, where `occlusion_shape` drops pixels), times this coefficient;
    # 0 leaves it out. Measured and not adopted: docs/encoders.md, "The cpu preset's encoder
    # settings".
    arm_pair_coef: float = 0.0
    image_size: int = 48  # "Implementation details": 48 x 48 images
    # Not in the paper. Reference code: logvar = log(1e-3) + |dense|, a variance floor.
    min_variance: float = 1e-3
    # "sum": Gaussian log-likelihood with identity variance summed over pixels (the paper's
    # "equivalent to a mean-squared error"). "mean": the reference code's per-pixel mean, the
    # scale against which its beta and matching coefficients were tuned (= sum / 6912).
    recon_reduction: str = "sum"
    # The paper's matching loss has no stop-gradient (reference code default too); True
    # detaches the clean encoding so only the occluded one moves.
    matching_one_sided: bool = False
    # The KL weight per image. The reference code's reconstruction term is
    # F.mse_loss(inputs, decoded, reduction='elementwise_mean') with the decoder output (which
    # requires grad) as the second argument: in the PyTorch versions it pins (1.4; rlkit's
    # 0.4.1) that call SUMS over the batch and all pixels (ROLL/LSTM_model.py `logprob`, rlkit
    # rlkit/torch/vae/conv_vae.py; PyTorch issues #43228, #11149), while its KL is a batch MEAN
    # (ROLL/LSTM_model.py ~l.222). Divided by the batch size B, the objective the published
    # betas were tuned on is SSE(x) + (beta / B) KL(x) per image: True applies that (the
    # default), False applies beta per image (which collapses the object-VAE: docs/encoders.md,
    # "Losses").
    kl_per_batch_sum: bool = True
    # B of that division: the batch the published beta was tuned with (Table 3: scene 64,
    # object 128). A preset that trains on smaller batches for speed keeps the paper's
    # objective by keeping this; None = batch_size.
    kl_reference_batch: int | None = None
    # Not in the paper: how the convolutions are computed, "matmul" (one matmul per layer,
    # roll_jax/common/conv.py: the fast path on XLA:CPU; the first transposed conv as col2im),
    # "matmul_patches" (the patch form in every layer, for comparison) or "lax" (XLA's
    # convolutions). The parameters and values are the same (float32 roundoff).
    conv_impl: str = "matmul"
    # Not in the paper: a train step's gradient is the mean of the gradients of this many equal
    # slices of its batch (loss and metrics are batch means: the same values within float32
    # roundoff). XLA:CPU runs the slices' independent ops side by side on its threads; measured
    # in docs/encoders.md ("Speed on the CPU"). None (auto): 2 on a CPU backend where the
    # batch splits evenly, else 1 (the whole batch at once; accelerators gain nothing from it).
    grad_parts: int | None = None
    # Not in the paper: "deconv" is Table 3's decoder (dense -> 3x3x64 -> three transposed
    # convs); "broadcast" tiles the latent over a grid with coordinate channels (a spatial
    # broadcast decoder, roll_jax/encoders/models.py) before Table 3's last transposed conv.
    decoder: str = "deconv"

    def __post_init__(self):
        _check_positive(self, ("latent_dim", "feature_dim", "batch_size", "lr", "epochs",
                               "batches_per_epoch", "n_pretrain_images", "image_size",
                               "min_variance"))
        if self.grad_parts is not None and not (
                self.grad_parts > 0 and self.batch_size % self.grad_parts == 0):
            raise ValueError(f"VAEConfig.grad_parts={self.grad_parts!r} must be None or a "
                             f"positive divisor of batch_size={self.batch_size}")
        if self.beta < 0:
            raise ValueError(f"VAEConfig.beta must be >= 0, got {self.beta!r}")
        for name in ("matching_coef", "arm_pair_coef"):
            if getattr(self, name) < 0:
                raise ValueError(f"VAEConfig.{name} must be >= 0, got {getattr(self, name)!r}")
        if not 0.0 <= self.occlusion_drop <= 1.0:
            raise ValueError(f"VAEConfig.occlusion_drop must be in [0, 1], got {self.occlusion_drop!r}")
        for name in ("pretrain_occluded_fraction", "pretrain_occluded_drop",
                     "pretrain_goal_share"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"VAEConfig.{name} must be in [0, 1], got {getattr(self, name)!r}")
        if self.pretrain_hand not in PRETRAIN_HANDS:
            raise ValueError(f"VAEConfig.pretrain_hand must be one of {PRETRAIN_HANDS}, got "
                             f"{self.pretrain_hand!r}")
        if self.occlusion_shape not in OCCLUSION_SHAPES:
            raise ValueError(f"VAEConfig.occlusion_shape must be one of {OCCLUSION_SHAPES}, got "
                             f"{self.occlusion_shape!r}")
        if self.image_size != 48:
            raise ValueError(f"VAEConfig.image_size must be 48 (the conv stack maps 48 -> 15 -> 7 "
                             f"-> 3 and back), got {self.image_size!r}")
        if self.kl_reference_batch is not None and self.kl_reference_batch <= 0:
            raise ValueError(f"VAEConfig.kl_reference_batch must be positive or None, got "
                             f"{self.kl_reference_batch!r}")
        if self.recon_reduction not in ("sum", "mean"):
            raise ValueError(f"VAEConfig.recon_reduction must be 'sum' or 'mean', got {self.recon_reduction!r}")
        if self.decoder not in DECODERS:
            raise ValueError(f"VAEConfig.decoder must be one of {DECODERS}, got {self.decoder!r}")
        if self.conv_impl not in CONV_IMPLS:
            raise ValueError(f"VAEConfig.conv_impl must be one of {CONV_IMPLS}, got {self.conv_impl!r}")

    @property
    def image_shape(self) -> tuple[int, int, int]:
        return (self.image_size, self.image_size, 3)

    @property
    def effective_beta(self) -> float:
        """The KL weight per image that the loss applies (see `kl_per_batch_sum`)."""
        if not self.kl_per_batch_sum:
            return self.beta
        return self.beta / (self.kl_reference_batch or self.batch_size)


@dataclasses.dataclass(frozen=True)
class LSTMConfig:
    """The object LSTM g_psi on top of the frozen object-VAE's latent means."""

    hidden: int = 128  # "Network Architectures": hidden size 128
    layers: int = 2  # "Network Architectures": 2 layers
    out_dim: int = 6  # = object-VAE latent size (Table 3): the output reconstructs the input
    matching_coef: float = 50.0  # Table 3: LSTM matching loss coefficient
    ae_coef: float = 1.0  # paper: unweighted L^ae (reference code used 0.5)
    batch_size: int = 128  # "Training schedules": pre-training batch size 128
    online_batch_size: int = 25  # "Training schedules": online batches of 25 trajectories
    lr: float = 1e-3  # "Training schedules": learning rate 1e-3
    epochs: int = 2000  # "Training schedules": 2000 pre-training epochs (auto-encoder loss only)
    batches_per_epoch: int = 25  # "Training schedules": 25 batches per epoch
    occlusion_drop: float = 0.5  # "Training schedules": drop 50% of the object's pixels
    # "Robustness to Object Occlusions": the occluded frame t is drawn with t > 1 (1-based),
    # i.e. 0-based index >= 1. (The reference code drew t >= 10 of 50.)
    min_occlusion_t: int = 1
    matching_one_sided: bool = False  # see VAEConfig.matching_one_sided
    # "Training schedules", online LSTM training: (until env step, every k steps, n batches).
    online_schedule: tuple[tuple[int, int, int], ...] = (
        (5_000, 500, 80),
        (50_000, 500, 20),
        (2**62, 1000, 20),
    )

    def __post_init__(self):
        _check_positive(self, ("hidden", "layers", "out_dim", "batch_size", "online_batch_size",
                               "lr", "epochs", "batches_per_epoch", "min_occlusion_t"))
        for name in ("matching_coef", "ae_coef"):
            if getattr(self, name) < 0:
                raise ValueError(f"LSTMConfig.{name} must be >= 0, got {getattr(self, name)!r}")
        if not 0.0 <= self.occlusion_drop <= 1.0:
            raise ValueError(f"LSTMConfig.occlusion_drop must be in [0, 1], got {self.occlusion_drop!r}")
        for until, every, batches in self.online_schedule:
            if until <= 0 or every <= 0 or batches <= 0:
                raise ValueError(f"LSTMConfig.online_schedule entries must be positive, got "
                                 f"{(until, every, batches)!r}")

    def online_batches(self, env_step: int) -> tuple[int, int]:
        """(train every k env steps, batches per training) at `env_step` (Python int)."""
        for until, every, batches in self.online_schedule:
            if env_step < until:
                return every, batches
        return self.online_schedule[-1][1:]


def scene_vae_config(task: str, algo: str = "roll", **overrides) -> VAEConfig:
    """Scene-VAE of `task` for ROLL or Skew-Fit (Table 2, Table 3)."""
    _check_task(task)
    if algo not in ALGOS:
        raise ValueError(f"unknown algo {algo!r}; expected one of {ALGOS}")
    values = {
        "latent_dim": _SCENE_LATENT[algo][task],  # Table 2
        "beta": _SCENE_BETA[task],  # Table 2
        "feature_dim": SCENE_FEATURE_DIM,
        "matching_coef": 0.0,  # the scene-VAE uses the plain beta-VAE loss ("Training schedules")
        "batch_size": 64,  # Table 3
        "kl_reference_batch": 64,  # Table 3: the batch beta was tuned with (see effective_beta)
    }
    return VAEConfig(**{**values, **overrides})


def object_vae_config(task: str, **overrides) -> VAEConfig:
    """Object-VAE of `task` (Table 2 matching coefficient, Table 3 for the rest)."""
    _check_task(task)
    values = {
        "latent_dim": 6,  # Table 3
        "beta": 20.0,  # Table 3
        "feature_dim": OBJECT_FEATURE_DIM,
        "matching_coef": _VAE_MATCHING_COEF[task],  # Table 2
        "batch_size": 128,  # Table 3
        "kl_reference_batch": 128,  # Table 3: the batch beta was tuned with (see effective_beta)
        "pretrain_occluded_fraction": _PRETRAIN_OCCLUDED_FRACTION[task],  # reference code
        "pretrain_hand": _PRETRAIN_HAND[task],  # reference code
        "pretrain_goal_share": _PRETRAIN_GOAL_SHARE[task],  # reference code
    }
    return VAEConfig(**{**values, **overrides})


def lstm_config(task: str, **overrides) -> LSTMConfig:
    """Object LSTM of `task`: the same values for every task (Table 3)."""
    _check_task(task)
    return LSTMConfig(**overrides)
