"""Learning benchmark: a training run of the real loop (`roll_jax.training.driver.run`, the
code path of train.py) and its learning curve, measured.

    python -m bench learning --algo oracle --preset cpu --seeds 3 --set total_env_steps=20000 \
        --name oracle_cpu                       # state oracle: SAC + HER + the loop themselves
    python -m bench learning --algo roll --preset cpu --seeds 3 --name roll_cpu
    python -m bench learning ... --seed 1       # another base seed

`--algo oracle` replaces the latents with the true hand and object positions and the reward
with the true distance (`encoders.oracle.StateOracle`); `roll` and `skewfit` learn from
pixels. The run's directory is --run-dir (default runs/learning_NAME); an unfinished run is
resumed, a finished one only summarised.

Writes bench/results/learning.json (or --out): the config, the curve (median and 25-75% over
seeds of the per-seed mean final distance, at every evaluation), the area under the median
curve, the first env step where the median reaches --target, the step-0 distance, the run's
timings.json (wall and CPU seconds per phase); and the learning curve beside it as .png.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import time

import numpy as np

from bench.common import REPO, machine_info, result_path, write_result


def summarize(rows: list[dict], target: float) -> dict:
    """Curve figures of metrics rows: median / IQR over seeds per evaluation, the area under
    the median curve (trapezoid, in metre x env steps, and as the mean distance over the run),
    the first env step where the median is <= target, the step-0 and final medians."""
    from roll_jax.training.plots import seed_quantiles

    steps, med, q25, q75 = seed_quantiles(rows)
    hit = [int(s) for s, m in zip(steps, med) if m <= target]
    auc = float(np.trapezoid(med, steps)) if len(steps) > 1 else 0.0
    span = float(steps[-1] - steps[0]) if len(steps) > 1 else 1.0
    out = {"env_steps": steps.tolist(), "median": med.tolist(), "q25": q25.tolist(),
           "q75": q75.tolist(), "auc_m_steps": auc, "mean_distance_over_run": auc / span,
           "initial_median": float(med[0]), "final_median": float(med[-1]),
           "final_over_initial": float(med[-1] / med[0]),
           "target": target, "first_env_steps_median_le_target": hit[0] if hit else None}
    if "start_distance" in rows[0]:  # the test goals' distance at their first step (fixed)
        start = float(seed_quantiles(rows, "start_distance")[1][0])
        out.update(start_median=start, final_over_start=float(med[-1] / start))
    return out


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(prog="python -m bench learning", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", default="puck_push", help="the task (default puck_push)")
    p.add_argument("--algo", default="roll", choices=("roll", "skewfit", "oracle"),
                   help="the algorithm (default roll)")
    p.add_argument("--preset", default="cpu", help="smoke | cpu | paper (configs/presets.py)")
    p.add_argument("--seeds", type=int, default=3, help="seeds of the run (default 3)")
    p.add_argument("--seed", type=int, default=0, help="base PRNG seed of the run")
    p.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                   help="config overrides (as train.py --set)")
    p.add_argument("--name", default=None, help="the run's name (default ALGO_PRESET)")
    p.add_argument("--run-dir", default=None, help="default runs/learning_NAME")
    p.add_argument("--out", default=result_path("learning"),
                   help="result file (its learning curve beside it as .png)")
    p.add_argument("--target", type=float, default=0.05, help="distance target (m)")
    p.add_argument("--seg-ckpt", default=None, help="a fitted segmentation to reuse")
    p.add_argument("--enc-ckpt", default=None, help="pretrained encoders to reuse")
    a = p.parse_args(argv)
    name = a.name or f"{a.algo}_{a.preset}"
    out_dir = a.run_dir or os.path.join(REPO, "runs", f"learning_{name}")

    from configs.train import build_config
    from roll_jax.training import compiler, driver, run_dir

    machine = machine_info()

    compiler.use(compiler.default_dir())
    cfg = build_config(a.task, a.algo, a.preset, seeds=a.seeds, overrides=a.set)
    driver.check_given(seg_ckpt=a.seg_ckpt, enc_ckpt=a.enc_ckpt)
    resume = os.path.exists(os.path.join(out_dir, "config.json"))
    t0 = time.perf_counter()
    if run_dir.is_complete(out_dir):  # summarise the finished run (its timings.json as written)
        run_dir.check_resume(out_dir, cfg)
        rows = run_dir.read_rows(os.path.join(out_dir, "metrics.csv"), cfg.total_env_steps, True)
    else:
        rows = driver.run(cfg, out_dir, resume=resume, seed=a.seed, seg_ckpt=a.seg_ckpt,
                         enc_ckpt=a.enc_ckpt)
    wall = time.perf_counter() - t0
    with open(os.path.join(out_dir, "timings.json")) as f:
        timings = json.load(f)
    out = {"name": name, "task": a.task, "algo": a.algo, "preset": a.preset, "seeds": cfg.seeds,
           "seed": a.seed, "overrides": a.set, "resumed": resume,
           "seg_ckpt": a.seg_ckpt, "enc_ckpt": a.enc_ckpt,
           "config": run_dir.config_json(cfg), "curve": summarize(rows, a.target),
           "wall_s": round(wall, 1), "timings": timings}
    path = write_result("learning", out, machine, argv, a.out)
    shutil.copy(os.path.join(out_dir, "plots", "learning_curve.png"),
                os.path.splitext(path)[0] + ".png")
    c = out["curve"]
    for s, m, lo, hi in zip(c["env_steps"], c["median"], c["q25"], c["q75"]):
        print(f"env steps {s:7d}: median final distance {m * 100:5.2f} cm "
              f"(25-75%: {lo * 100:.2f}-{hi * 100:.2f})")
    if "start_median" in c:
        print(f"test goals' start distance {c['start_median'] * 100:.2f} cm; "
              f"final/start {c['final_over_start']:.2f}")
    print(f"final/initial {c['final_over_initial']:.2f}; first <= {a.target * 100:.0f} cm at "
          f"{c['first_env_steps_median_le_target']}; wall {wall:.0f} s; wrote {path}")
    return out


if __name__ == "__main__":
    main()
