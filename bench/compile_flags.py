"""XLA:CPU compiler options against the chunk's compile time: does any cut the ~40 s compile
of a tiny training chunk (the test suite compiles several) without slowing what it runs?

Each option set runs in a fresh process (XLA_FLAGS is read once at start-up; no persistent
cache): the test suite's tiny ROLL chunk (puck_push, smoke preset, 2 seeds, 500 env steps,
random-weight segmentation and encoders) is traced + lowered, compiled ahead of time and
called twice (chunks 0 and 1). Writes bench/results/compile_flags.json.

    python bench/compile_flags.py                      # the default option sets
    python bench/compile_flags.py --flags="" --flags=--xla_backend_optimization_level=0
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
# bench/ first: `import train` below is bench/train.py, not the top-level train.py.
sys.path.insert(0, os.path.dirname(HERE))
sys.path.insert(0, HERE)

from common import cpu_model, write_results  # noqa: E402
from roll_jax.training import compiler  # noqa: E402

DEFAULT_FLAGS = ("", "--xla_backend_optimization_level=0",
                 "--xla_llvm_disable_expensive_passes=true")


def one() -> dict:
    """Compile and run the tiny chunk in this process (XLA_FLAGS as the parent set it)."""
    import jax

    import envs_mjx
    import train as bench_train  # bench/train.py
    from configs.segmentation import segmentation_config
    from configs.train import make_config
    from roll_jax.training import loop, sharding

    # The chunk's own compiler options would override the flags under test.
    loop.chunk_compiler_options = lambda: None
    seg = segmentation_config("puck_push", "smoke", n_frames=300, unet_epochs=2, eval_states=8)
    cfg = make_config("puck_push", "roll", "smoke", seeds=2, total_env_steps=1000,
                      n_eval_goals=2, segmentation=seg)
    env = envs_mjx.make(cfg.task)
    frozen, scene_vae, lstm = bench_train.fresh_frozen_and_pretrained(cfg, jax.random.PRNGKey(0))
    state = jax.jit(jax.vmap(lambda k: loop.init_state(k, cfg, env, scene_vae, lstm)))(
        jax.random.split(jax.random.PRNGKey(1), cfg.seeds))
    chunk = loop.compile_chunk(cfg, env, 1, sharding.resolve_seed_batch("auto", cfg.seeds))
    plan = loop.plan_chunk(cfg, 0)
    compiled, lower_s, compile_s = bench_train._compile(chunk, state, frozen, plan)
    runs = []
    for epoch in (0, 1):
        t = time.perf_counter()
        state, _ = jax.block_until_ready(compiled(state, frozen, loop.plan_chunk(cfg, epoch)))
        runs.append(time.perf_counter() - t)
    return {"trace_lower_s": lower_s, "compile_s": compile_s, "chunk_s": runs}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--flags", action="append",
                   help="an XLA_FLAGS value to compare, repeatable (--flags= for XLA's defaults); "
                   "one process each; default: the three of DEFAULT_FLAGS")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--out", default=os.path.join(HERE, "results", "compile_flags.json"))
    a = p.parse_args(argv)
    a.flags = a.flags if a.flags is not None else list(DEFAULT_FLAGS)
    if a.child:
        print("RESULT " + json.dumps(one()), flush=True)
        return 0
    envs = {flags: dict(os.environ, XLA_FLAGS=flags, JAX_PLATFORMS="cpu", MUJOCO_GL="disable")
            for flags in a.flags}
    for flags in a.flags:  # an unknown flag fails here, not after minutes of runs
        refusal = compiler.xla_flags_refusal(flags)
        if refusal:
            raise SystemExit(f"XLA_FLAGS={flags!r} is refused by XLA: {refusal}")
    results = []
    for flags, env in envs.items():
        proc = subprocess.run([sys.executable, os.path.abspath(__file__), "--child"], env=env,
                              capture_output=True, text=True, check=False)
        lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
        if proc.returncode != 0 or not lines:
            raise RuntimeError(f"XLA_FLAGS={flags!r} failed:\n{proc.stderr[-3000:]}")
        res = {"xla_flags": flags, **json.loads(lines[-1][len("RESULT "):])}
        print(f"  XLA_FLAGS={flags!r:45s} trace+lower {res['trace_lower_s']:5.1f} s  "
              f"compile {res['compile_s']:5.1f} s  chunks {[round(s, 1) for s in res['chunk_s']]} s",
              flush=True)
        results.append(res)
    write_results(a.out, {"cpu_model": cpu_model(), "program": "tiny ROLL chunk (test suite)",
                          "results": results})
    return 0


if __name__ == "__main__":
    sys.exit(main())
