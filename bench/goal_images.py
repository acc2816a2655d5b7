"""How a task's goal images are segmented and how much Fig. 5 depends on the one goal image.

Figure 5 compares N observations with one goal through the object encoding, so a goal image
whose object is masked badly misplaces the whole ranking. Four measurements:

1. ``--seg DIR``: the segmentation's masks of `--n` goal images (`env.sample_goal`; on pickup
   split into goals held in the air and goals on the table) against the renderer's labels,
   scored as the segmentation's evaluation scores random states (`pipeline.score`: IoU, robot
   leakage, a threshold sweep), and the shares of object pixels that the background model
   keeps and that the U-Net calls robot.
2. ``--ckpt DIR`` (a `roll_jax.pretrain --out` directory with its segmentation): Fig. 5's
   object Spearman of every analysis seed's observation set against every seed's goal image
   (`--seeds`), which tells a goal that ranks badly from an observation set that does; and the
   same with each goal's code replaced by the mean code of the observations that show the whole
   object within 3 cm of the goal (what the goal image "should" encode).

3. ``--goal-sweep K`` (with ``--ckpt``): Fig. 5 of the first seed's observation set against K
   goals from `env.sample_goal`, with each goal's offset from the goal space's centre: whether
   the ranking depends on where the goal lies.
4. (with ``--ckpt``) Fig. 5 of each seed with the codes of the observations whose object is
   hidden replaced by the mean code of the others (what the perfect-segmentation yardstick
   does with a hidden object): whether an encoder that put an empty image at the centre of the
   codes would rank better.

    python bench/goal_images.py --task pickup --seg runs/enc/pickup/segmentation \\
        [--ckpt runs/enc/pickup] [--name NAME]   # bench/results/goal_images_NAME.json
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable
from typing import NamedTuple

import jax
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from bench.common import write_results  # noqa: E402

NEAR_M = 0.03


def sampled_goals(env, key, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`n` goals from `env.sample_goal` -> (rgb, renderer labels, object states), numpy."""
    @jax.jit
    def goals(keys):
        def one(k):
            g = env.sample_goal(k)
            rgb, labels = env.render_both(g)
            return rgb, labels, env.object_state(g)
        return jax.vmap(one)(keys)

    return tuple(map(np.asarray, goals(jax.random.split(key, n))))


def goal_segmentation(task: str, seg_dir: str, n: int, seed: int) -> dict:
    import envs_mjx
    from roll_jax.segmentation import pipeline

    seg, _ = pipeline.load(seg_dir, task)
    env = envs_mjx.make(task)

    rgb, labels, state = sampled_goals(env, jax.random.PRNGKey(seed), n)
    groups = {"all": np.ones(n, bool)}
    if env.spec.kind == "pickup":
        air = state[:, 2] > 0.03  # the cube's centre sits at its half size on the table
        groups = {"held_in_air": air, "on_table": ~air}
    out = {}
    for name, m in groups.items():
        if not m.any():
            continue
        # the segmentation evaluation's scores, with its threshold sweep, on these images;
        # besides, which stage loses the object's pixels (pooled over the images)
        summary, arrays = pipeline.score(seg, rgb[m], labels[m])
        true = arrays["labels"] == 2
        out[name] = {**summary,
                     "foreground_keeps_object": float((arrays["foreground"] & true).sum()
                                                      / max(true.sum(), 1)),
                     "unet_calls_object_robot": float((arrays["robot"] & true).sum()
                                                      / max(true.sum(), 1))}
    return out


class Observed(NamedTuple):
    """A checkpoint's object encoder and the observation sets of some analysis seeds, each
    rendered and encoded once for every table below."""
    env: object
    seg: object
    encode_object: Callable
    sets: dict  # seed -> analysis.ObservationSet
    codes: dict  # seed -> object codes [n, d] of that set's observations
    goal_codes: dict  # seed -> object code [d] of that set's goal image


