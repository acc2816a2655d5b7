"""Learning benchmark: a training run of the real loop (`roll_jax.train.run`, the code path of
train.py) and its learning curve, measured.

    python bench/learning.py --algo oracle --preset cpu --seeds 3 --set total_env_steps=20000 \
        --name oracle_cpu                       # state oracle: SAC + HER + the loop themselves
    python bench/learning.py --algo roll --preset cpu --seeds 3 --name roll_cpu
    python bench/learning.py ... --seed 1       # another base seed

`--algo oracle` replaces the latents with the true hand and object positions and the reward
with the true distance (`loop.oracle_obs`); `roll` and `skewfit` learn from pixels. The run's
directory is --run-dir (default runs/learning_NAME); an unfinished run is resumed, a finished
one only summarised.

Writes bench/results/learning_NAME.json: the config, the curve (median and 25-75% over seeds of
the per-seed mean final distance, at every evaluation), the area under the median curve,
the first env step where the median reaches --target, the step-0 distance, the run's
timings.json (wall and CPU seconds per phase), the machine; and learning_NAME.png.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402

from bench.common import cpu_model  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RESULTS = os.path.join(ROOT, "bench", "results")


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
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", default="puck_push")
    p.add_argument("--algo", default="roll", choices=("roll", "skewfit", "oracle"))
    p.add_argument("--preset", default="cpu", help="smoke | cpu | paper (configs/presets.py)")
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--seed", type=int, default=0, help="base PRNG seed of the run")
    p.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE")
    p.add_argument("--name", default=None, help="default ALGO_PRESET")
    p.add_argument("--run-dir", default=None, help="default runs/learning_NAME")
    p.add_argument("--target", type=float, default=0.05, help="distance target (m)")
    p.add_argument("--seg-ckpt", default=None, help="a fitted segmentation to reuse")
    p.add_argument("--enc-ckpt", default=None, help="pretrained encoders to reuse")
    a = p.parse_args(argv)
    name = a.name or f"{a.algo}_{a.preset}"
    out_dir = a.run_dir or os.path.join(ROOT, "runs", f"learning_{name}")

    import jax

    from roll_jax.training import compiler, driver, run_dir

    compiler.use(compiler.default_dir())
    cfg = build_config(a.task, a.algo, a.preset, seeds=a.seeds, overrides=a.set)
    driver.check_given(seg_ckpt=a.seg_ckpt, enc_ckpt=a.enc_ckpt)
    resume = os.path.exists(os.path.join(out_dir, "config.json"))
    load0 = os.getloadavg()
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
           "command": "python bench/learning.py " + " ".join(argv if argv is not None
                                                             else sys.argv[1:]),
           "config": run_dir.config_json(cfg), "curve": summarize(rows, a.target),
           "wall_s": round(wall, 1), "timings": timings,
           "machine": {"device": str(jax.devices()[0]), "cpu_count": os.cpu_count(),
                       "platform": platform.machine(), "cpu_model": cpu_model(),
                       "jax": jax.__version__,
                       "load_avg_start": [round(x, 2) for x in load0],
                       "load_avg_end": [round(x, 2) for x in os.getloadavg()]}}
    os.makedirs(RESULTS, exist_ok=True)
    path = os.path.join(RESULTS, f"learning_{name}.json")
    with open(path, "w") as f:
        json.dump(out, f, indent=2)
    shutil.copy(os.path.join(out_dir, "plots", "learning_curve.png"),
                os.path.join(RESULTS, f"learning_{name}.png"))
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
