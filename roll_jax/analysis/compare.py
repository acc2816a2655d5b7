"""Comparing training runs: paired learning curves, paired final policies, the policy panel.

    roll-analysis compare RUN_A RUN_B [RUN_C ...] [--from-steps N] [--to-steps N] [--partial]
        [--n-goals N [--seed S]] [--labels ...] [--out FILE.json] [--plot PNG]
                                                                        (roll-compare ...)
    roll-analysis policy-panel --evals OUT_A OUT_B --labels ROLL Skew-Fit [--goals 0 1 2 3]
        --out PNG

Runs with the same base seed (`--seed` of train.py) evaluate on the same test goals at each
evaluation (the goal and start keys depend on neither the algorithm nor the reward), so each
evaluation of A and B is a pair: `compare` reports, per evaluation, the median over seeds of
each run's final distance and, over the evaluations from --from-steps on, the mean of those
medians, how many A is below B, the paired per-seed differences (mean and standard error)
and the correlation of A's and B's per-seed distances (how much of a curve's jitter is the
goals' rather than the policies'). A run evaluates on few goals (16 per seed at the cpu
preset); `--n-goals N` also evaluates both runs' last checkpoints on N more goals per seed,
the same goals from the same starts for both (`--seed`), and pairs them episode by episode.
With more than two runs, each of B, C, ... is paired with A (one entry per pair in the JSON's
"pairs"). `--plot PNG` draws every run's learning curve (median over seeds, 25-75% band) on
one figure.

`policy-panel` draws the paper's policy visualisation from `roll-evaluate` outputs of one
task made with the same --seed: per goal, the goal image and each run's final frame (seed 0)
with its final distance.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import sys

import numpy as np

from roll_jax.analysis.stats import format_distance
from roll_jax.training import plots, run_dir


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


def difference(a: np.ndarray, b: np.ndarray) -> dict:
    """Paired statistics of final distances a, b (cm) of the same episodes."""
    d = np.asarray(a, np.float64).ravel() - np.asarray(b, np.float64).ravel()
    return {"n": int(d.size), "mean_a_minus_b_cm": float(d.mean()),
            "standard_error_cm": float(d.std(ddof=1) / np.sqrt(d.size)),
            "median_a_minus_b_cm": float(np.median(d)), "share_a_closer": float((d < 0).mean())}


def final_policies(runs: list[str], n_goals: int, seed: int) -> dict:
    """Each run's last checkpoint on `n_goals` goals per seed (the same goals and starts for
    every run): per run the final distances (cm) and their summary, and A - B paired."""
    from roll_jax.analysis import evaluation

    finals, out = [], {}
    for run in runs:
        loaded = evaluation.load_run(run)
        dist = 100 * evaluation.evaluate(loaded, None, n_goals, seed)["final_distance"]
        finals.append(dist)
        out[run] = {"env_steps": loaded.epoch * loaded.cfg.epoch_env_steps,
                    "median_cm": float(np.median(dist)), "mean_cm": float(dist.mean()),
                    "share_within_3cm": float((dist < 3.0).mean()),
                    "share_beyond_10cm": float((dist > 10.0).mean())}
    if finals[0].shape != finals[1].shape:
        raise ValueError(f"the runs differ in seeds x goals: {finals[0].shape} vs "
                         f"{finals[1].shape}")
    return {"n_goals": n_goals, "seed": seed, "runs": out,
            "a_minus_b": difference(finals[0], finals[1])}


def write_json(path: str, obj) -> None:
    """`obj` as indented JSON at `path` (its directory made), and say so."""
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as f:
        json.dump(obj, f, indent=2)
    print(f"wrote {path}")


def _print_pair(pair: dict, from_steps: int, task: str) -> None:
    """One line per paired evaluation and a summary, in `task`'s unit (cm; rad on the door)."""
    f = functools.partial(format_distance, task)
    for s, x, y in zip(pair["env_steps"], pair["median_a"], pair["median_b"]):
        print(f"env steps {s:7d}: A {f(x)}  B {f(y)}")
    print(f"from {from_steps}: mean of medians A {f(pair['mean_median_a'])}, "
          f"B {f(pair['mean_median_b'])}; A below B in "
          f"{pair['evaluations_a_below_b']}/{pair['n_evaluations']}; paired A-B "
          f"{f(pair['paired_diff_mean'], '+')} +- {f(pair['paired_diff_sem'])}; "
          f"corr {pair['corr_per_seed_eval']}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="roll-analysis compare", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", nargs="+", metavar="RUN",
                   help="two or more train.py --out directories: A B [C ...]; every other "
                        "run is paired with A")
    p.add_argument("--from-steps", type=int, default=0,
                   help="pair the evaluations from this env step on (default 0)")
    p.add_argument("--to-steps", type=int, default=None,
                   help="pair the evaluations up to this env step only")
    p.add_argument("--partial", action="store_true",
                   help="accept an unfinished run; compare up to the last evaluation all have")
    p.add_argument("--n-goals", type=int, default=0,
                   help="also evaluate A's and B's last checkpoints on N goals per seed "
                        "(two runs only; default 0)")
    p.add_argument("--seed", type=int, default=7,
                   help="PRNG seed of those goals and starts (default 7; not a run's seed)")
    p.add_argument("--labels", nargs="+", default=None,
                   help="one label per run for the plot (default: A, B, C, ... and the "
                        "directory name)")
    p.add_argument("--out", default=None, metavar="FILE", help="write the figures as JSON")
    p.add_argument("--plot", default=None, metavar="PNG",
                   help="draw every run's learning curve (median over seeds, 25-75%% band) "
                        "there")
    a = p.parse_args(argv)
    if len(a.runs) < 2:
        p.error(f"compare needs two or more runs, got {len(a.runs)}: {a.runs}")
    if a.labels is not None and len(a.labels) != len(a.runs):
        p.error(f"--labels gives {len(a.labels)} labels for {len(a.runs)} runs")
    if a.n_goals > 0 and len(a.runs) != 2:
        p.error(f"--n-goals evaluates two runs' final policies; got {len(a.runs)} runs")
    runs, complete = [], []
    try:
        for d in a.runs:
            complete.append(run_dir.is_complete(d))
            if not (a.partial or complete[-1]):
                raise ValueError(f"{d}: not a finished run (no {run_dir.COMPLETE_MARKER}); "
                                 "--partial compares what it has")
            runs.append((run_dir.read_config(d),
                         run_dir.read_rows(os.path.join(d, "metrics.csv"), 2**62, True)))
        ca = runs[0][0]
        for d, (c, _) in zip(a.runs[1:], runs[1:]):
            if (c.task, c.seeds) != (ca.task, ca.seeds):
                raise ValueError(f"task/seeds differ: {a.runs[0]} {ca.task}/{ca.seeds} vs "
                                 f"{d} {c.task}/{c.seeds}")
        if a.n_goals > 0 and ca.task == "door_open":
            raise ValueError("--n-goals reports final policies in cm (within 3 cm, beyond 10 cm); "
                             "door_open's distances are angles: compare its learning curves")
        to_steps = a.to_steps
        if a.partial:
            last = min(max(r["env_steps"] for r in rows) for _, rows in runs)
            to_steps = last if to_steps is None else min(to_steps, last)
        pairs = [{"a": a.runs[0], "b": d,
                  **compare(runs[0][1], rows, a.from_steps, to_steps)}
                 for d, (_, rows) in zip(a.runs[1:], runs[1:])]
        # two runs: the pair's figures at the top level; more: one entry per pair with A
        out = {"runs": a.runs, "task": ca.task, "seeds": ca.seeds, "complete": complete,
               **(pairs[0] if len(pairs) == 1 else {"pairs": pairs})}
        if a.n_goals > 0:
            out["final_policies"] = final_policies(a.runs, a.n_goals, a.seed)
    except (FileNotFoundError, ValueError) as e:
        p.error(str(e))
    for pair in pairs:
        if len(pairs) > 1:
            print(f"A = {pair['a']}, B = {pair['b']}")
        _print_pair(pair, a.from_steps, ca.task)
    if "final_policies" in out:
        d = out["final_policies"]["a_minus_b"]
        print(f"final policies on {a.n_goals} goals per seed: A - B "
              f"{d['mean_a_minus_b_cm']:+.2f} +- {d['standard_error_cm']:.2f} cm (median "
              f"{d['median_a_minus_b_cm']:+.2f}; A closer in {d['share_a_closer']:.0%})")
    if a.out:
        write_json(a.out, out)
    if a.plot:
        os.makedirs(os.path.dirname(os.path.abspath(a.plot)), exist_ok=True)
        last = pairs[0]["env_steps"][-1]
        labels = a.labels or [f"{chr(ord('A') + i)}: {os.path.basename(os.path.normpath(d))}"
                              for i, d in enumerate(a.runs)]
        plots.compare_curves([(label, [r for r in rows if r["env_steps"] <= last])
                              for label, (_, rows) in zip(labels, runs)],
                             a.plot, f"{ca.task}, {ca.seeds} seeds")
        print(f"wrote {a.plot}")
    return 0