def observed(task: str, ckpt: str, seeds: list[int], n: int) -> Observed:
    import envs_mjx
    from roll_jax import analysis as A

    cfg, pre, seg = A.load_checkpoint(ckpt, task)
    env = envs_mjx.make(task)
    _, encode_object = A.model_encoders(cfg, pre, seg)
    sets = {s: A.observation_set(env, jax.random.PRNGKey(s), n) for s in seeds}
    codes = {s: np.asarray(encode_object(sets[s].rgb), np.float64) for s in seeds}
    goal_codes = {s: np.asarray(encode_object(sets[s].goal_rgb[None]), np.float64)[0]
                  for s in seeds}
    return Observed(env, seg, encode_object, sets, codes, goal_codes)


def _fig5(distances, codes, goal_code) -> float:
    """Fig. 5's object Spearman: true distances against the codes' distances to the goal's."""
    from roll_jax import analysis as A

    return round(A.spearman(distances, np.linalg.norm(codes - goal_code, axis=1)), 4)


def goal_swap(ob: Observed) -> dict:
    from roll_jax import analysis as A

    env, sets, codes = ob.env, ob.sets, ob.codes
    seeds = list(sets)
    all_codes = np.concatenate([codes[s] for s in seeds])
    all_states = np.concatenate([sets[s].states for s in seeds])
    whole = np.concatenate([A.object_visibility(sets[s].labels) >= A.WHOLE_SHARE for s in seeds])

    out = {"goal_state": {str(s): sets[s].goal_state.round(4).tolist() for s in seeds},
           "swap": {}, "near_mean_goal_code": {}}
    for g in seeds:
        zg = ob.goal_codes[g]
        near = (np.asarray(env.object_distance(all_states, sets[g].goal_state)) < NEAR_M) & whole
        zn = all_codes[near].mean(0)
        out["near_mean_goal_code"][str(g)] = {
            "n_near": int(near.sum()), "goal_code_offset": round(float(np.linalg.norm(zg - zn)), 4),
            "near_code_spread": round(float(np.linalg.norm(all_codes[near] - zn, axis=1).mean()), 4),
            "spearman_object": _fig5(sets[g].distances, codes[g], zn)}
        for s in seeds:
            d = np.asarray(env.object_distance(sets[s].states, sets[g].goal_state))
            out["swap"][f"obs{s}_goal{g}"] = _fig5(d, codes[s], zg)
    return out


def hidden_at_mean(ob: Observed) -> dict:
    from roll_jax import analysis as A

    out = {}
    for s, obs in ob.sets.items():
        hidden = A.object_visibility(obs.labels) < A.HIDDEN_SHARE
        z = ob.codes[s].copy()
        z[hidden] = z[~hidden].mean(0)
        zg = ob.goal_codes[s]
        out[str(s)] = {"n_hidden": int(hidden.sum()),
                       "spearman_object": _fig5(obs.distances, ob.codes[s], zg),
                       "hidden_at_mean": _fig5(obs.distances, z, zg)}
    return out


def _min_median(x) -> list[float] | None:
    return [round(float(np.min(x)), 4), round(float(np.median(x)), 4)] if len(x) else None


