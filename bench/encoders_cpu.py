"""The cpu preset's segmentation and encoders per task, measured: for each --tasks entry,

1. `python -m roll_jax.segmentation --task T --preset cpu --out DIR/T/seg` (fit + evaluation:
   IoU, robot leakage),
2. `python -m roll_jax.pretrain --task T --preset cpu --seg DIR/T/seg/ckpt --out DIR/T`,
3. `python -m roll_jax.analysis latent-vs-distance --task T --ckpt DIR/T` (paper Fig. 5, plus
   the object-VAE's r2 / pairwise Spearman and the scene-VAE's r2 of the object state),

each its own process, timed. Appends one row per task to bench/results/encoders_cpu.json
(written after every task, so a cut-off run keeps what it measured) and copies the Fig. 5 PNG
to docs/images/latent_vs_distance_T_cpu.png.

    python bench/encoders_cpu.py --tasks puck_push hurdle_top door_open --out runs/enc_cpu
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from bench.common import cpu_model, last_json, run_module  # noqa: E402

RESULTS = os.path.join(ROOT, "bench", "results", "encoders_cpu.json")


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tasks", nargs="+", default=["puck_push", "hurdle_bottom", "hurdle_top",
                                                  "door_open", "pickup"])
    p.add_argument("--out", default=os.path.join(ROOT, "runs", "enc_cpu"))
    p.add_argument("--seed", type=int, default=0, help="analysis seed (observations, goal)")
    a = p.parse_args(argv)
    rows = []
    if os.path.exists(RESULTS):
        with open(RESULTS) as f:
            rows = json.load(f)
    for task in a.tasks:
        d = os.path.join(a.out, task)
        t_seg, out = run_module(["roll_jax.segmentation", "--task", task, "--preset", "cpu",
                                 "--out", os.path.join(d, "seg")])
        seg = last_json(out)
        t_pre, _ = run_module(["roll_jax.pretrain", "--task", task, "--preset", "cpu",
                               "--seg", os.path.join(d, "seg", "ckpt"), "--out", d])
        shutil.copytree(os.path.join(d, "seg", "ckpt"), os.path.join(d, "segmentation"),
                        dirs_exist_ok=True)
        t_an, out = run_module(["roll_jax.analysis", "latent-vs-distance", "--task", task,
                                "--ckpt", d, "--seed", str(a.seed)])
        res = last_json(out)
        row = {"task": task, "preset": "cpu", "seed": a.seed, "cpu_model": cpu_model(),
               "segmentation_s": round(t_seg, 1), "pretrain_s": round(t_pre, 1),
               "analysis_s": round(t_an, 1),
               "segmentation": {k: seg.get(k) for k in seg if not isinstance(seg[k], list)},
               **{k: v for k, v in res.items() if k not in ("png", "json")}}
        rows.append(row)  # every run kept: a row names its machine and segmentation
        with open(RESULTS, "w") as f:
            json.dump(rows, f, indent=2)
        shutil.copy(res["png"], os.path.join(ROOT, "docs", "images",
                                             f"latent_vs_distance_{task}_cpu.png"))
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
