"""Roofline of the encoders and SAC on this machine: time, hand-counted FLOPs, and the fraction
of the matmul rate measured in the same process.

1. matmul: a 2048 x 2048 float32 `jnp.dot` (2 * 2048^3 FLOPs), the machine's reference rate;
2. scene-VAE train step (batch 64, Table 3) and object-VAE train step (batch 128, matching
   loss on occluded copies), each with the convolutions of roll_jax/common/conv.py ("matmul", the
   default; "matmul_patches", every transposed conv in the patch form) and with XLA's
   ("lax"), side by side, each batch drawn from a pool as in training;
3. U-Net train step (the cpu preset's width 8 and the paper preset's 16 at batch 32) with the
   kernel gradient as dots (`dot_wgrad`, the CPU default) and with XLA's, and inference;
4. SAC update standalone on a fixed batch: the cpu preset's 128-128 at batch 256, the paper's
   400-300 at batch 1024;
5. (--chunk) SAC per update inside the cpu-preset ROLL chunk: the same compiled chunk run with
   the plan's `learn` on and off (`state.ChunkPlan`, an un-batched switch), plan by plan, the
   difference divided by its updates; HER sampling, prior goals through the LSTM and the
   gathers included. After each on/off pair the standalone update and the other yardsticks
   (`sac_yardstick_timer`) are timed again, and the ratios are the medians over the pairs.
   The target (<= 1.3x) is judged against `TARGET_YARDSTICK`, the update as the chunk
   computes it (metrics kept, a new batch each update) without the HER sampling.

Every step runs inside a jitted `lax.scan` (how training runs them), timed after a warm-up,
best of several calls.

FLOPs are counted by hand from the architecture (multiply-adds x 2; elementwise work,
BatchNorm, Adam and the losses are not counted):
- a VALID conv of a k x k kernel, Cin -> Cout, with an Ho x Wo output: Ho*Wo*k*k*Cin*Cout
  MACs; a transposed conv from an H x W input: H*W*k*k*Cin*Cout; dense: in*out;
- a train step is 3x its forward (forward, input gradients, weight gradients); the
  object-VAE's matching loss adds the encoder on the occluded batch (3x);
- U-Net: each 3x3 conv at the resolution of its block (48 at inc/up4, /2 per level);
- SAC update per sample: critic (policy forward on s', target twin-Q forward, twin-Q forward
  + backward: P + 2Q + 6Q) and actor (policy forward + backward, twin-Q forward + input
  gradient: 3P + 4Q): 4P + 12Q MACs, P and Q the MLPs' MACs per sample.

    python -m bench roofline [--chunk [--chunk-rounds 2]] [--quick]

Writes bench/results/roofline.json.
"""
from __future__ import annotations

import argparse
import dataclasses
import math

import jax
import jax.numpy as jnp

from bench.common import machine_info, result_path, time_best, write_result

from configs.encoders import object_vae_config, scene_vae_config
from configs.sac import SACConfig
from configs.segmentation import SegmentationConfig
from roll_jax.agents import sac
from roll_jax.encoders import steps as encoder_steps
from roll_jax.encoders.models import _CONV, _DECONV, _FEATURE_MAP, IMAGE_SHAPE
from roll_jax.segmentation import unet

TASK = "puck_push"


def _row(name: str, seconds: float, flops: float, peak: float, **extra) -> dict:
    rate = flops / seconds / 1e9
    row = {"ms": 1e3 * seconds, "gflop": flops / 1e9, "gflop_per_s": rate,
           "fraction_of_matmul": rate / peak, **extra}
    print(f"  {name:38s} {row['ms']:9.2f} ms  {row['gflop']:8.4f} GFLOP  {rate:7.1f} GFLOP/s  "
          f"{100 * row['fraction_of_matmul']:5.1f}% of matmul", flush=True)
    return row


# ----------------------------------------------------------------------------- FLOP counts

def vae_macs(latent_dim: int, feature_dim: int) -> dict:
    """Multiply-adds per image of the ConvVAE (roll_jax/encoders/models.py) by layer group."""
    h, cin, enc = IMAGE_SHAPE[0], IMAGE_SHAPE[2], 0
    for f, k, s in _CONV:
        h = (h - k) // s + 1
        enc += h * h * k * k * cin * f
        cin = f
    flat = math.prod(_FEATURE_MAP)
    heads = flat * feature_dim + 2 * feature_dim * latent_dim
    dec = latent_dim * flat
    h, cin = _FEATURE_MAP[0], _FEATURE_MAP[2]
    for f, k, s in _DECONV:
        dec += h * h * k * k * cin * f
        h, cin = (h - 1) * s + k, f
    return {"encoder": enc + heads, "decoder": dec}


