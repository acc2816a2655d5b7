"""Reproduction-grid benchmark: wall time of the whole smoke grid and where it goes.

Runs `python -m roll_jax.reproduce --preset smoke --out DIR --ablations --jobs 2` (13 runs,
2 seeds each; the target: under 20 min on a 2-core CPU) as a subprocess, times it, and
collects every run's `timings.json` (wall and CPU seconds per phase) into one JSON file:

    python bench/grid.py --out /tmp/grid [--jobs 2] [--results bench/results/grid_smoke.json]
    python bench/grid.py --out DIR --summarize-only --wall-s S   # a grid timed by hand

With --summarize-only nothing runs: the runs already in DIR are collected and the wall time
is the one given (measured around the same command, e.g. with time(1)); the JSON says so in
`wall_how` ("given (--wall-s S): ..." rather than "timed by bench/grid.py ..."). The committed
bench/results/grid_smoke.json is such a summary: that grid was timed with time(1).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RESULTS = os.path.join(ROOT, "bench", "results", "grid_smoke.json")
PHASES = ("segmentation", "pretrain", "init", "chunks", "final_eval")


def collect(out: str) -> list[dict]:
    """Per run: its phase times (the first chunk apart: it includes the compile)."""
    runs = []
    base = os.path.join(out, "runs")
    for name in sorted(os.listdir(base)):
        path = os.path.join(base, name, "timings.json")
        if not os.path.exists(path):
            raise FileNotFoundError(f"{path}: the run has no timings.json (unfinished?)")
        with open(path) as f:
            t = json.load(f)
        wall, cpu = t["wall_s"], t["cpu_s"]
        row = {"run": name, "total_wall_s": t["total_wall_s"], "total_cpu_s": t["total_cpu_s"]}
        for k in PHASES:
            row[f"{k}_wall_s"] = round(sum(wall.get(k, [])), 2)
            row[f"{k}_cpu_s"] = round(sum(cpu.get(k, [])), 2)
        row["first_chunk_wall_s"] = wall["chunks"][0]
        runs.append(row)
    return runs


def summarize(runs: list[dict], command: str, wall: float, how: str) -> dict:
    """The results JSON: the grid's wall time (`how`: timed here or given by hand) and the
    sums over the `collect`ed runs."""
    return {"command": command, "machine": {"cpu_count": os.cpu_count(),
                                            "platform": platform.platform()},
            "wall_s": round(wall, 1), "wall_min": round(wall / 60, 2), "wall_how": how,
            "target_wall_min": 20, "runs": len(runs),
            "sum_run_wall_s": round(sum(r["total_wall_s"] for r in runs), 1),
            "sum_run_cpu_s": round(sum(r["total_cpu_s"] for r in runs), 1),
            "first_chunk_wall_s": round(sum(r["first_chunk_wall_s"] for r in runs), 1),
            "phase_wall_s": {k: round(sum(r[f"{k}_wall_s"] for r in runs), 1) for k in PHASES},
            "per_run": runs}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="the grid's directory (a fresh one to run)")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--results", default=RESULTS)
    p.add_argument("--summarize-only", action="store_true")
    p.add_argument("--wall-s", type=float, default=None,
                   help="with --summarize-only: the grid's wall seconds, measured by hand")
    a = p.parse_args(argv)
    cmd = [sys.executable, "-m", "roll_jax.reproduce", "--preset", "smoke", "--out", a.out,
           "--ablations", "--jobs", str(a.jobs)]
    if a.summarize_only:
        if a.wall_s is None or a.wall_s <= 0:
            p.error(f"--summarize-only needs --wall-s > 0, got {a.wall_s}")
        wall = a.wall_s
        how = f"given (--wall-s {a.wall_s:g}): timed by hand around the same command"
    else:
        if os.path.exists(os.path.join(a.out, "runs")):
            p.error(f"{a.out} already holds runs: a timed grid needs a fresh --out")
        load = os.getloadavg()
        t0 = time.perf_counter()
        subprocess.run(cmd, cwd=ROOT, check=True)
        wall, how = time.perf_counter() - t0, f"timed by bench/grid.py (load at start {load})"
    res = summarize(collect(a.out), " ".join(cmd[1:]), wall, how)
    totals = res["phase_wall_s"]
    os.makedirs(os.path.dirname(os.path.abspath(a.results)), exist_ok=True)
    with open(a.results, "w") as f:
        json.dump(res, f, indent=2)
    print(f"grid: {res['runs']} runs, {res['wall_min']} min wall ({how}); sum of runs "
          f"{res['sum_run_wall_s']} s wall, {res['sum_run_cpu_s']} s CPU; phases {totals}")
    print(f"wrote {a.results}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
