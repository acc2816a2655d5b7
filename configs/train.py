"""The full training config: one frozen dataclass composed of the component configs.

`make_config(task, algo, preset, **overrides)` is the only constructor the CLIs use; the
per-task modules (configs/puck_push.py, ...) hold each task's values (horizon, run length,
Skew-Fit alpha and schedule, Table 2), this module holds what all tasks share.
"""

from __future__ import annotations

import dataclasses
import importlib

from configs.encoders import (
    LSTMConfig,
    VAEConfig,
    lstm_config,
    object_vae_config,
    scene_vae_config,
)
from configs import presets
from configs.presets import PRESETS
from configs.sac import SACConfig
from configs.segmentation import SegmentationConfig, segmentation_config

TASKS = ("puck_push", "hurdle_bottom", "hurdle_top", "door_open", "pickup")
# "oracle": the same loop with the true hand and object positions for latents and the true
# distance as reward (no images encoded): a check of SAC, HER and the loop themselves.
ALGOS = ("roll", "skewfit", "oracle")
REWARD_NORMS = ("squared", "l2")
SAC_SCHEDULES = ("epoch", "step")

# rlkit vae_schedules (Skew-Fit appendix C.5): epoch -> (train?, batches); "none": the scene-VAE
# is trained in pretraining only (the cpu preset's ROLL).
VAE_SCHEDULES = ("custom_schedule", "custom_schedule_2", "smoke", "none")


# The string-valued TrainConfig fields and what each may be.
CHOICES = {"vae_schedule": VAE_SCHEDULES,
           "scene_pretrain_data": ("random_policy", "goals", "region", "placements"),
           "reward_norm": REWARD_NORMS, "prior_goals": ("standard", "buffer"),
           "achieved_encoding": ("sequence", "single", "held"),
           "sac_schedule": SAC_SCHEDULES}