def unet_macs(params, height: int) -> int:
    """Multiply-adds per image of the U-Net: every conv kernel at its block's resolution."""
    level = {"inc": 0, "down1": 1, "down2": 2, "down3": 3, "down4": 4,
             "up1": 3, "up2": 2, "up3": 1, "up4": 0, "outc": 0}
    total = 0
    for path, leaf in jax.tree_util.tree_flatten_with_path(params)[0]:
        names = [getattr(p, "key", "") for p in path]
        if names[-1] == "kernel":
            res = height // 2 ** level[names[0]]
            total += res * res * math.prod(leaf.shape)
    return total


def mlp_macs(sizes) -> int:
    return sum(a * b for a, b in zip(sizes[:-1], sizes[1:]))


def sac_update_flops(obs: int, goal: int, act: int, hidden, batch: int) -> float:
    p = mlp_macs((obs + goal, *hidden, 2 * act))
    q = mlp_macs((obs + goal + act, *hidden, 1))
    return 2.0 * batch * (4 * p + 12 * q)


# ----------------------------------------------------------------------------- benchmarks

def bench_matmul(n: int = 2048) -> dict:
    a = jax.random.normal(jax.random.PRNGKey(0), (n, n))
    b = jax.random.normal(jax.random.PRNGKey(1), (n, n))
    _, best = time_best(jax.jit(jnp.dot), a, b, repeats=10, min_time=3.0)
    rate = 2 * n ** 3 / best / 1e9
    print(f"  matmul {n}x{n} float32: {1e3 * best:.1f} ms, {rate:.1f} GFLOP/s", flush=True)
    return {"n": n, "ms": 1e3 * best, "gflop_per_s": rate}


def _vae_images(key, batch: int, object_like: bool):
    if not object_like:
        return jax.random.randint(key, (batch,) + IMAGE_SHAPE, 0, 256).astype(jnp.uint8), None
    c = jax.random.uniform(key, (batch, 2), minval=8, maxval=40)
    yy, xx = jnp.mgrid[0:48, 0:48]
    mask = (yy - c[:, 0, None, None]) ** 2 + (xx - c[:, 1, None, None]) ** 2 <= 25
    img = jnp.where(mask[..., None], jnp.uint8(200), jnp.uint8(0))
    return jnp.broadcast_to(img, mask.shape + (3,)), mask


def vae_step_timer(cfg, steps: int):
    """A function that times `steps` VAE train steps in one jitted `lax.scan` (each batch drawn
    from a pool of 4 batches, as `encoder_steps.vae_fit_epoch` does, so nothing is constant-folded)
    and returns (first call s, best s per call)."""
    key = jax.random.PRNGKey(0)
    pool, pool_masks = _vae_images(key, 4 * cfg.batch_size, cfg.matching_coef > 0)
    state = encoder_steps.init_vae(key, cfg)

    @jax.jit
    def run(state, key):
        def body(st, k):
            k_idx, k_step = jax.random.split(k)
            idx = jax.random.randint(k_idx, (cfg.batch_size,), 0, pool.shape[0])
            masks = None if pool_masks is None else pool_masks[idx]
            return encoder_steps.vae_train_step(st, k_step, pool[idx], cfg, masks)[0], None
        return jax.lax.scan(body, state, jax.random.split(key, steps))[0]

    return lambda: time_best(run, state, key)


def bench_vae(cfg, steps: int, peak: float, name: str) -> dict:
    macs = vae_macs(cfg.latent_dim, cfg.feature_dim)
    per_image = 3 * (macs["encoder"] + macs["decoder"])
    if cfg.matching_coef > 0:
        per_image += 3 * macs["encoder"]
    flops = 2.0 * per_image * cfg.batch_size
    out = {}
    for impl in ("matmul", "matmul_patches", "lax"):
        first, best = vae_step_timer(dataclasses.replace(cfg, conv_impl=impl), steps)()
        out[impl] = _row(f"{name} train step ({impl})", best / steps, flops, peak,
                         batch=cfg.batch_size, compile_and_first_call_s=first)
    out["speedup_matmul_over_lax"] = out["lax"]["ms"] / out["matmul"]["ms"]
    out["speedup_matmul_over_patches"] = out["matmul_patches"]["ms"] / out["matmul"]["ms"]
    return out


