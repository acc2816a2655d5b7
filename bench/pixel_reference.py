"""What Figure 5's observations allow, per task: the perfect-segmentation yardstick
(`analysis.pixel_reference`: the centroid of the true object pixels, the mean centroid where
the arm hides the object), the known-state reference (`analysis.known_reference`: the true
state wherever the object shows) and the shares of observations whose object is hidden or
partly hidden, for several analysis seeds. No checkpoint: the renderer's labels only.

    python bench/pixel_reference.py [--tasks T ...] [--seeds 0 1 2] [--n 500]

Writes bench/results/pixel_reference.json.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from bench.common import write_results  # noqa: E402

RESULTS = os.path.join(ROOT, "bench", "results", "pixel_reference.json")
KEYS = ("reference_spearman_object", "reference_pairwise_spearman", "reference_r2",
        "known_spearman_object", "known_pairwise_spearman", "known_r2",
        "share_object_hidden", "share_object_partly_hidden")


def main(argv=None) -> None:
    import jax

    import envs_mjx
    from roll_jax import analysis

    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tasks", nargs="+", default=["puck_push", "hurdle_bottom", "hurdle_top",
                                                  "door_open", "pickup"])
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    p.add_argument("--n", type=int, default=500)
    p.add_argument("--out", default=RESULTS)
    a = p.parse_args(argv)
    res = {"n": a.n, "seeds": a.seeds, "note": __doc__.split("\n\n")[0], "tasks": {}}
    for task in a.tasks:
        env = envs_mjx.make(task)
        t0 = time.perf_counter()
        per_seed = [analysis.pixel_reference(analysis.observation_set(env, jax.random.PRNGKey(s), a.n))
                    for s in a.seeds]
        row = {k: [round(r[k], 4) for r in per_seed] for k in KEYS}
        row["median"] = {k: round(statistics.median(v), 4) for k, v in row.items()}
        row["seconds"] = round(time.perf_counter() - t0, 1)
        res["tasks"][task] = row
        print(task, " ".join(f"{k} {row['median'][k]:.3f}" for k in KEYS), flush=True)
    write_results(a.out, res)


if __name__ == "__main__":
    main()
