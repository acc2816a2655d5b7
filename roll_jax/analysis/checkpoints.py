"""Pretrained encoders as the analyses' inputs: a `python -m roll_jax.encoders.pretrain --out`
directory (segmentation/, encoders/, pretrain.json) loaded with the config it was made with,
and its encoders as numpy callables over fixed-size batches."""

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


def load_checkpoint(ckpt: str, task: str, preset: str | None = None):
    """(cfg, Pretrained, seg params) from a `roll_jax.encoders.pretrain --out` directory. The preset is
    read from DIR/pretrain.json when not given (it sets the LSTM training config), and so are
    the pretraining's `--set` overrides."""
    cfg = checkpoint_config(ckpt, task, preset)
    pre = pretrain.load(os.path.join(ckpt, "encoders"), cfg)
    seg, _ = pipeline.load(os.path.join(ckpt, "segmentation"), task)
    return cfg, pre, seg


def checkpoint_config(ckpt: str, task: str, preset: str | None = None):
    """The ROLL config a `roll_jax.encoders.pretrain --out` directory was made with: its preset (or
    `preset`) and its `--set` overrides, both from DIR/pretrain.json."""
    return build_config(task, "roll", checkpoint_preset(ckpt, task, preset),
                        overrides=_pretrain_info(ckpt).get("overrides", []))


def _pretrain_info(ckpt: str) -> dict:
    meta = os.path.join(ckpt, "pretrain.json")
    if not os.path.exists(meta):
        return {}
    with open(meta) as f:
        return json.load(f)


def checkpoint_preset(ckpt: str, task: str | None = None, preset: str | None = None) -> str:
    """`preset`, or the one a `roll_jax.encoders.pretrain --out` directory was made with
    (DIR/pretrain.json; "paper" without one); refuses a checkpoint of another `task`."""
    info = _pretrain_info(ckpt)
    if task is not None and info.get("task") not in (None, task):
        raise ValueError(f"checkpoint {ckpt} was pretrained for task {info['task']!r}, "
                         f"not {task!r}")
    return preset or info.get("preset", "paper")


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