def vae_schedule(name: str, epoch: int) -> int:
    """Scene-VAE batches to train after `epoch` (0 = no training), rlkit's schedules."""
    if name == "custom_schedule":
        if epoch < 10:
            return 1000
        if epoch < 300:
            return 200
        return 200 if epoch % 3 == 0 else 0
    if name == "custom_schedule_2":
        if epoch < 10:
            return 1000
        if epoch < 100:
            return 200
        return 200 if epoch % 2 == 0 else 0
    if name == "smoke":  # CPU smoke runs: a little training every epoch, same code path
        return 5
    if name == "none":
        return 0
    raise ValueError(f"unknown VAE schedule {name!r}; expected one of {VAE_SCHEDULES}")


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    task: str
    algo: str
    preset: str
    horizon: int  # Table 2: trajectory length
    total_env_steps: int  # per seed; reference code launch files: epochs x 500 steps
    epoch_env_steps: int = 500  # rlkit num_expl_steps_per_train_loop (one compiled chunk)
    n_envs: int = 10  # envs per seed stepping together (ours; 2 SAC updates per transition kept)
    seeds: int = 1
    eval_every_epochs: int = 10
    n_eval_goals: int = 32  # test goals per evaluation (per seed)
    skew_alpha: float = -1.0  # Table 2: Skew-Fit alpha for the scene-VAE
    skew_num_latents: int = 10  # rlkit Skew-Fit priority: importance samples per image
    # Skew-Fit samples its scene-VAE batches and its goals uniformly from the buffer until this
    # epoch and p(x)^alpha after it: the reference code's replay_buffer_kwargs
    # start_skew_epoch=10 in every Skew-Fit launch file (rlkit examples/skewfit; ROLL's
    # examples/skewfit), read as OnlineVaeRelabelingBuffer's `skew = epoch > start_skew_epoch`.
    skew_start_epoch: int = 10
    vae_schedule: str = "custom_schedule_2"  # Skew-Fit appendix C.5 (rlkit vae_schedules)
    vae_online_batch: int = 64  # Table 3: scene-VAE batch size
    # Scene-VAE pretraining images: "random_policy" ("Training schedules": a random policy's
    # frames), "goals" (states set to random goals: the reference code's puck_push launch file,
    # oracle_dataset_using_set_to_goal=True) or "region" (hand and object each over the
    # object's region: the reference's hurdle corridor sampler); per task in configs/<task>.py.
    scene_pretrain_data: str = "random_policy"
    # The buffer's cached goal latents (LSTM outputs) are recomputed after online encoder
    # training every this many epochs (1: after each training, as rlkit refreshes its latents).
    refresh_every_epochs: int = 1
    # Reward -||z' - z_g||^2 ("squared", the paper's equation) or -||z' - z_g|| ("l2", the
    # reference code's LSTM_wrapped_env.py ~l.303).
    reward_norm: str = "squared"
    # When SAC updates: "epoch", all updates_per_step x epoch_env_steps of them after the
    # epoch's collection (rlkit's order, which Skew-Fit and ROLL ran); "step", n_envs x
    # updates_per_step after every vectorised env step (the same number per transition, the
    # policy fresher while it collects).
    sac_schedule: str = "epoch"
    # ROLL's prior goals (exploration and HER's prior share): "standard", N(0, I) through the
    # LSTM (Algorithm 1; the reference launch files' sample_from_true_prior=True); "buffer",
    # N(mean, std) of the stored frame latents (rlkit's dist_mu / dist_std, the reference
    # code's sample_from_true_prior=False).
    prior_goals: str = "standard"
    # The achieved goals on the reward's other side: "held", each frame one LSTM step from the
    # zero state, the same function as a goal image's, except that a frame whose segmented
    # image shows fewer than held_min_pixels object pixels (the arm over the object) keeps
    # the last achieved goal that showed it; "single", every frame one step (the reference
    # code's refresh_latents -> LSTM_wrapped_env._encode_lstm); "sequence", the LSTM run over
    # the episode so far (the paper's z_t = g(z_hat_1..t)). "held" because it measured best:
    # at 50k hurdle_top 5.7 cm (10.1 on base seed 1) against 10.0 ("single") and 12.5
    # ("sequence"), hurdle_bottom 2.1 against 3.9 ("sequence"); puck_push 0.3 cm worse
    # (docs/results.md, "Reward encoding"). --no-object-vae segments nothing, so it takes
    # "single".
    achieved_encoding: str = "held"
    # 10: half the fewest object pixels a visible puck shows anywhere along hurdle_top's
    # corridor (20; 20-55 along it, docs/encoders.md).
    held_min_pixels: int = 10
    # Ablations (paper section "Ablations"), flags on --algo roll.
    matching_loss: bool = True
    use_lstm: bool = True
    use_object_vae: bool = True
    keep_checkpoints: int = 2
    # The train state (replay buffer included) is checkpointed every this many epochs and at
    # the end; a resumed run continues from the last one.
    checkpoint_every_epochs: int = 10
    segmentation: SegmentationConfig = dataclasses.field(default_factory=SegmentationConfig)
    scene_vae: VAEConfig | None = None
    object_vae: VAEConfig | None = None
    lstm: LSTMConfig = dataclasses.field(default_factory=LSTMConfig)
    sac: SACConfig = dataclasses.field(default_factory=SACConfig)

    def __post_init__(self):
        if self.task not in TASKS:
            raise ValueError(f"unknown task {self.task!r}; expected one of {', '.join(TASKS)}")
        if self.algo not in ALGOS:
            raise ValueError(f"unknown algo {self.algo!r}; expected one of {', '.join(ALGOS)}")
        if self.preset not in PRESETS:
            raise ValueError(f"unknown preset {self.preset!r}; expected one of {', '.join(PRESETS)}")
        for name in ("horizon", "total_env_steps", "epoch_env_steps", "n_envs", "seeds",
                     "eval_every_epochs", "n_eval_goals", "vae_online_batch", "skew_num_latents",
                     "keep_checkpoints", "refresh_every_epochs", "checkpoint_every_epochs"):
            if getattr(self, name) <= 0:
                raise ValueError(f"TrainConfig.{name} must be positive, got {getattr(self, name)}")
        if self.epoch_env_steps % (self.n_envs * self.horizon):
            raise ValueError(
                f"TrainConfig.epoch_env_steps={self.epoch_env_steps} must be a multiple of "
                f"n_envs * horizon = {self.n_envs} * {self.horizon}: a chunk runs whole episodes")
        if self.skew_start_epoch < 0:
            raise ValueError(f"TrainConfig.skew_start_epoch must be >= 0, got {self.skew_start_epoch}")
        if self.total_env_steps % self.epoch_env_steps:
            raise ValueError(f"TrainConfig.total_env_steps={self.total_env_steps} must be a "
                             f"multiple of epoch_env_steps={self.epoch_env_steps}")
        for name, allowed in CHOICES.items():
            if getattr(self, name) not in allowed:
                raise ValueError(f"unknown {name} {getattr(self, name)!r}; expected one of "
                                 f"{', '.join(allowed)}")
        if self.sac.learning_starts >= self.total_env_steps:
            raise ValueError(f"sac.learning_starts={self.sac.learning_starts} is not below "
                             f"total_env_steps={self.total_env_steps}: the run would never learn")
        if self.eval_every_epochs > self.n_epochs:
            raise ValueError(f"eval_every_epochs={self.eval_every_epochs} is longer than the run "
                             f"(total_env_steps={self.total_env_steps} = {self.n_epochs} epochs)")
        if self.sac.replay_size < self.epoch_env_steps:
            raise ValueError(f"sac.replay_size={self.sac.replay_size} is smaller than one chunk "
                             f"(epoch_env_steps={self.epoch_env_steps})")
        if (self.scene_vae is not None and self.scene_vae.grad_parts is not None
                and self.vae_online_batch % self.scene_vae.grad_parts):
            raise ValueError(f"vae_online_batch={self.vae_online_batch} does not split into the "
                             f"scene-VAE's grad_parts={self.scene_vae.grad_parts} equal slices")
        ablated = [n for n, on in (("--no-matching-loss", not self.matching_loss),
                                   ("--no-lstm", not self.use_lstm),
                                   ("--no-object-vae", not self.use_object_vae)) if on]
        if self.algo != "roll" and ablated:
            raise ValueError(f"{', '.join(ablated)} ablate ROLL; they contradict --algo {self.algo}")
        if not self.use_lstm and not self.use_object_vae:
            raise ValueError("--no-lstm and --no-object-vae together remove the whole object "
                             "encoder; pick one")
        if self.achieved_encoding == "held" and self.algo == "roll" and not self.use_object_vae:
            raise ValueError("achieved_encoding='held' counts the object's pixels in the "
                             "segmented image, which --no-object-vae does not make")
        if self.held_min_pixels <= 0:
            raise ValueError(f"TrainConfig.held_min_pixels must be positive, got "
                             f"{self.held_min_pixels}")
        if self.algo == "roll" and self.use_lstm and self.scene_vae is not None:
            frame = self.scene_vae if not self.use_object_vae else self.object_vae
            if frame is not None and self.lstm.out_dim != frame.latent_dim:
                which = "scene" if not self.use_object_vae else "object"
                raise ValueError(f"lstm.out_dim={self.lstm.out_dim} must equal the {which}-VAE "
                                 f"latent size {frame.latent_dim}: the LSTM reconstructs its input")

    @property
    def n_epochs(self) -> int:
        return self.total_env_steps // self.epoch_env_steps

    @property
    def episodes_per_epoch(self) -> int:
        """Episodes each env runs per chunk."""
        return self.epoch_env_steps // (self.n_envs * self.horizon)

    @property
    def updates_per_vector_step(self) -> int:
        """SAC updates per step of all envs: updates_per_step per collected transition."""
        return self.sac.updates_per_step * self.n_envs

    @property
    def scene(self) -> VAEConfig:
        assert self.scene_vae is not None
        return self.scene_vae

    def to_json(self) -> dict:
        return dataclasses.asdict(self)


