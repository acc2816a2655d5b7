"""Paired comparison of two runs with the same base seed, task and seed count (finished, or
with --partial one still running or cut off: compared up to the last evaluation both have).

    python bench/paired.py --a runs/learning_roll_cpu --b runs/learning_roll_cpu_sq \
        --name reward_form_roll_cpu --from-steps 10000

Runs with the same base seed evaluate on the same test goals at each evaluation (the goal and
start keys do not depend on the algorithm or the reward), so each evaluation is a pair: the
comparison is of the two policies on the same goals, not of two goal samples. Prints and
writes bench/results/paired_NAME.json: per evaluation the median over seeds of the per-seed
mean final distance for A and B; over the evaluations from --from-steps on, the mean of those
medians, how many evaluations A is below B, the paired per-seed-evaluation differences (mean,
and its standard error) and the correlation of A's and B's per-seed distances (how much of
the curve's jitter is the goals rather than the policies).
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)


def per_eval(rows: list[dict]) -> dict[int, dict[int, float]]:
    """{env_steps: {seed: final_distance}} of metrics rows."""
    out: dict[int, dict[int, float]] = {}
    for r in rows:
        out.setdefault(int(r["env_steps"]), {})[int(r["seed"])] = float(r["final_distance"])
    return out


def compare(rows_a: list[dict], rows_b: list[dict], from_steps: int = 0,
            to_steps: int | None = None) -> dict:
    """The paired figures of two runs' metrics rows (same evaluation steps and seeds, up to
    `to_steps` when given: a longer run against the first part of a shorter one)."""
    if to_steps is not None:
        rows_a, rows_b = ([r for r in rows if r["env_steps"] <= to_steps]
                          for rows in (rows_a, rows_b))
    a, b = per_eval(rows_a), per_eval(rows_b)
    if sorted(a) != sorted(b) or any(sorted(a[s]) != sorted(b[s]) for s in a):
        raise ValueError("the two runs do not share evaluation steps and seeds: "
                         f"{sorted(a)[:3]}... vs {sorted(b)[:3]}...")
    steps = sorted(a)
    med_a = [float(np.median(list(a[s].values()))) for s in steps]
    med_b = [float(np.median(list(b[s].values()))) for s in steps]
    late = [i for i, s in enumerate(steps) if s >= from_steps]
    if not late:
        raise ValueError(f"--from-steps {from_steps} is past the last evaluation {steps[-1]}")
    xa = np.array([a[steps[i]][k] for i in late for k in sorted(a[steps[i]])])
    xb = np.array([b[steps[i]][k] for i in late for k in sorted(b[steps[i]])])
    diff = xa - xb
    return {"env_steps": steps, "median_a": med_a, "median_b": med_b, "from_steps": from_steps,
            "to_steps": to_steps,
            "n_evaluations": len(late),
            "mean_median_a": float(np.mean([med_a[i] for i in late])),
            "mean_median_b": float(np.mean([med_b[i] for i in late])),
            "evaluations_a_below_b": int(sum(med_a[i] < med_b[i] for i in late)),
            "paired_diff_mean": float(diff.mean()),
            "paired_diff_sem": float(diff.std(ddof=1) / np.sqrt(len(diff))) if len(diff) > 1
            else 0.0,
            "corr_per_seed_eval": float(np.corrcoef(xa, xb)[0, 1]) if len(xa) > 2 else None}


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--a", required=True, help="run directory A")
    p.add_argument("--b", required=True, help="run directory B")
    p.add_argument("--name", required=True)
    p.add_argument("--from-steps", type=int, default=0)
    p.add_argument("--to-steps", type=int, default=None,
                   help="compare evaluations up to this env step only")
    p.add_argument("--partial", action="store_true",
                   help="accept an unfinished run; compare up to the last evaluation both have")
    a = p.parse_args(argv)
    from roll_jax.training import driver, run_dir

    runs, complete = [], {}
    for name, d in (("a", a.a), ("b", a.b)):
        complete[name] = run_dir.is_complete(d)
        if not (a.partial or complete[name]):
            raise SystemExit(f"{d}: not a finished run (no {run_dir.COMPLETE_MARKER}); "
                             "--partial compares what it has")
        runs.append((run_dir.read_config(d),
                     run_dir.read_rows(os.path.join(d, "metrics.csv"), 2**62, True)))
    (ca, rows_a), (cb, rows_b) = runs
    to_steps = a.to_steps
    if a.partial:
        last = min(max(r["env_steps"] for r in rows) for rows in (rows_a, rows_b))
        to_steps = last if to_steps is None else min(to_steps, last)
    if (ca.task, ca.seeds) != (cb.task, cb.seeds):
        raise SystemExit(f"task/seeds differ: {ca.task}/{ca.seeds} vs {cb.task}/{cb.seeds}")
    out = {"name": a.name, "a": a.a, "b": a.b, "task": ca.task, "seeds": ca.seeds,
           "complete": complete,
           "command": "python bench/paired.py " + " ".join(argv if argv is not None
                                                           else sys.argv[1:]),
           **compare(rows_a, rows_b, a.from_steps, to_steps)}
    path = os.path.join(ROOT, "bench", "results", f"paired_{a.name}.json")
    with open(path, "w") as f:
        json.dump(out, f, indent=2)
    for s, x, y in zip(out["env_steps"], out["median_a"], out["median_b"]):
        print(f"env steps {s:7d}: A {x * 100:5.2f} cm  B {y * 100:5.2f} cm")
    print(f"from {a.from_steps}: mean of medians A {out['mean_median_a'] * 100:.2f} cm, "
          f"B {out['mean_median_b'] * 100:.2f} cm; A below B in {out['evaluations_a_below_b']}"
          f"/{out['n_evaluations']}; paired A-B {out['paired_diff_mean'] * 100:.2f} +- "
          f"{out['paired_diff_sem'] * 100:.2f} cm; corr {out['corr_per_seed_eval']}; "
          f"wrote {path}")
    return out


if __name__ == "__main__":
    main()
