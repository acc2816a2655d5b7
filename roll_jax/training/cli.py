"""Train ROLL, Skew-Fit or the state oracle on one task (or view random-policy rollouts).

    python train.py --task puck_push --algo roll --preset cpu --seeds 2 --out runs/x
    python train.py ... --resume                 # continue the run in --out exactly
    python train.py ... --no-matching-loss | --no-lstm | --no-object-vae   (ROLL ablations)
    python train.py ... --set total_env_steps=20000 sac.batch_size=256    (config overrides)
    python train.py ... --print-config           # the resolved config as JSON; runs nothing
    python train.py ... --seeds 8 --devices all  # seed axis sharded over the devices (or --devices N)
    python train.py ... --distributed            # one process per host/GPU (docs/training.md)
    python train.py --algo random ...            # random-policy rollout frames only (viewer)

(`roll-train` is the same command once the package is installed.) Writes DIR/config.json,
DIR/metrics.csv, DIR/tb/ (TensorBoard: `tensorboard --logdir runs`), DIR/ckpt/ (orbax),
DIR/plots/learning_curve.png, DIR/videos/eval_*.gif, and the fitted DIR/segmentation/ and
DIR/encoders/ (reused on resume or given with --seg-ckpt / --enc-ckpt).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time

# Only configs/ (plain dataclasses) before the arguments are parsed: --help and --print-config
# answer without loading JAX or MuJoCo.
from configs import presets
from configs.train import ALGOS as TRAIN_ALGOS
from configs.train import PRESETS, TASKS

ALGOS = (*TRAIN_ALGOS, "random")
DEFAULT_PRESET = "cpu"


@dataclasses.dataclass(frozen=True)
class RolloutConfig:
    task: str
    algo: str
    preset: str
    seeds: int
    n_envs: int
    episodes: int
    video_size: int
    out: str


def build_config(a, p):
    """TrainConfig from parsed args; every error is reported before anything compiles."""
    from configs.overrides import parse_overrides
    from configs.train import build_config as build

    overrides = list(a.set)
    if a.n_envs is not None:
        try:
            set_n_envs = "n_envs" in parse_overrides(overrides).get("", {})
        except ValueError as e:
            p.error(str(e))
        if set_n_envs:
            p.error(f"--n-envs {a.n_envs} and --set n_envs=... both set n_envs; give one")
        overrides.append(f"n_envs={a.n_envs}")
    try:
        return build(a.task, a.algo, a.preset, seeds=a.seeds, overrides=overrides,
                     matching_loss=not a.no_matching_loss, use_lstm=not a.no_lstm,
                     use_object_vae=not a.no_object_vae)
    except (ValueError, TypeError) as e:
        msg = str(e)
        p.error(f"--n-envs {a.n_envs}: {msg}" if a.n_envs is not None and "n_envs" in msg else msg)


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", default="puck_push", metavar="TASK",
                   help=f"one of {', '.join(TASKS)} (default puck_push)")
    p.add_argument("--algo", default="roll", metavar="ALGO",
                   help=f"one of {', '.join(ALGOS)} (default roll); oracle: true positions "
                        "for latents; random: random-policy frames only")
    p.add_argument("--preset", default=DEFAULT_PRESET, metavar="PRESET",
                   help=f"one of {', '.join(PRESETS)} (configs/presets.py; default "
                        f"{DEFAULT_PRESET})")
    p.add_argument("--seeds", type=int, default=1,
                   help="seeds trained side by side in one run (default 1)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="run directory (default runs/TASK_ALGO_PRESET)")
    p.add_argument("--resume", action="store_true",
                   help="continue the run in --out from its last checkpoint (same config and "
                        "--seed required)")
    p.add_argument("--no-matching-loss", action="store_true",
                   help="ROLL ablation: no matching loss on the object-VAE")
    p.add_argument("--no-lstm", action="store_true",
                   help="ROLL ablation: the object-VAE latents without the LSTM")
    p.add_argument("--no-object-vae", action="store_true",
                   help="ROLL ablation: the LSTM on scene-VAE latents, no object-VAE")
    p.add_argument("--seg-ckpt", default=None, metavar="DIR",
                   help="segmentation checkpoint dir to reuse (default: fit one in "
                        "DIR/segmentation)")
    p.add_argument("--enc-ckpt", default=None, metavar="DIR",
                   help="pretrained encoders dir to reuse (default: pretrain into DIR/encoders)")
    p.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                   help="config overrides as Python literals: FIELD=VALUE (a TrainConfig "
                        "field) or GROUP.FIELD=VALUE (a nested config, e.g. "
                        "sac.batch_size=256); --print-config shows them all")
    p.add_argument("--print-config", action="store_true",
                   help="print the resolved config as JSON and exit (runs and writes nothing)")
    p.add_argument("--seed", type=int, default=0, help="base PRNG seed of the run (default 0)")
    p.add_argument("--n-envs", type=int, default=None,
                   help="envs per seed (TrainConfig.n_envs; for roll/skewfit epoch_env_steps "
                        "must be a multiple of n_envs * horizon)")
    p.add_argument("--devices", default="all",
                   help="'all' or N: shard the seed axis over that many devices (seeds must be "
                        "divisible by it; 1 = unsharded)")
    p.add_argument("--compile-cache", default=None, metavar="DIR|off",
                   help="persistent JAX compilation cache (default: $ROLL_JAX_CACHE or "
                        "~/.cache/roll_jax/jax): a second run of a config skips its compiles")
    p.add_argument("--seed-batch", default="auto",
                   help="'auto' or N: seeds vmapped side by side per device, the rest run one "
                        "group after the other (auto: 1 on CPU, all on GPU/TPU)")
    d = p.add_argument_group(
        "several processes (hosts or GPUs)",
        "Start the same command once per process, with the same --out on a shared filesystem: "
        "the seeds are sharded over the devices of all processes, process 0 writes the files.")
    d.add_argument("--distributed", action="store_true",
                   help="call jax.distributed.initialize() first; under SLURM, Open MPI and "
                        "other clusters JAX finds the processes itself, elsewhere give the "
                        "three flags below (any of them implies --distributed)")
    d.add_argument("--coordinator", default=None, metavar="HOST:PORT",
                   help="address of process 0's coordinator service (default: "
                        "$JAX_COORDINATOR_ADDRESS or the cluster's)")
    d.add_argument("--num-processes", type=int, default=None, metavar="N",
                   help="how many processes take part")
    d.add_argument("--process-id", type=int, default=None, metavar="I",
                   help="this process's index, 0 .. N-1")
    return p


def distributed(a, p) -> None:
    """jax.distributed.initialize for --distributed / --coordinator / --num-processes /
    --process-id (before anything asks JAX for its devices); errors as one message."""
    given = {"coordinator_address": a.coordinator, "num_processes": a.num_processes,
             "process_id": a.process_id}
    if not (a.distributed or any(v is not None for v in given.values())):
        return
    from roll_jax.training import sharding

    try:
        sharding.initialize_distributed(**given)
    except (ValueError, RuntimeError) as e:
        p.error(f"--distributed: {e}")


def resolve(a, p):
    """(config, run directory) from the parsed flags: configs/ only, no JAX."""
    if a.task not in TASKS:
        p.error(f"unknown --task {a.task!r}; expected one of {', '.join(TASKS)}")
    if a.algo not in ALGOS:
        p.error(f"unknown --algo {a.algo!r}; expected one of {', '.join(ALGOS)}")
    if a.preset not in PRESETS:
        p.error(f"unknown --preset {a.preset!r}; expected one of {', '.join(PRESETS)}")
    if a.seeds < 1:
        p.error(f"--seeds must be >= 1, got {a.seeds}")
    out = a.out or os.path.join("runs", f"{a.task}_{a.algo}_{a.preset}")
    if a.algo == "random":
        preset = presets.get(a.preset).for_task("rollout", a.task)
        if a.n_envs is not None:
            if a.n_envs < 1:
                p.error(f"--n-envs must be >= 1, got {a.n_envs}")
            preset["n_envs"] = a.n_envs
        return RolloutConfig(task=a.task, algo=a.algo, preset=a.preset, seeds=a.seeds,
                             out=out, **preset), out
    return build_config(a, p), out


def check_run(a, p, cfg, out) -> None:
    """What the run needs beyond its config: the devices, the given checkpoints, and for
    --resume the run it continues (imports JAX for the devices)."""
    from roll_jax.training import sharding

    try:
        devs = sharding.resolve(a.devices, cfg.seeds)
        sharding.resolve_seed_batch(a.seed_batch, cfg.seeds, len(devs))
    except ValueError as e:
        p.error(str(e))
    from roll_jax.training.driver import check_given

    try:
        check_given(seg_ckpt=a.seg_ckpt, enc_ckpt=a.enc_ckpt)
    except FileNotFoundError as e:
        p.error(str(e))
    if a.resume:
        from roll_jax.training.run_dir import check_resume

        try:
            check_resume(out, cfg, a.seed)
        except ValueError as e:
            p.error(str(e))


def parse_args(argv=None):
    """(args, config, run directory), every flag checked before anything compiles."""
    p = make_parser()
    a = p.parse_args(argv)
    cfg, out = resolve(a, p)
    if a.algo != "random" and not a.print_config:
        distributed(a, p)
        check_run(a, p, cfg, out)
    return a, cfg, out


def run_random(cfg: RolloutConfig) -> dict:
    """Random-policy episodes for seeds x envs in one jitted program; frames to PNG."""
    import jax
    import jax.numpy as jnp
    import matplotlib.pyplot as plt
    import numpy as np

    import envs_mjx
    from envs_mjx.rollout import random_actions, rollout

    env = envs_mjx.make(cfg.task)
    steps = env.horizon * cfg.episodes

    def one_env(key, size=48):
        k_reset, k_act = jax.random.split(key)
        s0 = env.reset(k_reset)
        acts = random_actions(k_act, steps, env.action_size)
        _, traj = rollout(env, s0, acts, render=True, width=size, height=size)
        return env.object_state(s0), traj

    def one_seed(seed_key):
        return jax.vmap(one_env)(jax.random.split(seed_key, cfg.n_envs))

    seed_keys = jax.vmap(jax.random.PRNGKey)(jnp.arange(cfg.seeds))
    t0 = time.time()
    obj0, traj = jax.jit(jax.vmap(one_seed))(seed_keys)
    jax.block_until_ready(traj)
    wall = time.time() - t0

    frames_dir = os.path.join(cfg.out, "frames")
    os.makedirs(frames_dir, exist_ok=True)
    rgb = np.asarray(traj.rgb)  # [seed, env, T, 48, 48, 3]
    for t in range(steps):
        plt.imsave(os.path.join(frames_dir, f"seed0_env0_t{t:03d}.png"), rgb[0, 0, t])
    # The same episode of seed 0 / env 0 at a size people can look at.
    first_env_key = jax.random.split(seed_keys[0], cfg.n_envs)[0]
    _, big = jax.jit(lambda k: one_env(k, cfg.video_size))(first_env_key)
    big_dir = os.path.join(cfg.out, f"frames_{cfg.video_size}")
    os.makedirs(big_dir, exist_ok=True)
    for t in range(steps):
        plt.imsave(os.path.join(big_dir, f"t{t:03d}.png"), np.asarray(big.rgb[t]))
    # Contact sheet: every 5th frame of the first envs.
    n_show = min(cfg.n_envs, 4)
    sheet = np.concatenate([np.concatenate(list(rgb[0, e, ::5]), axis=1) for e in range(n_show)])
    plt.imsave(os.path.join(cfg.out, "contact_sheet.png"), sheet)

    obj_end = np.asarray(traj.obj[:, :, -1])
    displacement = np.linalg.norm(obj_end - np.asarray(obj0), axis=-1)
    labels = np.asarray(traj.labels)
    summary = {
        "task": cfg.task, "algo": cfg.algo, "seeds": cfg.seeds, "n_envs": cfg.n_envs,
        "env_steps": int(cfg.seeds * cfg.n_envs * steps),
        "wall_s_including_compile": round(wall, 2),
        "object_displacement_mean": float(displacement.mean()),
        "object_displacement_max": float(displacement.max()),
        "object_pixel_fraction_mean": float((labels == envs_mjx.LABEL_OBJECT).mean()),
        "robot_pixel_fraction_mean": float((labels == envs_mjx.LABEL_ROBOT).mean()),
        "frames": frames_dir,
    }
    with open(os.path.join(cfg.out, "rollout.json"), "w") as f:
        json.dump(summary, f, indent=2)
    return summary


def main(argv=None) -> int:
    a, cfg, out = parse_args(argv)
    if a.print_config:
        print(json.dumps(dataclasses.asdict(cfg), indent=2))
        return 0
    if a.algo != "random":
        return train(a, cfg, out)
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "config.json"), "w") as f:
        json.dump(dataclasses.asdict(cfg), f, indent=2)
    print(json.dumps(run_random(cfg), indent=2))
    return 0


def train(a, cfg, out) -> int:
    """The training run; what refuses it once it started (another process training into
    --out, an event directory that cannot be written, only damaged checkpoints to resume
    from) is one line on stderr and exit code 1, with nothing written lost."""
    from roll_jax.common.checkpoint import DamagedCheckpoint
    from roll_jax.training import compiler, driver, events, run_dir

    if a.compile_cache != "off":
        compiler.use(a.compile_cache or compiler.default_dir())
    t0 = time.time()
    try:
        rows = driver.run(cfg, out, resume=a.resume, seg_ckpt=a.seg_ckpt,
                          enc_ckpt=a.enc_ckpt, seed=a.seed, devices=a.devices,
                          seed_batch=a.seed_batch)
    except (run_dir.RunLocked, events.EventDirNotWritable, DamagedCheckpoint) as e:
        print(f"error: {e}", file=sys.stderr, flush=True)
        return 1
    last = [r for r in rows if r["env_steps"] == rows[-1]["env_steps"]]
    print(json.dumps({"out": out, "env_steps": rows[-1]["env_steps"], "seeds": cfg.seeds,
                      "final_distance_per_seed": [r["final_distance"] for r in last],
                      "wall_s": round(time.time() - t0, 1)}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
