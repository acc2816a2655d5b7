"""The training chunk's per-program XLA:CPU options (`loop.CHUNK_CPU_COMPILER_OPTIONS`) against
XLA's defaults: trace + lower, compile, and chunk wall times with SAC on and off.

Each setting runs in a fresh process (no compilation cache), the settings alternate over
`--rounds`: the cpu preset's ROLL chunk on puck_push, as `bench/train.py`'s
`sac_share_in_chunk` builds and times it (one refresh cycle of steady-state plans).

`--without OPTION` instead weighs one option of the chunk's: one process compiles the chunk
with all of them and without OPTION, then runs each plan of `--rounds` refresh cycles on both
programs, SAC on and off, the order of programs and of on/off flipped every other plan, so
that both see the same machine (its speed drifts by 10-30% over minutes).

    python bench/chunk_options.py [--rounds 1]      # ~3 min per setting and round on 2 cores
    python bench/chunk_options.py --without xla_cpu_experimental_ynn_fusion_type --rounds 3 \
        --out bench/results/chunk_options_without_ynn.json

Writes bench/results/chunk_compiler_options.json.
"""
from __future__ import annotations

import argparse
import functools
import json
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)

from common import cpu_model, write_results  # noqa: E402

SETTINGS = ("xla_defaults", "chunk_options")
_CHILD = """
import json, sys
sys.path.insert(0, {root!r}); sys.path.insert(0, {here!r})
from roll_jax.training import loop
if {setting!r} == "xla_defaults":
    loop.chunk_compiler_options = lambda: None
import train as bench_train  # bench/train.py
res = bench_train.sac_share_in_chunk("puck_push", "cpu")
res.pop("plans")
res["compiler_options"] = loop.chunk_compiler_options()
print("RESULT " + json.dumps(res))
"""


def one(setting: str) -> dict:
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env.pop("XLA_FLAGS", None)
    code = _CHILD.format(root=ROOT, here=HERE, setting=setting)
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True,
                          text=True, check=False)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"{setting}: the child failed:\n{proc.stderr[-3000:]}")
    return {"setting": setting, **json.loads(lines[-1][len("RESULT "):])}


def without(option: str, rounds: int) -> dict:
    """The chunk with all of its options ("all") and without `option`, in this process:
    per program its compile, and per plan its chunk time with SAC on and off."""
    import importlib.util
    import statistics

    import jax
    import jax.numpy as jnp

    from roll_jax.training import compiler, loop, sharding

    spec = importlib.util.spec_from_file_location("bench_train", os.path.join(HERE, "train.py"))
    bench_train = importlib.util.module_from_spec(spec)  # bench/train.py, not the CLI
    spec.loader.exec_module(bench_train)

    full = loop.CHUNK_CPU_COMPILER_OPTIONS
    if option not in dict(full):
        raise SystemExit(f"--without {option}: not one of the chunk's options {sorted(dict(full))}")
    variants = {"all": full, "without": tuple(kv for kv in full if kv[0] != option)}
    cfg, env, frozen, new_state, plans = bench_train.steady_chunk_inputs("puck_push", "cpu")
    seed_batch = sharding.resolve_seed_batch("auto", 1)
    evaluates = functools.partial(bench_train.evaluates, cfg)
    progs, states, out = {}, {}, {}
    for name, opts in variants.items():
        def make(ev, opts=opts):
            return jax.jit(sharding.over_seeds(loop.make_chunk(cfg, env, ev), 1, 1, seed_batch),
                           donate_argnums=0,
                           compiler_options=compiler.accepted_options(opts))

        progs[name] = bench_train.chunk_programs(cfg, env, frozen, new_state(), plans, make=make)
        states[name], _ = bench_train.warm_up(cfg, progs[name], new_state(), frozen, plans)
        first = progs[name][evaluates(0)]
        out[name] = {"options": dict(opts), "lower_s": first[1], "compile_s": first[2],
                     "on_s": [], "off_s": []}
        print(f"  {name:8s} trace+lower {first[1]:5.1f} s  compile {first[2]:5.1f} s", flush=True)
    n_updates = cfg.epoch_env_steps * cfg.sac.updates_per_step
    for i, (epoch, plan) in enumerate(plans * rounds):
        flip = i % 2 == 1
        for name in (reversed(variants) if flip else variants):
            compiled = progs[name][evaluates(epoch)][0]
            for switch in (("off", "on") if flip else ("on", "off")):
                pl = plan if switch == "on" else plan.replace(learn=jnp.bool_(False))
                (states[name], _), wall, _ = bench_train._call(compiled, states[name],
                                                                frozen, pl)
                out[name][f"{switch}_s"].append(wall)
        print(f"  plan {i}: " + "  ".join(f"{n} {out[n]['on_s'][-1]:.2f} / {out[n]['off_s'][-1]:.2f} s"
                                          for n in variants), flush=True)
    for name, r in out.items():
        sac = [1e3 * (x - y) / n_updates for x, y in zip(r["on_s"], r["off_s"])]
        r.update(chunk_s_mean=statistics.mean(r["on_s"]), chunk_s_median=statistics.median(
            r["on_s"]), sac_off_s_median=statistics.median(r["off_s"]),
            sac_ms_per_update_median=statistics.median(sac))
        r["chunk_over_sac"] = r["chunk_s_median"] / (r["sac_ms_per_update_median"] * n_updates / 1e3)
        print(f"  {name:8s} chunk mean {r['chunk_s_mean']:.2f} s, median {r['chunk_s_median']:.2f}"
              f" s (SAC off {r['sac_off_s_median']:.2f} s); SAC {r['sac_ms_per_update_median']:.2f}"
              f" ms per update; chunk / its SAC {r['chunk_over_sac']:.2f}", flush=True)
    return {"without": option, "rounds": rounds, "plans_per_round": len(plans),
            "sac_updates_per_chunk": n_updates, "programs": out}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rounds", type=int, default=1)
    p.add_argument("--without", metavar="OPTION",
                   help="weigh this one of the chunk's options in one process (see above)")
    p.add_argument("--out", default=os.path.join(HERE, "results", "chunk_compiler_options.json"))
    a = p.parse_args(argv)
    if a.rounds < 1:
        p.error(f"--rounds must be >= 1, got {a.rounds}")
    if a.without:
        res = without(a.without, a.rounds)
        write_results(a.out, {"what": __doc__.split("\n\n")[0], "task": "puck_push",
                              "preset": "cpu", "cpu_model": cpu_model(), **res})
        return
    runs = []
    for r in range(a.rounds):
        for setting in SETTINGS:
            res = one(setting)
            runs.append({"round": r, **res})
            print(f"  {setting:13s} trace+lower {res['lower_s']:5.1f} s  compile "
                  f"{res['compile_s']:5.1f} s  chunk {res['chunk_s']:.2f} s (SAC off "
                  f"{res['chunk_without_sac_s']:.2f} s)  SAC {res['sac_ms_per_update']:.2f} ms "
                  f"per update  chunk / its SAC {res['chunk_over_sac']:.2f}", flush=True)
    write_results(a.out, {"what": __doc__.split("\n\n")[0], "task": "puck_push",
                          "preset": "cpu", "runs": runs})


if __name__ == "__main__":
    main()
