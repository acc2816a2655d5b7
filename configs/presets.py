"""Presets: named sets of overrides over the paper's tagged values (the defaults of every config).

- `paper`: nothing overridden; the paper's sizes and schedules (GPU-sized: 300k-400k env
  steps, SAC 400-300 at batch 1024).
- `cpu`: sized by measurement for a 2-core CPU (docs/training.md#presets): the paper's
  method, smaller networks, batches and run, shorter pretraining (with a smaller object-VAE
  KL weight and VAE matching coefficient, a faster U-Net learning rate), a
  frozen-after-pretraining scene-VAE for ROLL, cached latents refreshed on a schedule. Each
  departure says why in a line.
- `smoke`: the whole path end to end in minutes (tests, `reproduce --preset smoke`); far too
  short to learn.

Each preset maps a config group to field overrides: "train" (TrainConfig), "train_roll"
(TrainConfig, ROLL runs and their ablations only), "sac", "scene_vae",
"object_vae" (VAEConfig), "lstm", "segmentation", "rollout" (train.py --algo random) and
"occlusion" (the defaults of `roll-analysis occlusion`).
The values are plain data; configs/train.py and configs/segmentation.py apply them. A value
that differs between tasks is a `PerTask`, resolved by `Preset.for_task` (`TASK_DEFAULT`: the
task keeps its own value).
"""

from __future__ import annotations

import dataclasses
import types
from collections.abc import Mapping

GROUPS = ("train", "train_roll", "sac", "scene_vae", "object_vae", "lstm", "segmentation",
          "rollout", "occlusion")


class _TaskDefault:
    """The task's own value (configs/TASK.py, or the tagged default): `for_task` leaves the
    field out."""

    def __repr__(self):
        return "TASK_DEFAULT"


TASK_DEFAULT = _TaskDefault()


@dataclasses.dataclass(frozen=True)
class PerTask:
    """A preset value measured per task: one entry for every task (`TASK_DEFAULT`: the
    task's own value)."""
    values: Mapping[str, object]

    def __post_init__(self):
        object.__setattr__(self, "values", types.MappingProxyType(dict(self.values)))

    def get(self, task: str, where: str):
        if task not in self.values:
            raise ValueError(f"{where} has no value for task {task!r} (it has "
                             f"{', '.join(self.values)})")
        return self.values[task]


@dataclasses.dataclass(frozen=True)
class Preset:
    name: str
    doc: str
    groups: Mapping[str, Mapping]

    def __post_init__(self):
        unknown = set(self.groups) - set(GROUPS)
        if unknown:
            raise ValueError(f"preset {self.name!r}: unknown group(s) {sorted(unknown)}; "
                             f"expected some of {GROUPS}")
        object.__setattr__(self, "groups", types.MappingProxyType(
            {g: types.MappingProxyType(dict(self.groups.get(g, {}))) for g in GROUPS}))

    def __getitem__(self, group: str) -> Mapping:
        """The group's overrides as written (PerTask values unresolved)."""
        return self.groups[group]

    def for_task(self, group: str, task: str) -> dict:
        """The group's overrides for `task`: each PerTask value resolved (a TASK_DEFAULT one
        left out)."""
        resolved = {k: v.get(task, f"preset {self.name!r} {group}.{k}") if isinstance(v, PerTask)
                    else v for k, v in self.groups[group].items()}
        return {k: v for k, v in resolved.items() if v is not TASK_DEFAULT}


PAPER = Preset("paper", "the paper's values (appendix tables); GPU-sized", {
    "rollout": {"n_envs": 64, "episodes": 4, "video_size": 128},
    "occlusion": {"n_train": 500, "n_eval": 200, "lstm_steps": 10000, "vae_steps": 5000},
})

