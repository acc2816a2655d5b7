"""Encoder benchmarks: training steps/s at the paper's batch sizes and encoding throughput.

- scene-VAE train step, batch 64 (Table 3), beta-VAE loss;
- object-VAE train step, batch 128 (Table 3), beta-VAE + VAE matching loss (50% drop);
- LSTM train step, 25 trajectories x T = 50 (online training batch, "Training schedules"),
  auto-encoder + matching loss, including the synthetic occlusion (`make_occlusion`: drop
  50% of one frame's object pixels and encode it with the object-VAE), as the training loop
  runs it; the auto-encoder-only step (pre-training) for comparison;
- encoding throughput at batch 1024: scene-VAE means; object-VAE means + one LSTM step
  (`GoalEncoder.single`, how goal images are encoded).

Steps run inside one jitted `lax.scan` of K steps (how pre-training and the training chunk run
them), timed after a warm-up call, best of a few repeats. Architectures and batch sizes are the
paper's whatever the machine; latent sizes from hurdle_top (scene 6, object 6).

    python -m bench encoders [--quick]

Writes bench/results/encoders.json.
"""
from __future__ import annotations

import argparse
import functools
import json
import time

import jax
import jax.numpy as jnp

from bench.common import machine_info, result_path, time_best, write_result
from configs.encoders import lstm_config, object_vae_config, scene_vae_config
from roll_jax.encoders import models, steps
from roll_jax.encoders.goal_encoding import GoalEncoder
from roll_jax.encoders.models import lstm_encode

TASK = "hurdle_top"


def _timeit_donated(run, state, key):
    """`time_best` of a jitted `run(state, key) -> (state, out)` that donates its state: each
    call feeds the previous call's state back in (a donated buffer cannot be reused)."""
    holder = {"s": state}

    def call(k):
        holder["s"], out = run(holder["s"], k)
        return out

    return time_best(call, key)


def _images(key, shape, object_like: bool):
    """uint8 images; object_like: a random disc on black (segmented-image statistics) + mask."""
    if not object_like:
        return jax.random.randint(key, shape, 0, 256).astype(jnp.uint8), None
    lead = shape[:-3]
    k1, k2 = jax.random.split(key)
    c = jax.random.uniform(k1, lead + (2,), minval=8, maxval=40)
    yy, xx = jnp.mgrid[0:48, 0:48]
    mask = (yy - c[..., 0, None, None]) ** 2 + (xx - c[..., 1, None, None]) ** 2 <= 25
    colour = jax.random.randint(k2, lead + (1, 1, 3), 50, 256).astype(jnp.uint8)
    return jnp.where(mask[..., None], colour, 0).astype(jnp.uint8), mask


def bench_vae(cfg, k_steps: int, object_like: bool, key) -> dict:
    state = steps.init_vae(key, cfg)
    data, masks = _images(key, (cfg.batch_size,) + cfg.image_shape, object_like)

    @functools.partial(jax.jit, donate_argnums=0)
    def run(state, key):
        def body(st, k):
            st, m = steps.vae_train_step(st, k, data, cfg, masks)
            return st, m["loss"]
        return jax.lax.scan(body, state, jax.random.split(key, k_steps))

    first, best = _timeit_donated(run, state, key)
    return {"batch": cfg.batch_size, "latent_dim": cfg.latent_dim,
            "matching_loss": cfg.matching_coef > 0, "steps_per_call": k_steps,
            "steps_per_s": k_steps / best, "images_per_s": k_steps * cfg.batch_size / best,
            "compile_and_first_call_s": first}


def bench_lstm(vcfg, lcfg, batch: int, horizon: int, k_steps: int, matching: bool, key) -> dict:
    vae = steps.init_vae(key, vcfg)
    images, masks = _images(key, (batch, horizon) + vcfg.image_shape, True)
    latents = models.encode_mean(vae.params, vcfg, images)
    state = steps.init_lstm(key, lcfg, vcfg.latent_dim)

    @functools.partial(jax.jit, donate_argnums=0)
    def run(state, key):
        def body(st, k):
            k_occ, k_step = jax.random.split(k)
            occ = (steps.make_occlusion(k_occ, vae.params, vcfg, images, lcfg, masks)
                   if matching else None)
            st, m = steps.lstm_train_step(st, k_step, latents, lcfg, occ)
            return st, m["loss"]
        return jax.lax.scan(body, state, jax.random.split(key, k_steps))

    first, best = _timeit_donated(run, state, key)
    return {"batch_trajectories": batch, "horizon": horizon, "hidden": lcfg.hidden,
            "layers": lcfg.layers, "matching_loss": matching, "steps_per_call": k_steps,
            "steps_per_s": k_steps / best, "compile_and_first_call_s": first}


