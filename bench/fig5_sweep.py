"""Fig. 5 and the object-VAE figures over analysis seeds and sample sizes, on fixed encoders.

The issue's targets hold "for any --seed and --n", so this runs, for each task's checkpoint,
`python -m roll_jax.analysis latent-vs-distance --task T --ckpt DIR --seed S --n N` (each its
own process, as a user runs it) for every (S, N) asked, and keeps the scalar figures of each
run in bench/results/fig5_sweep_cpu_preset.json (written after every run, so a cut-off sweep
keeps what it measured).

    python bench/fig5_sweep.py --runs 3:500 4:500 0:200 0:1000
    python bench/fig5_sweep.py --ckpt pickup=runs/enc_cpu_x/pickup --tasks pickup --runs 5:500
"""
from __future__ import annotations

import argparse
import json
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from bench.common import cpu_model, last_json, run_module  # noqa: E402

RESULTS = os.path.join(ROOT, "bench", "results", "fig5_sweep_cpu_preset.json")
TASKS = ("puck_push", "hurdle_bottom", "hurdle_top", "door_open", "pickup")
# The cpu preset's committed encoders (docs/analysis.md, "The cpu preset as committed").
CKPTS = {t: os.path.join("runs", "enc_cpu_z", t) for t in TASKS}


def _pair(text: str) -> tuple[int, int]:
    try:
        seed, n = (int(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected SEED:N, got {text!r}") from None
    if n < 2:
        raise argparse.ArgumentTypeError(f"N must be >= 2, got {n} in {text!r}")
    return seed, n


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tasks", nargs="+", default=list(TASKS), choices=TASKS)
    p.add_argument("--runs", nargs="+", type=_pair, required=True, metavar="SEED:N")
    p.add_argument("--ckpt", nargs="*", default=[], metavar="TASK=DIR",
                   help="a task's encoder dir instead of the committed preset's")
    p.add_argument("--out", default=os.path.join(ROOT, "runs", "fig5_sweep"),
                   help="the analysis outputs, one folder per checkpoint, seed and n")
    a = p.parse_args(argv)
    ckpts = dict(CKPTS)
    for item in a.ckpt:
        task, sep, d = item.partition("=")
        if not sep or task not in TASKS:
            p.error(f"--ckpt wants TASK=DIR with TASK one of {TASKS}, got {item!r}")
        ckpts[task] = d
    for task in a.tasks:
        if not os.path.isdir(os.path.join(ROOT, ckpts[task], "encoders")):
            p.error(f"{task}: no encoders in {ckpts[task]} (python -m roll_jax.pretrain ...)")
    res = {"rows": []}
    if os.path.exists(RESULTS):
        with open(RESULTS) as f:
            res = json.load(f)
    res["command"] = "python -m roll_jax.analysis latent-vs-distance --task T --ckpt DIR --seed S --n N"
    os.makedirs(os.path.dirname(RESULTS), exist_ok=True)
    for task in a.tasks:
        for seed, n in a.runs:
            args = ["roll_jax.analysis", "latent-vs-distance", "--task", task, "--ckpt",
                    ckpts[task], "--seed", str(seed), "--n", str(n),
                    "--out", os.path.join(a.out, ckpts[task].strip(os.sep).replace(os.sep, "_"),
                                          f"seed{seed}_n{n}")]
            seconds, out = run_module(args)
            figures = {k: v for k, v in last_json(out).items()
                       if isinstance(v, (int, float)) and not isinstance(v, bool)}
            row = {"task": task, "seed": seed, "n": n, "ckpt": ckpts[task],
                   "cpu_model": cpu_model(), "seconds": round(seconds, 1), **figures}
            res["rows"] = [r for r in res["rows"] if (r["task"], r["seed"], r["n"], r["ckpt"])
                           != (task, seed, n, ckpts[task])] + [row]
            with open(RESULTS, "w") as f:
                json.dump(res, f, indent=2)
            print(json.dumps({k: row[k] for k in ("task", "seed", "n", "seconds",
                                                  "spearman_object", "spearman_scene",
                                                  "object_vae_r2",
                                                  "object_vae_pairwise_spearman")
                              if k in row}), flush=True)


if __name__ == "__main__":
    main()
