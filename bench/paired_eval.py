"""Paired comparison of trained runs' final policies on many more test goals than a run's
in-training evaluation.

A cpu-preset run evaluates on 16 test goals per seed, the same ones at every evaluation, so
its curve carries those goals' luck, and differences between evaluations of one run are not
independent. This evaluates each run's last checkpoint (`roll_jax.evaluate`, deterministic
actions) on one larger sample of goals and starts (`--n-goals` per seed, `--seed`): every run
meets the same goal from the same start, so each (seed, goal) is a pair across runs.

    python bench/paired_eval.py --pairs runs/A:runs/B runs/C:runs/D --name NAME

Per run: median and mean final distance (cm), per seed, and the shares of episodes ending
within 3 cm and beyond 10 cm. Per pair A:B, and pooled over the
pairs: the mean paired difference A - B with its standard error, the median difference, and
the share of episodes where A ends closer. Writes bench/results/paired_eval_NAME.json.
"""
from __future__ import annotations

import argparse
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from bench.common import machine_info, write_results  # noqa: E402


def difference(a: np.ndarray, b: np.ndarray) -> dict:
    """Paired statistics of final distances a, b (cm) of the same episodes."""
    d = np.asarray(a, np.float64).ravel() - np.asarray(b, np.float64).ravel()
    return {"n": int(d.size), "mean_a_minus_b_cm": float(d.mean()),
            "standard_error_cm": float(d.std(ddof=1) / np.sqrt(d.size)),
            "median_a_minus_b_cm": float(np.median(d)), "share_a_closer": float((d < 0).mean())}


def main(argv=None) -> dict:
    from roll_jax.analysis import evaluation

    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--pairs", nargs="+", required=True, metavar="A:B")
    p.add_argument("--n-goals", type=int, default=100)
    p.add_argument("--seed", type=int, default=7, help="goals and starts (not a run's seed)")
    p.add_argument("--name", required=True)
    a = p.parse_args(argv)
    pairs = []
    for pair in a.pairs:
        if pair.count(":") != 1:
            p.error(f"--pairs takes RUN_A:RUN_B, got {pair!r}")
        pairs.append(tuple(pair.split(":")))
    finals, runs = {}, {}
    for run in dict.fromkeys(r for pair in pairs for r in pair):
        loaded = evaluation.load_run(run)
        dist = 100 * evaluation.evaluate(loaded, None, a.n_goals, a.seed)["final_distance"]
        finals[run] = dist
        runs[run] = {"task": loaded.cfg.task, "env_steps": loaded.epoch * loaded.cfg.epoch_env_steps,
                     "median_cm": float(np.median(dist)), "mean_cm": float(dist.mean()),
                     "mean_cm_per_seed": dist.mean(1).tolist(),
                     "share_within_3cm": float((dist < 3.0).mean()),
                     "share_beyond_10cm": float((dist > 10.0).mean()),
                     "final_distance_cm": dist.round(3).tolist()}
        print(f"{run}: median {runs[run]['median_cm']:.2f} cm, mean {runs[run]['mean_cm']:.2f} cm, "
              f"within 3 cm {runs[run]['share_within_3cm']:.0%}, "
              f"beyond 10 cm {runs[run]['share_beyond_10cm']:.0%}")
    shapes = {run: f.shape for run, f in finals.items()}
    if len(set(shapes.values())) != 1:
        raise SystemExit(f"runs differ in seeds x goals: {shapes}")
    res = {"command": " ".join(sys.argv), "n_goals": a.n_goals, "seed": a.seed,
           "machine": machine_info(), "runs": runs, "pairs": {}}
    for ra, rb in pairs:
        res["pairs"][f"{ra}:{rb}"] = difference(finals[ra], finals[rb])
    res["pooled"] = difference(np.concatenate([finals[ra].ravel() for ra, _ in pairs]),
                               np.concatenate([finals[rb].ravel() for _, rb in pairs]))
    for name, d in {**res["pairs"], "pooled": res["pooled"]}.items():
        print(f"{name}: A - B {d['mean_a_minus_b_cm']:+.2f} +- {d['standard_error_cm']:.2f} cm "
              f"(median {d['median_a_minus_b_cm']:+.2f}; A closer in {d['share_a_closer']:.0%})")
    write_results(os.path.join(ROOT, "bench", "results", f"paired_eval_{a.name}.json"), res)
    return res


if __name__ == "__main__":
    main()