def unet_step_timer(features: int, batch: int, steps: int, dot_wgrad: bool):
    """(timer, state, images) for `steps` U-Net train steps in one jitted `lax.scan`: the timer
    traces and compiles at its first call, then returns (first call s, best call s)."""
    cfg = SegmentationConfig()
    key = jax.random.PRNGKey(0)
    h = IMAGE_SHAPE[0]
    state = unet.init_unet(key, features, h, h, cfg)
    images = jax.random.randint(key, (steps, batch, h, h, 3), 0, 256).astype(jnp.uint8)
    labels = jax.random.uniform(key, (steps, batch, h, h)) > 0.8
    model = unet.UNet(features, dot_wgrad=dot_wgrad)

    @jax.jit
    def run(state):
        def body(st, xy):
            x, y = xy

            def loss_fn(p):
                logits, upd = model.apply({"params": p, "batch_stats": st.batch_stats},
                                          x.astype(jnp.float32) / 255.0, train=True,
                                          mutable=["batch_stats"])
                return unet.bce_loss(logits, y.astype(jnp.float32)), upd["batch_stats"]

            grads, stats = jax.grad(loss_fn, has_aux=True)(st.params)
            upd, opt = unet.make_optimizer(cfg).update(grads, st.opt_state, st.params)
            params = jax.tree.map(lambda p, u: p + u, st.params, upd)
            return st.replace(params=params, batch_stats=stats, opt_state=opt), None
        return jax.lax.scan(body, state, (images, labels))[0]

    return (lambda: time_best(run, state)), state, images


def bench_unet(features: int, batch: int, steps: int, peak: float) -> dict:
    out = {"features": features, "batch": batch}
    for name, dot_wgrad in (("dot_wgrad", True), ("lax", False)):
        timer, state, images = unet_step_timer(features, batch, steps, dot_wgrad)
        first, best = timer()
        macs = unet_macs(state.params, IMAGE_SHAPE[0])
        out[f"train_{name}"] = _row(f"U-Net f{features} train step ({name})", best / steps,
                                    2.0 * 3 * macs * batch, peak, compile_and_first_call_s=first)
    infer = jax.jit(lambda p, x: jax.lax.map(lambda xb: unet.robot_probability(p, xb), x))
    _, best = time_best(infer, state, images)
    out["inference"] = _row(f"U-Net f{features} inference", best / steps, 2.0 * macs * batch,
                            peak)
    out["speedup_dot_wgrad_over_lax"] = out["train_lax"]["ms"] / out["train_dot_wgrad"]["ms"]
    return out


def bench_sac(hidden, batch: int, steps: int, peak: float, obs=6, goal=6, act=2) -> dict:
    cfg = SACConfig(hidden=tuple(hidden), batch_size=batch)
    key = jax.random.PRNGKey(0)
    state = sac.init_sac(key, obs, goal, act, cfg)
    ks = jax.random.split(key, 6)
    batch_ = sac.Transition(obs=jax.random.normal(ks[0], (batch, obs)),
                            goal=jax.random.normal(ks[1], (batch, goal)),
                            action=jax.random.uniform(ks[2], (batch, act), minval=-1, maxval=1),
                            reward=-jax.random.uniform(ks[3], (batch,)),
                            next_obs=jax.random.normal(ks[4], (batch, obs)),
                            done=jnp.zeros((batch,)))

    @jax.jit
    def run(state, key):
        def body(st, k):
            return sac.sac_update(st, k, batch_, cfg)[0], None
        return jax.lax.scan(body, state, jax.random.split(key, steps))[0]

    first, best = time_best(run, state, key)
    return _row(f"SAC {hidden} batch {batch} standalone", best / steps,
                sac_update_flops(obs, goal, act, hidden, batch), peak, hidden=list(hidden),
                batch=batch, compile_and_first_call_s=first)


def bench_sac_in_chunk(rounds: int) -> dict:
    """Per-update SAC cost inside the cpu-preset ROLL chunk (learn on minus learn off, plan by
    plan), each on/off pair followed by the yardsticks of `sac_yardstick_timer`."""
    from bench import chunk

    return chunk.sac_share_in_chunk(TASK, "cpu", rounds=rounds,
                                 yardsticks=sac_yardstick_timer(300))


# The yardstick the in-chunk target is judged by: the update the chunk runs (metrics kept, a
# new batch each update), without the HER sampling the chunk adds. "standalone update" (one
# constant batch, metrics dropped) is the FLOP-rate yardstick of `bench_sac`: in its loop XLA
# deletes the metrics' work and hoists the batch-only work (184 against 251 fusions per
# update), so it times less than the update (bench/sac.py; the target: docs/training.md,
# "What a chunk costs").
TARGET_YARDSTICK = "update on a new batch"


