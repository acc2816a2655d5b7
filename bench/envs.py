"""Env throughput, compile times, and physics parity with C MuJoCo.

For every task and N parallel envs: MJX env steps/s with and without rendering (48x48), the
compile time of the jitted rollout, and, in the same run, C MuJoCo single-thread stepping
of the same model with the same action semantics (the reference; ratio printed). Parity:
object-position error between MJX and C MuJoCo on the scripted sequences and on longer
random-action sequences. Writes bench/results/envs.json.

    python -m bench envs                      # CPU: N = 1, 64, 512
    python -m bench envs --n 1 64 512 4096    # GPU
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np

import envs_mjx
from bench.common import machine_info, read_figures, result_path, write_result
from envs_mjx.reference import CReference
from envs_mjx.rollout import random_actions, rollout
from envs_mjx.scripts import SCRIPTS


def _timed(fn, *args):
    t0 = time.perf_counter()
    out = fn(*args)
    jax.block_until_ready(out)
    return out, time.perf_counter() - t0


def mjx_throughput(env, n: int, steps: int, render: bool, repeats: int = 2) -> dict:
    keys = jax.random.split(jax.random.PRNGKey(0), n)
    states = jax.jit(jax.vmap(env.reset))(keys)
    acts = jax.vmap(lambda k: random_actions(k, steps, env.action_size))(keys)
    fn = jax.jit(jax.vmap(lambda s, a: rollout(env, s, a, render=render)[0]))
    t0 = time.perf_counter()
    compiled = fn.lower(states, acts).compile()
    compile_s = time.perf_counter() - t0
    best = float("inf")
    for _ in range(repeats):
        _, dt = _timed(compiled, states, acts)
        best = min(best, dt)
    return {"steps_per_s": n * steps / best, "compile_s": compile_s}


def c_mujoco_throughput(env, steps: int) -> float:
    s0 = jax.jit(env.reset)(jax.random.PRNGKey(0))
    ref = CReference(env, s0)
    acts = np.asarray(random_actions(jax.random.PRNGKey(1), steps, env.action_size))
    t0 = time.perf_counter()
    for a in acts:
        ref.step(a)
    return steps / (time.perf_counter() - t0)


def parity(env, actions, s0) -> float:
    """Max object-position error (m or rad) between MJX and C MuJoCo along the sequence."""
    _, traj = jax.jit(lambda s, a: rollout(env, s, a))(s0, jnp.asarray(actions))
    ref = CReference(env, s0)
    err = 0.0
    for t, a in enumerate(np.asarray(actions)):
        ref.step(a)
        err = max(err, float(np.abs(np.asarray(traj.obj[t]) - ref.object_state()).max()))
    return err


def main(argv=None) -> None:
    p = argparse.ArgumentParser(prog="python -m bench envs", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tasks", nargs="+", default=list(envs_mjx.TASK_NAMES), help="tasks to time")
    p.add_argument("--n", nargs="+", type=int, default=[1, 64, 512], help="parallel envs")
    p.add_argument("--steps", type=int, default=20, help="env steps per timed rollout")
    p.add_argument("--parity-steps", type=int, default=200,
                   help="steps of the MJX / C MuJoCo parity sequences")
    p.add_argument("--out", default=result_path("envs"), help="result file")
    args = p.parse_args(argv)
    machine = machine_info()
    # other tasks' figures from an earlier (partial) run on the same device are kept
    figures = {"steps": args.steps, "tasks": read_figures(args.out, machine).get("tasks", {})}
    for task in args.tasks:
        env = envs_mjx.make(task)
        c_sps = c_mujoco_throughput(env, 500)
        row = {"c_mujoco_steps_per_s_1thread": c_sps, "n_envs": args.n, "mjx": {}}
        for n in args.n:
            for render in (False, True):
                r = mjx_throughput(env, n, args.steps, render)
                r["ratio_vs_c_mujoco"] = r["steps_per_s"] / c_sps
                row["mjx"][f"n{n}_{'render' if render else 'norender'}"] = r
                print(f"{task:14s} N={n:5d} render={render!s:5s} "
                      f"{r['steps_per_s']:10.0f} steps/s  x{r['ratio_vs_c_mujoco']:.3f} of C "
                      f"MuJoCo ({c_sps:.0f}/s)  compile {r['compile_s']:.1f}s", flush=True)
        s0 = jax.jit(env.reset)(jax.random.PRNGKey(2))
        row["parity_scripted_max_err"] = parity(env, SCRIPTS[task](args.parity_steps), s0)
        rand = random_actions(jax.random.PRNGKey(5), args.parity_steps, env.action_size)
        row["parity_random_max_err"] = parity(env, rand, s0)
        print(f"{task:14s} parity vs C MuJoCo over {args.parity_steps} steps: scripted "
              f"{row['parity_scripted_max_err'] * 1000:.2f} mm, random "
              f"{row['parity_random_max_err'] * 1000:.2f} mm (door: mrad)", flush=True)
        figures["tasks"][task] = row
        # after every task, so a cut-off run keeps its figures
        write_result("envs", figures, machine, argv, args.out)


if __name__ == "__main__":
    main()
