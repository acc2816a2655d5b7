"""The check a lent GPU runs: one prepared command, about 8 minutes on one H100.

1. Rendered env steps/s (MJX step and the 48x48 render, `envs.mjx_throughput`) of --task at
   1024 and 4096 envs, with the compile time of each rollout;
2. one training chunk of the paper preset (ROLL, --seeds seeds vmapped, the code path of
   train.py: `loop.compile_chunk`; the program of the chunks that do not evaluate), its
   trace + lower and compile times, its first call and a steady one, env steps/s and whether
   its metrics are finite. The segmentation and the
   encoders have random weights (speed does not depend on them, so nothing is fitted or
   pretrained) and the plan is the steady state after learning starts: the policy acts and
   SAC learns (the scheduled VAE / LSTM rounds off).

    python -m bench gpu_check                  # on the GPU: bench/results/gpu_check.json
    python -m bench gpu_check --tiny --out F   # the same at tiny sizes (a CPU; the tests)

--tiny: 4 envs, 2 steps, and a smoke-preset state-oracle chunk of one seed.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import tempfile
import time

import jax
import jax.numpy as jnp

import envs_mjx
from bench.chunk import _call, _compile, fresh_frozen_and_pretrained
from bench.common import machine_info, result_path, write_result
from bench.envs import mjx_throughput
from configs.train import make_config
from roll_jax.encoders import pretrain
from roll_jax.encoders.goal_encoding import Frozen
from roll_jax.training import loop, sharding
from roll_jax.training.state import ChunkPlan, init_state


def chunk_config(task: str, algo: str, preset: str, seeds: int, tiny: bool):
    """The chunk's config: the preset's, learning from the first chunk; --tiny: one episode of
    2 envs per chunk and a small replay buffer."""
    base = make_config(task, algo, preset)
    over = {"seeds": seeds, "sac": dataclasses.replace(base.sac, learning_starts=0)}
    if tiny:
        over.update(n_envs=2, epoch_env_steps=2 * base.horizon, total_env_steps=2 * base.horizon,
                    n_eval_goals=2, sac=dataclasses.replace(base.sac, learning_starts=0,
                                                            replay_size=4 * base.horizon))
    return make_config(task, algo, preset, **over)


def chunk_figures(cfg, env, key) -> dict:
    """Compile and run the chunk twice (the second call timed as the steady state)."""
    k_fz, k_init = jax.random.split(key)
    if cfg.algo == "oracle":  # no segmentation or encoders to stand in for
        pre = pretrain.initial(cfg, k_fz)
        frozen, scene_vae, lstm = Frozen(seg=None, object_vae=None), pre.scene_vae, pre.lstm
    else:
        frozen, scene_vae, lstm = fresh_frozen_and_pretrained(cfg, k_fz)
    frozen = jax.device_put(frozen, jax.devices()[0])
    state = jax.jit(jax.vmap(lambda k: init_state(k, cfg, env, scene_vae, lstm)))(
        jax.random.split(k_init, cfg.seeds))
    plan = ChunkPlan(learn=jnp.bool_(True), act_random=jnp.bool_(False),
                     vae_batches=jnp.int32(0), lstm_batches=jnp.int32(0),
                     refresh_goals=jnp.bool_(False))
    seed_batch = sharding.resolve_seed_batch("auto", cfg.seeds)
    chunk = loop.compile_chunk(cfg, env, 1, seed_batch, evaluate=False)
    compiled, lower_s, compile_s = _compile(chunk, state, frozen, plan)
    print(f"  chunk: trace+lower {lower_s:.1f} s, compile {compile_s:.1f} s", flush=True)
    (state, _), first_s, _ = _call(compiled, state, frozen, plan)
    (state, metrics), steady_s, _ = _call(compiled, state, frozen, plan)
    finite = bool(all(jnp.all(jnp.isfinite(x)) for x in jax.tree.leaves(metrics["train"])))
    steps = cfg.seeds * cfg.epoch_env_steps
    print(f"  chunk: first call {first_s:.2f} s, steady {steady_s:.2f} s -> "
          f"{steps / steady_s:.0f} env steps/s ({cfg.seeds} seeds); metrics finite: {finite}",
          flush=True)
    return {"algo": cfg.algo, "preset": cfg.preset, "seeds": cfg.seeds,
            "seed_batch": seed_batch, "n_envs": cfg.n_envs, "n_eval_goals": cfg.n_eval_goals,
            "env_steps_per_chunk": steps,
            "sac_updates_per_seed": cfg.epoch_env_steps * cfg.sac.updates_per_step,
            "sac_batch_size": cfg.sac.batch_size, "replay_size": cfg.sac.replay_size,
            "lower_s": lower_s, "compile_s": compile_s, "first_call_s": first_s,
            "steady_chunk_s": steady_s, "env_steps_per_s": steps / steady_s,
            "metrics_finite": finite}


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(prog="python -m bench gpu_check", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", default="puck_push", choices=envs_mjx.TASK_NAMES,
                   help="the task (default puck_push)")
    p.add_argument("--seeds", type=int, default=6, help="seeds of the chunk (default 6)")
    p.add_argument("--tiny", action="store_true",
                   help="tiny sizes (4 envs, a smoke-preset oracle chunk of one seed): the "
                        "check's code path on a CPU")
    p.add_argument("--out", default=None,
                   help="result file (default bench/results/gpu_check.json; --tiny: a file in "
                        "the temporary directory)")
    a = p.parse_args(argv)
    out = a.out or (os.path.join(tempfile.gettempdir(), "gpu_check_tiny.json") if a.tiny
                    else result_path("gpu_check"))
    machine = machine_info()
    if jax.default_backend() == "cpu" and not a.tiny:
        print("note: no GPU (JAX's backend is the CPU): at full size this takes hours; "
              "--tiny checks the code path", flush=True)
    t0 = time.perf_counter()
    env = envs_mjx.make(a.task)
    n_envs, steps = ((4,), 2) if a.tiny else ((1024, 4096), 20)
    figures = {"task": a.task, "tiny": a.tiny, "rollout_steps": steps, "rendered_env_steps": {}}
    for n in n_envs:
        r = mjx_throughput(env, n, steps, render=True)
        figures["rendered_env_steps"][f"n{n}"] = r
        print(f"  {n:5d} envs: {r['steps_per_s']:10.0f} rendered env steps/s, compile "
              f"{r['compile_s']:.1f} s", flush=True)
    cfg = chunk_config(a.task, "oracle" if a.tiny else "roll", "smoke" if a.tiny else "paper",
                       1 if a.tiny else a.seeds, a.tiny)
    figures["chunk"] = chunk_figures(cfg, env, jax.random.PRNGKey(0))
    figures["wall_s"] = round(time.perf_counter() - t0, 1)
    print(f"  wall {figures['wall_s']} s", flush=True)
    write_result("gpu_check", figures, machine, argv, out)
    return figures


if __name__ == "__main__":
    main()
