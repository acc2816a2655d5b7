"""The training chunk's per-program XLA:CPU options (`loop.CHUNK_CPU_COMPILER_OPTIONS`) against
XLA's defaults: trace + lower, compile, and chunk wall times with SAC on and off.

Each setting runs in a fresh process (no compilation cache), the settings alternate over
`--rounds`: the cpu preset's ROLL chunk on puck_push, as `bench/train.py`'s
`sac_share_in_chunk` builds and times it (one refresh cycle of steady-state plans).

    python bench/chunk_options.py [--rounds 1]      # ~3 min per setting and round on 2 cores

Writes bench/results/chunk_compiler_options.json.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)

from common import write_results  # noqa: E402

SETTINGS = ("xla_defaults", "chunk_options")
_CHILD = """
import json, sys
sys.path.insert(0, {root!r}); sys.path.insert(0, {here!r})
from roll_jax import loop
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


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rounds", type=int, default=1)
    p.add_argument("--out", default=os.path.join(HERE, "results", "chunk_compiler_options.json"))
    a = p.parse_args(argv)
    if a.rounds < 1:
        p.error(f"--rounds must be >= 1, got {a.rounds}")
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
