"""Reproduction-grid benchmark: wall time of the whole smoke grid and where it goes.

Runs `python -m roll_jax.training.reproduce --preset smoke --out DIR --ablations --jobs 2`
(13 runs, 2 seeds each; the target: under 20 min on a 2-core CPU) as a subprocess, times it,
and sums every run's `timings.json` (wall and CPU seconds per phase,
`reproduce.run_timings` / `timings_summary`):

    python -m bench grid --out /tmp/grid [--jobs 2]
    python -m bench grid --out DIR --summarize-only --wall-s S   # a grid timed by hand

With --summarize-only nothing runs: the runs already in DIR are summed and the wall time is
the one given (measured around the same command, e.g. with time(1)); the result says so in
`wall_how`. Writes bench/results/grid.json.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

from bench.common import REPO, machine_info, result_path, write_result
from roll_jax.training.reproduce import run_timings, timings_summary

TARGET_WALL_MIN = 20


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench grid", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, help="the grid's directory (a fresh one to run)")
    p.add_argument("--jobs", type=int, default=2, help="cells trained side by side (default 2)")
    p.add_argument("--results", default=result_path("grid"), help="result file")
    p.add_argument("--summarize-only", action="store_true",
                   help="run nothing: sum the runs in --out (needs --wall-s)")
    p.add_argument("--wall-s", type=float, default=None,
                   help="with --summarize-only: the grid's wall seconds, measured by hand")
    a = p.parse_args(argv)
    cmd = [sys.executable, "-m", "roll_jax.training.reproduce", "--preset", "smoke", "--out",
           a.out, "--ablations", "--jobs", str(a.jobs)]
    machine = machine_info()
    if a.summarize_only:
        if a.wall_s is None or a.wall_s <= 0:
            p.error(f"--summarize-only needs --wall-s > 0, got {a.wall_s}")
        wall = a.wall_s
        how = f"given (--wall-s {a.wall_s:g}): timed by hand around the same command"
    else:
        if os.path.exists(os.path.join(a.out, "runs")):
            p.error(f"{a.out} already holds runs: a timed grid needs a fresh --out")
        t0 = time.perf_counter()
        subprocess.run(cmd, cwd=REPO, check=True)
        wall, how = time.perf_counter() - t0, "timed by python -m bench grid"
    runs = run_timings(a.out)
    figures = {"grid_command": " ".join(cmd[1:]), "wall_s": round(wall, 1),
               "wall_min": round(wall / 60, 2), "wall_how": how,
               "target_wall_min": TARGET_WALL_MIN, **timings_summary(runs), "per_run": runs}
    print(f"grid: {figures['runs']} runs, {figures['wall_min']} min wall ({how}); sum of runs "
          f"{figures['sum_run_wall_s']} s wall, {figures['sum_run_cpu_s']} s CPU; phases "
          f"{figures['phase_wall_s']}")
    write_result("grid", figures, machine, argv, a.results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