def _task_module(task: str):
    if task not in TASKS:
        raise ValueError(f"unknown task {task!r}; expected one of {', '.join(TASKS)}")
    return importlib.import_module(f"configs.{task}")


def _object_vae(task: str, over) -> VAEConfig:
    """object_vae_config with a preset's overrides; "matching_coef_factor" scales the task's
    Table 2 VAE matching coefficient (the cpu preset's)."""
    over = dict(over)
    factor = over.pop("matching_coef_factor", None)
    if factor is not None:
        over["matching_coef"] = factor * object_vae_config(task).matching_coef
    return object_vae_config(task, **over)


def make_config(task: str, algo: str = "roll", preset: str = "paper", **overrides) -> TrainConfig:
    """The config of `task` x `algo` x `preset`; keyword overrides win (nested configs are
    replaced whole: pass e.g. sac=dataclasses.replace(cfg.sac, batch_size=256))."""
    mod = _task_module(task)
    pre = presets.get(preset)
    values = dict(mod.TRAIN)
    values.update(
        segmentation=segmentation_config(task, preset),
        scene_vae=scene_vae_config(task, "skewfit" if algo == "skewfit" else "roll",
                                   **pre.for_task("scene_vae", task)),
        object_vae=_object_vae(task, pre.for_task("object_vae", task)),
        lstm=lstm_config(task, **pre.for_task("lstm", task)),
        sac=SACConfig(**pre.for_task("sac", task)),
    )
    values.update(pre.for_task("train", task))
    if algo == "roll":
        values.update(pre.for_task("train_roll", task))
    values.update(overrides)
    if not values.get("use_object_vae", True) and "lstm" not in overrides:
        # --no-object-vae: the LSTM runs on (and reconstructs) scene-VAE latents.
        values["lstm"] = dataclasses.replace(values["lstm"],
                                             out_dim=values["scene_vae"].latent_dim)
    if (not values.get("use_object_vae", True) and "achieved_encoding" not in overrides
            and values.get("achieved_encoding", TrainConfig.achieved_encoding) == "held"):
        # --no-object-vae segments nothing, so no object pixels are counted: each frame is
        # its own achieved goal ("single"). Asking for "held" with it is refused (validate).
        values["achieved_encoding"] = "single"
    return TrainConfig(task=task, algo=algo, preset=preset, **values)


