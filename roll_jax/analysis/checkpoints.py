"""Pretrained encoders as the analyses' inputs: a `python -m roll_jax.encoders.pretrain --out`
directory (segmentation/, encoders/, pretrain.json) or a `train.py --out` run directory (its
config.json, and the segmentation and encoders its inputs.json names) loaded with the config
they were made with, and the encoders as numpy callables over fixed-size batches."""

from __future__ import annotations

import functools
import json
import os
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from configs.train import build_config
from roll_jax.encoders import models, pretrain
from roll_jax.encoders.goal_encoding import Frozen, GoalEncoder, goal_encoder
from roll_jax.segmentation import pipeline


def load_checkpoint(ckpt: str, task: str | None = None, preset: str | None = None):
    """(cfg, Pretrained, seg params) of a pretraining or a run directory
    (`checkpoint_config`, `checkpoint_paths`)."""
    cfg = checkpoint_config(ckpt, task, preset)
    seg_dir, enc_dir = checkpoint_paths(ckpt)
    pre = pretrain.load(enc_dir, cfg)
    seg, _ = pipeline.load(seg_dir, cfg.task)
    return cfg, pre, seg


def is_run(ckpt: str) -> bool:
    """A train.py run directory (config.json) rather than a pretraining one."""
    return os.path.exists(os.path.join(ckpt, "config.json"))


def checkpoint_paths(ckpt: str) -> tuple[str, str]:
    """(segmentation dir, encoders dir): a pretraining directory's own; a run's, as its
    inputs.json names them (its own sub-directories, or the --seg-ckpt / --enc-ckpt it was
    given)."""
    if is_run(ckpt):
        from roll_jax.training import run_dir

        inputs = run_dir.read_inputs(ckpt)
        return (inputs.get("seg_ckpt", os.path.join(ckpt, "segmentation")),
                inputs.get("enc_ckpt", os.path.join(ckpt, "encoders")))
    return os.path.join(ckpt, "segmentation"), os.path.join(ckpt, "encoders")


def checkpoint_config(ckpt: str, task: str | None = None, preset: str | None = None):
    """The config a directory's encoders were made with: a run's config.json; a pretraining
    directory's preset (or `preset`), algorithm (ROLL where it does not say) and `--set`
    overrides from DIR/pretrain.json (`checkpoint_preset` refuses a directory that says
    neither)."""
    if is_run(ckpt):
        from roll_jax.training import run_dir

        cfg = run_dir.read_config(ckpt)
        if task is not None and cfg.task != task:
            raise ValueError(f"run {ckpt} trained task {cfg.task!r}, not {task!r}")
        if preset is not None and cfg.preset != preset:
            raise ValueError(f"run {ckpt} was trained with preset {cfg.preset!r}, not "
                             f"{preset!r} (leave --preset out: a run's config.json says it)")
        return cfg
    task = checkpoint_task(ckpt, task)
    info = _pretrain_info(ckpt)
    return build_config(task, info.get("algo", "roll"), checkpoint_preset(ckpt, task, preset),
                        overrides=info.get("overrides", []))


def _pretrain_info(ckpt: str) -> dict:
    meta = os.path.join(ckpt, "pretrain.json")
    if not os.path.exists(meta):
        return {}
    with open(meta) as f:
        return json.load(f)


def checkpoint_task(ckpt: str, task: str | None = None) -> str:
    """`task`, or the one the directory was made for (pretrain.json, config.json); refuses a
    directory of another task, and a directory that does not say when `task` is None."""
    if is_run(ckpt):
        from roll_jax.training import run_dir

        saved = run_dir.read_config(ckpt).task
    else:
        saved = _pretrain_info(ckpt).get("task")
    if task is not None and saved not in (None, task):
        raise ValueError(f"checkpoint {ckpt} was made for task {saved!r}, not {task!r}")
    if task is None and saved is None:
        raise ValueError(f"{ckpt} has no pretrain.json (roll-pretrain writes one) nor "
                         f"config.json (a train.py run): give --task")
    return task or saved


def checkpoint_preset(ckpt: str, task: str | None = None, preset: str | None = None) -> str:
    """`preset`, or the one the directory was made with (a pretraining directory's
    pretrain.json, a run's config.json); refuses a checkpoint of another `task`, and a
    directory that says neither: its encoders' sizes depend on the preset, a guess would load
    them with the wrong config."""
    if is_run(ckpt):
        return checkpoint_config(ckpt, task, preset).preset
    info = _pretrain_info(ckpt)
    if task is not None:
        checkpoint_task(ckpt, task)  # refuses another task's checkpoint
    if preset is None and "preset" not in info:
        raise ValueError(f"{ckpt} has no pretrain.json (roll-pretrain writes one) nor "
                         f"config.json (a train.py run) to say which preset its encoders "
                         f"were pretrained with: give --preset")
    return preset or info["preset"]


def batched(fn: Callable, x, chunk: int = 512):
    """fn over the leading axis of x in fixed-size chunks (the last one padded, so fn compiles
    at most once); returns a numpy array."""
    x = np.asarray(x)
    n = x.shape[0]
    if n <= chunk:
        return np.asarray(fn(jnp.asarray(x)))
    out = []
    for i in range(0, n, chunk):
        part = x[i:i + chunk]
        m = part.shape[0]
        if m < chunk:
            part = np.concatenate([part, np.repeat(part[-1:], chunk - m, 0)])
        out.append(np.asarray(fn(jnp.asarray(part)))[:m])
    return np.concatenate(out)


@functools.partial(jax.jit, static_argnames=("cfg",))
def vae_means(params, cfg, rgb):
    """`models.encode_mean`, jitted (one program per config and batch shape)."""
    return models.encode_mean(params, cfg, rgb)


@functools.partial(jax.jit, static_argnames=("enc",))
def _object_encode(enc: GoalEncoder, frozen, scene_params, lstm_params, rgb):
    return enc.encode_goal_images(frozen, scene_params, lstm_params, rgb)


@functools.partial(jax.jit, static_argnames=("enc",))
def frame_encode(enc: GoalEncoder, frozen, scene_params, rgb):
    """The per-frame latents of images that the goal encoder feeds its LSTM (jitted)."""
    return enc.frame_latents(frozen, scene_params, enc.goal_images(frozen, rgb))


def model_encoders(cfg, pre, seg, chunk: int = 512) -> tuple[Callable, Callable]:
    """(encode_scene, encode_object) of a pretrained checkpoint: the scene-VAE mean of the
    image, and the goal encoding of the config's GoalEncoder (segment -> object-VAE -> one
    LSTM step for ROLL)."""
    enc = goal_encoder(cfg)
    frozen = Frozen(seg=seg, object_vae=None if pre.object_vae is None else pre.object_vae.params)
    scene_params = pre.scene_vae.params
    lstm_params = None if pre.lstm is None else pre.lstm.params

    def encode_scene(rgb):
        return batched(lambda x: vae_means(scene_params, cfg.scene, x), rgb, chunk)

    def encode_object(rgb):
        return batched(lambda x: _object_encode(enc, frozen, scene_params, lstm_params, x),
                        rgb, chunk)

    return encode_scene, encode_object


def encode_frames(vae_params, vae_cfg, images, chunk: int = 1024) -> jnp.ndarray:
    """Object-VAE means of images [..., 48, 48, 3] -> [..., d] (chunked)."""
    images = np.asarray(images)
    lead = images.shape[:-3]
    flat = images.reshape((-1,) + images.shape[-3:])
    z = batched(lambda x: vae_means(vae_params, vae_cfg, x), flat, chunk)
    return jnp.asarray(z.reshape(lead + (-1,)))
