"""The paper's policy visualisation from `roll_jax.evaluate` outputs: per goal, the goal image
and each method's final frame (seed 0) with its final distance.

    python -m roll_jax.evaluate --run runs/A --n-goals 8 --seed 0 --out runs/eval_A
    python -m roll_jax.evaluate --run runs/B --n-goals 8 --seed 0 --out runs/eval_B
    python bench/policy_panel.py --evals runs/eval_A runs/eval_B --labels ROLL Skew-Fit \
        --goals 0 1 2 3 --out docs/images/policy_panel.png

The evaluations must share their goal images (same task, same --seed, sampled goals); a pair
that does not is refused, naming the first goal that differs.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def read_evaluation(path: str, goals: list[int]) -> dict:
    """Goal images, seed-0 final frames and final distances of an evaluate --out directory."""
    from PIL import Image

    meta = os.path.join(path, "evaluation.json")
    if not os.path.exists(meta):
        raise FileNotFoundError(f"{path}: no evaluation.json (not a roll_jax.evaluate --out)")
    with open(meta) as f:
        summary = json.load(f)
    n = len(summary["goals"])
    bad = [g for g in goals if not 0 <= g < n]
    if bad:
        raise ValueError(f"{path}: goal(s) {bad} out of range: it has {n} goals")
    load = lambda name: np.asarray(Image.open(os.path.join(path, name)).convert("RGB"))  # noqa: E731
    return {"task": summary["task"],
            "goal_images": {g: load(f"goal_{g:02d}.png") for g in goals},
            "final_frames": {g: load(f"final_{g:02d}_seed0.png") for g in goals},
            "final_distance": ({g: summary["goals"][g]["final_distance"][0] for g in goals}
                               if summary["goals"][0]["final_distance"] is not None else None)}


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--evals", nargs="+", required=True, help="roll_jax.evaluate --out dirs")
    p.add_argument("--labels", nargs="+", required=True)
    p.add_argument("--goals", nargs="+", type=int, default=[0, 1, 2, 3])
    p.add_argument("--out", required=True, help="PNG path")
    a = p.parse_args(argv)
    if len(a.labels) != len(a.evals):
        p.error(f"{len(a.labels)} labels for {len(a.evals)} evaluations")
    from roll_jax.training import plots

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
    plots.policy_panel(evs, a.labels, a.goals, a.out)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
