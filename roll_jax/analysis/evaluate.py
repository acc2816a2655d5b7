"""Evaluate a training run's policy on goal images, as at the paper's test time.

    roll-evaluate --run DIR [--goal-image PNG ...] [--n-goals N] [--seed S]
        --out OUT            (python -m roll_jax.analysis.evaluate ... without installing)

Loads the run's latest checkpoint (finished or not: DIR/ckpt, read only) with its
segmentation and encoders, takes the goal images (PNG or any image PIL reads, RGB; resized to
48x48 with a note when they are another size) or samples N goals from the task's goal space
and renders them, segments and encodes each goal as the loop encodes its test goals
(object-VAE + one LSTM step for ROLL, the scene-VAE for Skew-Fit), runs the deterministic
policy of every seed for one episode per goal from a reset, and writes to OUT:

    goal_GG.png                    the 48x48 goal image as the encoder saw it
    goal_GG_seedS.gif              observation (left) beside the goal, every step
    final_GG_seedS.png             the last observation
    evaluation.json                per goal and seed: the final latent distance to the goal,
                                   the final object state and, for sampled goals (whose
                                   state is known), the true final distance (env.goal_distance)

The start states and the goals depend only on --seed, so the same goal image gives the same
distances twice. Nothing in DIR is written.
"""

from __future__ import annotations

import argparse
import json
import os
import sys


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="roll-evaluate", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--run", required=True, metavar="DIR", help="a train.py --out directory")
    p.add_argument("--goal-image", nargs="*", default=[], metavar="PNG",
                   help="goal image files (RGB); default: sample --n-goals goals")
    p.add_argument("--n-goals", type=int, default=8,
                   help="goals sampled from the task's goal space when no --goal-image "
                        "(default 8)")
    p.add_argument("--seed", type=int, default=0,
                   help="PRNG seed of the start states and sampled goals (default 0)")
    p.add_argument("--seg-ckpt", metavar="DIR", help="segmentation to use (default: the run's)")
    p.add_argument("--enc-ckpt", metavar="DIR", help="encoders to use (default: the run's)")
    p.add_argument("--out", required=True, metavar="OUT",
                   help="output directory (outside the run directory)")
    return p


def main(argv=None) -> int:
    p = make_parser()
    a = p.parse_args(argv)
    if a.n_goals <= 0:
        p.error(f"--n-goals must be positive, got {a.n_goals}")
    run, out = os.path.realpath(a.run), os.path.realpath(a.out)
    if out == run or out.startswith(run + os.sep):
        p.error(f"--out {a.out} is inside the run directory {a.run}: evaluate writes nothing there")
    from roll_jax.analysis import evaluation  # JAX: only once the arguments are known to be good
    from roll_jax.common.checkpoint import DamagedCheckpoint

    try:
        images = [evaluation.read_goal_image(path) for path in a.goal_image]
        loaded = evaluation.load_run(a.run, a.seg_ckpt, a.enc_ckpt)
        res = evaluation.evaluate(loaded, [im for im, _ in images], a.n_goals, a.seed)
    except (FileNotFoundError, ValueError, DamagedCheckpoint) as e:
        p.error(str(e))
    for path, (_, note) in zip(a.goal_image, images):
        if note:
            print(f"note: goal image {path} {note}", file=sys.stderr)
    sources = list(a.goal_image) or ["sampled"] * a.n_goals
    notes = [n for _, n in images] or [None] * a.n_goals
    summary = evaluation.write_outputs(a.out, loaded, res, sources, notes, a.run, a.seed)
    print(json.dumps({k: v for k, v in summary.items() if k != "goals"}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
