"""roll-jax command line.

Today this runs the one job the project can do end to end: a random-policy rollout of a
task's MJX scene, rendered by the JAX renderer, vmapped over envs and seeds, writing the
frames as PNGs. ROLL training (`--algo roll`) and the Skew-Fit baseline arrive with the
training issues; asking for them now fails with a clear message instead of pretending.

    python train.py --task puck_push --preset smoke --out runs/puck_push_smoke
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time

ALGOS_AVAILABLE = ("random",)
ALGOS_PLANNED = ("roll", "skewfit")
PRESETS = {
    # n_envs per seed, episodes, frame size of the saved video frames
    "smoke": dict(n_envs=4, episodes=1, video_size=128),
    "paper": dict(n_envs=64, episodes=4, video_size=128),
}


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


def parse_args(argv=None) -> RolloutConfig:
    import envs_mjx

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--task", default="puck_push")
    p.add_argument("--algo", default="random")
    p.add_argument("--preset", default="smoke")
    p.add_argument("--seeds", type=int, default=1)
    p.add_argument("--n-envs", type=int, default=None, help="override the preset's envs per seed")
    p.add_argument("--out", default=None)
    a = p.parse_args(argv)
    if a.task not in envs_mjx.TASK_NAMES:
        p.error(f"unknown --task {a.task!r}; expected one of {', '.join(envs_mjx.TASK_NAMES)}")
    if a.algo in ALGOS_PLANNED:
        p.error(f"--algo {a.algo!r} is not implemented yet (ROLL training and Skew-Fit are the "
                f"next issues); available now: {', '.join(ALGOS_AVAILABLE)}")
    if a.algo not in ALGOS_AVAILABLE:
        p.error(f"unknown --algo {a.algo!r}; expected one of "
                f"{', '.join(ALGOS_AVAILABLE + ALGOS_PLANNED)}")
    if a.preset not in PRESETS:
        p.error(f"unknown --preset {a.preset!r}; expected one of {', '.join(PRESETS)}")
    if a.seeds < 1:
        p.error(f"--seeds must be >= 1, got {a.seeds}")
    preset = dict(PRESETS[a.preset])
    if a.n_envs is not None:
        if a.n_envs < 1:
            p.error(f"--n-envs must be >= 1, got {a.n_envs}")
        preset["n_envs"] = a.n_envs
    out = a.out or os.path.join("runs", f"{a.task}_{a.algo}_{a.preset}")
    return RolloutConfig(task=a.task, algo=a.algo, preset=a.preset, seeds=a.seeds, out=out,
                         **preset)


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
    cfg = parse_args(argv)
    os.makedirs(cfg.out, exist_ok=True)
    with open(os.path.join(cfg.out, "config.json"), "w") as f:
        json.dump(dataclasses.asdict(cfg), f, indent=2)
    summary = run_random(cfg)
    print(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