def goal_position_sweep(ob: Observed, seed: int, n_goals: int) -> dict:
    """Fig. 5's object Spearman of one observation set (analysis seed `seed`) against
    `n_goals` goals drawn by `env.sample_goal`: how the ranking depends on where the goal lies
    in the goal space (its offset from the centre, per axis over the half-extent, the largest
    over the axes the space spans), on all observations and on those that show the object."""
    from roll_jax import analysis as A
    from roll_jax.segmentation import pipeline

    env, obs, codes = ob.env, ob.sets[seed], ob.codes[seed]
    shown = A.object_visibility(obs.labels) >= A.HIDDEN_SHARE

    rgb, labels, states = sampled_goals(env, jax.random.PRNGKey(10_000 + seed), n_goals)
    zg = np.asarray(ob.encode_object(rgb), np.float64)
    masks = pipeline.mask_scores(pipeline.segment(ob.seg, rgb), labels)
    lo, hi = (np.asarray(v, np.float64) for v in (env.spec.object_goal_low,
                                                  env.spec.object_goal_high))
    span = hi > lo  # (pickup's goal space is a plane: x is fixed)
    offset = np.max(np.abs(states[:, :len(lo)] - (lo + hi) / 2)[:, span]
                    / ((hi - lo) / 2)[span], axis=1)
    rows = []
    for g in range(n_goals):
        d = np.asarray(env.object_distance(obs.states, states[g]))
        z = np.linalg.norm(codes - zg[g], axis=1)
        rows.append({"goal_state": states[g].round(4).tolist(), "offset": round(float(offset[g]), 3),
                     "goal_object_pixels": int((labels[g] == 2).sum()),
                     "goal_mask_iou": round(float(masks["iou"][g]), 4),
                     "spearman_object": round(A.spearman(d, z), 4),
                     "shown_spearman_object": round(A.spearman(d[shown], z[shown]), 4)})
    fig5 = np.array([r["spearman_object"] for r in rows])
    middle = offset < 0.5
    return {"observation_seed": seed, "n_goals": n_goals, "goals": rows,
            "spearman_offset_vs_fig5": round(A.spearman(offset, fig5), 4),
            "fig5_goals_in_middle_half": _min_median(fig5[middle]),
            "fig5_goals_in_outer_half": _min_median(fig5[~middle]),
            "shown_fig5_min_median": _min_median([r["shown_spearman_object"] for r in rows])}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", required=True)
    p.add_argument("--seg", help="segmentation checkpoint dir (default: CKPT/segmentation)")
    p.add_argument("--ckpt", help="pretrain --out dir: also the goal-swap table")
    p.add_argument("--n", type=int, default=128, help="goal images to segment")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--n-obs", type=int, default=500)
    p.add_argument("--name", default=None)
    p.add_argument("--goal-sweep", type=int, default=0, metavar="K",
                   help="with --ckpt: Fig. 5 of the first seed's observations against K goals")
    a = p.parse_args(argv)
    if a.seg is None and a.ckpt is None:
        p.error("give --seg or --ckpt")
    if a.goal_sweep < 0 or (a.goal_sweep and not a.ckpt):
        p.error(f"--goal-sweep wants a count >= 1 and --ckpt, got {a.goal_sweep}"
                + ("" if a.ckpt else " without --ckpt"))
    seg_dir = a.seg or os.path.join(a.ckpt, "segmentation")
    res = {"task": a.task, "seg": os.path.abspath(seg_dir),
           "goal_segmentation": goal_segmentation(a.task, seg_dir, a.n, seed=123)}
    print("goal images:", {g: {k: v for k, v in r.items() if k != "threshold_sweep"}
                           for g, r in res["goal_segmentation"].items()})
    if a.ckpt:
        res["ckpt"] = os.path.abspath(a.ckpt)
        ob = observed(a.task, a.ckpt, a.seeds, a.n_obs)
        res.update(goal_swap(ob))
        print("Fig. 5 object Spearman, observation set x goal:", res["swap"])
        print("with the near-mean goal code:", res["near_mean_goal_code"])
        res["hidden_at_mean"] = hidden_at_mean(ob)
        print("hidden observations at the mean code:", res["hidden_at_mean"])
        if a.goal_sweep:
            res["goal_position_sweep"] = goal_position_sweep(ob, a.seeds[0], a.goal_sweep)
            print("goal position sweep:", {k: v for k, v in res["goal_position_sweep"].items()
                                           if k != "goals"})
    write_results(os.path.join(ROOT, "bench", "results",
                               f"goal_images_{a.name or a.task}.json"), res)


if __name__ == "__main__":
    main()