# ----------------------------------------------------------------------------- policy panel

def read_evaluation(path: str, goals: list[int]) -> dict:
    """Goal images, seed-0 final frames and final distances of a `roll-evaluate --out`."""
    from PIL import Image

    meta = os.path.join(path, "evaluation.json")
    if not os.path.exists(meta):
        raise FileNotFoundError(f"{path}: no evaluation.json (not a roll-evaluate --out)")
    with open(meta) as f:
        summary = json.load(f)
    n = len(summary["goals"])
    bad = [g for g in goals if not 0 <= g < n]
    if bad:
        raise ValueError(f"{path}: goal(s) {bad} out of range: it has {n} goals")

    def load(name):
        return np.asarray(Image.open(os.path.join(path, name)).convert("RGB"))

    return {"task": summary["task"],
            "goal_images": {g: load(f"goal_{g:02d}.png") for g in goals},
            "final_frames": {g: load(f"final_{g:02d}_seed0.png") for g in goals},
            "final_distance": ({g: summary["goals"][g]["final_distance"][0] for g in goals}
                               if summary["goals"][0]["final_distance"] is not None else None)}


def panel_main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="roll-analysis policy-panel", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--evals", nargs="+", required=True, metavar="DIR",
                   help="roll-evaluate --out directories (same task, same --seed)")
    p.add_argument("--labels", nargs="+", required=True, help="one label per evaluation")
    p.add_argument("--goals", nargs="+", type=int, default=[0, 1, 2, 3],
                   help="goal indices, one row each (default 0 1 2 3)")
    p.add_argument("--out", required=True, metavar="PNG", help="the figure's path")
    a = p.parse_args(argv)
    if len(a.labels) != len(a.evals):
        p.error(f"{len(a.labels)} labels for {len(a.evals)} evaluations")
    try:
        evs = [read_evaluation(d, a.goals) for d in a.evals]
    except (FileNotFoundError, ValueError) as e:
        p.error(str(e))
    for d, ev in zip(a.evals[1:], evs[1:]):
        for g in a.goals:
            if ev["task"] != evs[0]["task"] or not np.array_equal(ev["goal_images"][g],
                                                                  evs[0]["goal_images"][g]):
                p.error(f"{d}: goal {g} is not {a.evals[0]}'s goal {g} (evaluate both runs of "
                        f"one task with the same --seed)")
    os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
    plots.policy_panel(evs, a.labels, a.goals, a.out)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