# TrainConfig fields the commands set with their own flags, not with --set.
FLAG_FIELDS = {"task": "--task", "algo": "--algo", "preset": "--preset", "seeds": "--seeds",
               "matching_loss": "--no-matching-loss", "use_lstm": "--no-lstm",
               "use_object_vae": "--no-object-vae"}


def build_config(task: str, algo: str, preset: str, seeds: int = 1, overrides=(),
                 matching_loss: bool = True, use_lstm: bool = True,
                 use_object_vae: bool = True) -> TrainConfig:
    """The config the commands run (train.py, the reproduction grid, pretraining): `make_config`
    with `--set KEY=VALUE` / `--set GROUP.KEY=VALUE` overrides (strings) and the ablation
    flags; ValueError on anything unknown, mistyped or contradictory (naming it; the nearest
    valid name for a misspelt one). Light: nothing but configs/ is imported."""
    from configs.overrides import check_field, parse_overrides, unknown

    over = parse_overrides(overrides)
    top = dict(over.pop("", {}))
    for name, value in top.items():
        if name in FLAG_FIELDS:
            raise ValueError(f"--set {name}: given by the command's {FLAG_FIELDS[name]}, not --set")
        check_field(TrainConfig, name, value)
    top.update(seeds=seeds, matching_loss=matching_loss, use_lstm=use_lstm,
               use_object_vae=use_object_vae)
    base = make_config(task, algo, preset)
    groups = [f.name for f in dataclasses.fields(TrainConfig)
              if dataclasses.is_dataclass(getattr(base, f.name))]
    for group, fields in over.items():
        if group not in groups:
            raise ValueError(f"--set {group}.{next(iter(fields))}: "
                             f"{unknown(group, groups, 'config group')}")
        sub = getattr(base, group)
        for name, value in fields.items():
            check_field(type(sub), name, value, f"{group}.{name}")
        top[group] = dataclasses.replace(sub, **fields)
    return make_config(task, algo, preset, **top)


def _tuples(x):
    """JSON lists back to the tuples the configs hold (nested: e.g. LSTM schedules)."""
    return tuple(_tuples(v) for v in x) if isinstance(x, list) else x


def config_from_json(values: dict) -> TrainConfig:
    """The TrainConfig a run wrote to its config.json (`dataclasses.asdict` as JSON)."""
    import typing

    hints = typing.get_type_hints(TrainConfig)
    names = {f.name for f in dataclasses.fields(TrainConfig)}
    unknown = set(values) - names
    if unknown:
        raise ValueError(f"config.json: unknown TrainConfig field(s) {sorted(unknown)}")
    fields = {}
    for name, value in values.items():
        # `X | None` fields: the dataclass among the union's members
        kinds = [k for k in (typing.get_args(hints[name]) or (hints[name],))
                 if dataclasses.is_dataclass(k)]
        if kinds and isinstance(value, dict):
            value = kinds[0](**{k: _tuples(v) for k, v in value.items()})
        fields[name] = _tuples(value)
    return TrainConfig(**fields)