def bench_encode(scfg, vcfg, lcfg, batch: int, key) -> dict:
    scene = steps.init_vae(key, scfg)
    obj = steps.init_vae(jax.random.fold_in(key, 1), vcfg)
    lstm = steps.init_lstm(key, lcfg, vcfg.latent_dim)
    enc = GoalEncoder(scfg, vcfg, segment=False, lstm=True)
    rgb, _ = _images(key, (batch,) + scfg.image_shape, False)
    seg, _ = _images(key, (batch,) + vcfg.image_shape, True)

    scene_fn = jax.jit(lambda p, x: models.encode_mean(p, scfg, x))
    obj_fn = jax.jit(lambda p, l, x: enc.single(l, models.encode_mean(p, vcfg, x)))
    # the same images as 1024/50 ~ 20 trajectories through the LSTM (per-step encoding)
    t_len = 50
    n_traj = batch // t_len
    seq = seg[:n_traj * t_len].reshape((n_traj, t_len) + vcfg.image_shape)
    seq_fn = jax.jit(lambda p, l, x: lstm_encode(l, models.encode_mean(p, vcfg, x)))
    out = {"batch": batch}
    f, b = time_best(scene_fn, scene.params, rgb)
    out["scene_vae_images_per_s"], out["scene_vae_compile_s"] = batch / b, f
    f, b = time_best(obj_fn, obj.params, lstm.params, seg)
    out["object_vae_lstm_single_images_per_s"], out["object_vae_lstm_single_compile_s"] = batch / b, f
    f, b = time_best(seq_fn, obj.params, lstm.params, seq)
    out["object_vae_lstm_sequence_images_per_s"] = n_traj * t_len / b
    out["object_vae_lstm_sequence_shape"] = [n_traj, t_len]
    return out


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench encoders", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true", help="fewer steps per timed call")
    p.add_argument("--out", default=result_path("encoders"), help="result file")
    a = p.parse_args(argv)
    machine = machine_info()
    k = 5 if a.quick else 10
    key = jax.random.PRNGKey(0)
    scfg = scene_vae_config(TASK)
    vcfg = object_vae_config(TASK)
    lcfg = lstm_config(TASK)
    t0 = time.perf_counter()
    res = {
        "task_configs": TASK,
        "note": ("steps/s of one jitted lax.scan of K train steps (Adam included), best of "
                 "repeats after a warm-up call; synthetic data (random images for the scene-VAE, "
                 "a random disc on black for the object-VAE); the machine was shared with other "
                 "jobs (see load averages), so CPU figures are lower bounds"),
    }
    res["scene_vae_train"] = bench_vae(scfg, k, False, key)
    print("scene-VAE  ", json.dumps(res["scene_vae_train"]), flush=True)
    res["object_vae_train"] = bench_vae(vcfg, k, True, key)
    print("object-VAE ", json.dumps(res["object_vae_train"]), flush=True)
    res["lstm_train_matching"] = bench_lstm(vcfg, lcfg, lcfg.online_batch_size, 50, k, True, key)
    print("LSTM+match ", json.dumps(res["lstm_train_matching"]), flush=True)
    res["lstm_train_ae_only"] = bench_lstm(vcfg, lcfg, lcfg.online_batch_size, 50, k, False, key)
    print("LSTM ae    ", json.dumps(res["lstm_train_ae_only"]), flush=True)
    res["encode"] = bench_encode(scfg, vcfg, lcfg, 1024, key)
    print("encode     ", json.dumps(res["encode"]), flush=True)
    res["wall_s"] = time.perf_counter() - t0
    write_result("encoders", res, machine, argv, a.out)


if __name__ == "__main__":
    main()