CPU = Preset("cpu", "sized for a 2-core CPU: learns puck pushing within a session", {
    # Each value's reason in one line; the figures behind it: docs/training.md#presets,
    # docs/encoders.md#the-cpu-presets-encoder-settings, docs/segmentation.md#the-cpu-preset.
    "train": {
        "total_env_steps": 50_000,  # paper 300k-400k: what fits a session on 2 cores
        "n_eval_goals": 16,  # paper 32: half the variance of 8 for little time
        "eval_every_epochs": 4,  # every 2k env steps: the test envs step in 1 chunk of 4
        "checkpoint_every_epochs": 20,  # each writes the 50k-frame buffer, slowing a chunk
        "skew_num_latents": 4,  # paper 10: Skew-Fit's log p(x) decodes per stored frame
        "refresh_every_epochs": 4,  # the buffer's cached LSTM latents every 2k env steps
        "reward_norm": "l2",  # the reference code's -||z' - z_g|| (paper: its square)
        "sac_schedule": "step",  # updates between the steps: the oracle learns faster
    },
    "train_roll": {
        # ROLL's scene-VAE trains in pretraining only: online it costs 2-3x per chunk and
        # changed nothing on the door (+0.004 +- 0.009 rad); Skew-Fit keeps its schedule
        "vae_schedule": "none",
        # so on the door it must see the hand off the handle, where no goal image shows it:
        # hand R^2 0.39 -> 0.69, ROLL at 50k 0.381 -> 0.227 rad (docs/results.md)
        "scene_pretrain_data": PerTask({"puck_push": TASK_DEFAULT, "hurdle_bottom": TASK_DEFAULT,
                                        "hurdle_top": TASK_DEFAULT, "door_open": "placements",
                                        "pickup": TASK_DEFAULT}),
    },
    "sac": {
        "hidden": (128, 128),  # paper 400-300: ~8x fewer FLOPs per update
        "batch_size": 256,  # paper 1024
        "replay_size": 50_000,  # paper 100k: the run is 50k env steps
        "learning_starts": 2_000,  # paper 10k: 1/25 of the run, as 10k is of 250k
    },
    "scene_vae": {
        "epochs": 400,  # paper 2000 x 25 batches: 10k steps locate the puck (R^2 0.74)
        "batch_size": 64,
        "n_pretrain_images": 2000,
    },
    "object_vae": {
        # paper 2000 x 25 batches: the push latents rank best after 500-1000 steps;
        # pickup's ranking needs 3000
        "epochs": PerTask({"puck_push": 40, "hurdle_bottom": 40, "hurdle_top": 40,
                           "door_open": 40, "pickup": 120}),
        "batch_size": 64,  # paper 128; the KL keeps beta / 128 (kl_reference_batch)
        "beta": 5.0,  # Table 3's 20 lets the latent line of object positions fold
        "n_pretrain_images": 2000,
        # 1% of Table 2's coefficient: the paper's shrinks the latents far off the prior
        "matching_coef_factor": 0.01,
        # the reference code's 0.3 straightens the hurdles' codes and blurs puck_push's
        "pretrain_occluded_fraction": PerTask({"puck_push": 0.0, "hurdle_bottom": 0.3,
                                               "hurdle_top": 0.3, "door_open": 0.0,
                                               "pickup": 0.0}),
        # decoder: Table 3's (the broadcast decoder's policies finish less precisely)
    },
    "lstm": {
        "epochs": 80,  # paper 2000 x 25 batches: 2000 steps make one step encode a goal
        "batch_size": 32,  # paper 128
        "online_batch_size": 16,  # paper 25 (the reference code: 16)
        # paper (5k, 500, 80), (50k, 500, 20), then (1000, 20): a quarter of the batches
        "online_schedule": ((5_000, 500, 20), (2**62, 1000, 10)),
    },
    "segmentation": {
        "n_frames": 1000,  # paper 2000/4000 MOG2 frames
        # pickup 16: it masks the cube held in the gripper (its goal images)
        "unet_features": PerTask({"puck_push": 8, "hurdle_bottom": 8, "hurdle_top": 8,
                                  "door_open": 8, "pickup": 16}),
        # paper 30: 24 lower the arm's leakage at width 8; pickup's width 16 needs 8
        "unet_epochs": PerTask({"puck_push": 24, "hurdle_bottom": 24, "hurdle_top": 24,
                                "door_open": 24, "pickup": 8}),
        "unet_lr": 0.03,  # paper SGD 1e-3 leaves the U-Net under-confident in few epochs
        "eval_states": 256,  # paper 500
    },
    "rollout": {"n_envs": 8, "episodes": 2, "video_size": 128},
    "occlusion": {"n_train": 200, "n_eval": 100, "lstm_steps": 2000, "vae_steps": 1000},
})

SMOKE = Preset("smoke", "the whole path in minutes (tests); learns nothing", {
    # Two chunks (3 evaluations: 0, 500, 1000 env steps).
    "train": {"total_env_steps": 1000, "epoch_env_steps": 500, "eval_every_epochs": 1,
              "checkpoint_every_epochs": 1, "n_eval_goals": 4, "vae_schedule": "smoke",
              # skewed Skew-Fit sampling from the second chunk on (reference code: after epoch 10)
              "skew_num_latents": 2, "skew_start_epoch": 0},
    "sac": {"hidden": (32, 32), "batch_size": 64, "replay_size": 2_000, "learning_starts": 200},
    # 50 VAE pre-training steps on batches of 32.
    "scene_vae": {"epochs": 10, "batches_per_epoch": 5, "batch_size": 32, "n_pretrain_images": 200},
    "object_vae": {"epochs": 10, "batches_per_epoch": 5, "batch_size": 32, "n_pretrain_images": 200},
    "lstm": {"epochs": 10, "batches_per_epoch": 5, "batch_size": 16, "online_batch_size": 4,
             "online_schedule": ((2**62, 500, 2),)},
    "segmentation": {"n_frames": 300, "n_envs": 30, "unet_features": 8, "unet_epochs": 3,
                     "eval_states": 64},
    "rollout": {"n_envs": 4, "episodes": 1, "video_size": 128},
    "occlusion": {"n_train": 64, "n_eval": 64, "lstm_steps": 200, "vae_steps": 200},
})

_ALL = {p.name: p for p in (SMOKE, CPU, PAPER)}
PRESETS = tuple(_ALL)


def get(name: str) -> Preset:
    """The preset called `name`; ValueError naming the known ones otherwise."""
    if name not in _ALL:
        raise ValueError(f"unknown preset {name!r}; expected one of {', '.join(PRESETS)}")
    return _ALL[name]