def sac_yardstick_timer(steps: int):
    """A function -> {name: best ms per update} of bench/sac.py's variants at the cpu
    preset's sizes, each compiled once: the standalone update (one constant batch, XLA's
    defaults, as `bench_sac` times it), the same with its metrics kept, the update on a new
    batch per update (`TARGET_YARDSTICK`), one jitted update per call on a batch of its own,
    and `her.sac_steps` (HER sampling + update) with XLA's defaults and with the chunk's
    options."""
    from bench import sac as sp
    from roll_jax.training.compiler import chunk_compiler_options

    v = sp.variants(steps)
    forms = {
        "standalone update": (v["update, constant batch, metrics dropped (roofline standalone)"],
                              None),
        "update on a constant batch, metrics kept": (v["update, constant batch, metrics kept"],
                                                     None),
        TARGET_YARDSTICK: (v["update, new batch per update, metrics kept"], None),
        "her.sac_steps": (v["her.sac_steps (sampling + update)"], None),
        "her.sac_steps, chunk options": (v["her.sac_steps (sampling + update)"],
                                         chunk_compiler_options()),
    }
    compiled = {name: (jax.jit(var.fn, compiler_options=opts).lower(*var.args).compile(), var)
                for name, (var, opts) in forms.items()}

    per_call = sp.per_call_timer(steps)

    def timer() -> dict:
        out = {name: 1e3 * time_best(c, *var.args)[1] / var.updates
               for name, (c, var) in compiled.items()}
        out["update per call"] = per_call()
        return out
    return timer


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench roofline", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--chunk", action="store_true",
                   help="also time SAC inside the cpu-preset chunk (compiles the chunk: minutes)")
    p.add_argument("--chunk-rounds", type=int, default=2, metavar="N",
                   help="--chunk: refresh cycles of 4 plans, each plan with SAC on and off")
    p.add_argument("--quick", action="store_true", help="fewer steps per call")
    p.add_argument("--out", default=result_path("roofline"), help="result file")
    a = p.parse_args(argv)
    machine = machine_info()
    if a.chunk_rounds < 1:
        p.error(f"--chunk-rounds must be >= 1, got {a.chunk_rounds}")
    steps = 5 if a.quick else 20
    res = {"task_configs": TASK, "note": __doc__.split("\n\n")[0]}
    print("matmul reference", flush=True)
    res["matmul"] = bench_matmul()
    peak = res["matmul"]["gflop_per_s"]
    print("encoders (paper architectures and batch sizes)", flush=True)
    res["scene_vae"] = bench_vae(scene_vae_config(TASK), steps, peak, "scene-VAE b64")
    res["object_vae"] = bench_vae(object_vae_config(TASK), steps, peak, "object-VAE b128+match")
    res["unet"] = [bench_unet(f, 32, max(steps // 4, 3), peak) for f in (8, 16)]
    print("SAC", flush=True)
    res["sac"] = [bench_sac((128, 128), 256, steps * 5, peak),
                  bench_sac((400, 300), 1024, steps, peak)]
    if a.chunk:
        # The standalone update trains on one constant batch, so XLA folds part of its work;
        # the same update on a new batch per update, and `her.sac_steps` (HER sampling
        # included) outside the chunk, are the fairer yardsticks (bench/sac.py). Each
        # is timed after every on/off pair of chunks: their ratios are taken pair by pair.
        print(f"SAC inside the cpu-preset chunk, {a.chunk_rounds} refresh cycle(s)", flush=True)
        res["sac_in_chunk"] = bench_sac_in_chunk(a.chunk_rounds)
        in_chunk = res["sac_in_chunk"]["sac_ms_per_update"]
        over = res["sac_in_chunk"]["median_over"]
        res["sac_in_chunk"]["over_standalone"] = over["standalone update"]
        res["sac_in_chunk"]["over_target_yardstick"] = over[TARGET_YARDSTICK]
        print(f"  in-chunk ({in_chunk:.2f} ms, mean) per update, median of the pairs: "
              f"{over[TARGET_YARDSTICK]:.2f}x the {TARGET_YARDSTICK} (target <= 1.3x), "
              f"{over['standalone update']:.2f}x the constant-batch update without metrics",
              flush=True)
    write_result("roofline", res, machine, argv, a.out)


if __name__ == "__main__":
    main()
