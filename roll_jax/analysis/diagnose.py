"""Diagnosis of a push task's pretrained encoders and its reset, before any tuning.

    roll-analysis diagnose --task hurdle_bottom --run DIR [--out FILE.json] [--png PRIOR.png]
    roll-analysis diagnose --plot before=A.json after=B.json --png PATHS.png
    roll-analysis diagnose --task pickup --run DIR     (its own measurements: diagnose_pickup.py)
    roll-analysis diagnose --task door_open [--run DIR] (c) from two hand starts; (b) with DIR

DIR holds segmentation/ and encoders/ (a `roll_jax.encoders.pretrain --out` or a `train.py` run
directory). Five measurements, each a question a failed learning run raises:

(a) `path`: does ROLL's reward point the right way along the way the puck must go? Pucks are
    placed every `step` along the task's corridor (`scenes.hurdle_path`; on puck_push a line
    across the table), the hand out of view; each image goes segment -> object-VAE -> one LSTM
    step, and its latent distance to a goal image's is ranked (Spearman) against the path
    distance to the goal: over the whole path, beyond and within 8 cm of the goal.
(b) `scene`: does the policy's input say where hand and puck are? The affine R^2 of hand xy
    and puck xy from the scene-VAE's means, over states with the hand uniform in its box and
    the puck where it can be (`env.random_placement`). On door_open: hand xyz and the door
    angle, over such placements and over random-policy episodes from the reset.
(c) `random_pushes`: can exploration find the way? The share of random-policy episodes from
    the task's reset whose puck moves >= 3 cm, and whose path distance to the goal falls by
    >= 3 cm.
(d) `prior_goals`: where are the goals the agent practises? N(0, I) samples through one LSTM
    step (Algorithm 1's exploration and relabelling goals), decoded by the object-VAE; each
    decoded puck's image centroid is matched to the nearest centroid of pucks rendered on a
    1 cm grid over the table: where it lies, and how many decoded images show no puck.
(e) `occlusion`: can hiding the puck pay? The latent distance to the goal of an empty
    segmented image (the puck wholly hidden, as by the claw over it) against (a)'s profile:
    the share of path points where the visible puck scores worse than no puck. And does the
    LSTM remember a hidden puck? Per path point, `OCC_VISIBLE` frames with the puck visible
    then `OCC_HIDDEN` empty frames through the LSTM from a zero state: the `memory` of each
    hidden frame is 1 - |z_hidden - z_visible| / |z_empty - z_visible|, where z_visible is the
    last visible frame's encoding and z_empty one LSTM step on the empty image (1: the LSTM
    keeps the puck; 0: it encodes the empty image as one step would). On a train.py run
    directory (e) is measured twice: with the pretrained LSTM (`occlusion`) and with seed 0's
    LSTM as online training left it (`occlusion_trained_lstm`).
"""

from __future__ import annotations

import argparse
import json
import os

import numpy as np

NEAR = 0.08  # m: "within 8 cm of the goal"
TOWARDS = 0.03  # m: a random episode "moves the puck towards the goal" by this much
# Goal puck positions: the centre of each task's puck goal space.
GOALS = {"hurdle_bottom": (0.105, 0.60), "hurdle_top": (0.105, 0.575), "puck_push": (0.0, 0.6)}
OCC_VISIBLE, OCC_HIDDEN = 10, 20  # (e): frames with the puck in view, then hidden


# ----------------------------------------------------------------------------- path geometry

def task_path(task: str) -> np.ndarray:
    """Waypoints [k, 2] of the way the puck can take to its goal: the hurdle corridor
    (`scenes.hurdle_path`, ending at the goal column), or on puck_push a line along x through
    the goal."""
    from envs_mjx import scenes

    if task in scenes.MIDDLE_WALL:
        return np.asarray(scenes.hurdle_path(task), np.float64)
    if task == "puck_push":
        gy = GOALS[task][1]
        return np.asarray([(-0.15, gy), (0.15, gy)], np.float64)
    raise ValueError(f"task {task!r} has no puck path; expected one of {sorted(GOALS)}")


def arclength(path: np.ndarray, points) -> np.ndarray:
    """Arclength [n] of each point's projection onto the polyline `path` [k, 2]."""
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    seg_a, seg_b = path[:-1], path[1:]
    d = seg_b - seg_a
    lengths = np.linalg.norm(d, axis=1)
    start = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
    t = np.clip(np.einsum("nkj,kj->nk", pts[:, None] - seg_a[None], d) / lengths ** 2, 0, 1)
    proj = seg_a[None] + t[..., None] * d[None]
    dist = np.linalg.norm(pts[:, None] - proj, axis=2)
    k = np.argmin(dist, axis=1)
    return start[k] + t[np.arange(len(pts)), k] * lengths[k]


def path_points(path: np.ndarray, step: float) -> np.ndarray:
    """Points about every `step` along the polyline (each segment cut in equal parts of
    about `step`; both ends included)."""
    out = []
    for a, b in zip(path[:-1], path[1:]):
        n = max(int(round(np.linalg.norm(b - a) / step)), 1)
        out.append(a + np.linspace(0, 1, n, endpoint=False)[:, None] * (b - a))
    out.append(path[-1:])
    return np.concatenate(out)


def path_distance(path: np.ndarray, points, goal) -> np.ndarray:
    """Distance along the path from each point to the goal (both projected onto it)."""
    return np.abs(arclength(path, points) - arclength(path, goal)[0])


# ----------------------------------------------------------------------------- measurements

def _render_fn(env):
    import jax

    def one(hand, puck):
        return env.render(env.place(hand, puck))

    return jax.jit(jax.vmap(one))


def _hand_away(env) -> np.ndarray:
    return np.asarray(env.spec.hand_away, np.float32)


def _goal_hand(env) -> np.ndarray:
    s = env.spec
    xy = (np.asarray(s.hand_goal_low) + np.asarray(s.hand_goal_high)) / 2
    return np.asarray([*xy, s.hand_low[2]], np.float32)


def latent_along_path(env, encode_object, step: float = 0.01) -> dict:
    """(a): the object latent distance along the task path against the path distance."""
    path = task_path(env.name)
    goal = np.asarray(GOALS[env.name])
    pts = path_points(path, step)
    render = _render_fn(env)
    away = np.repeat(_hand_away(env)[None], len(pts), 0)
    rgb = np.asarray(render(away, pts.astype(np.float32)))
    goal_rgb = np.asarray(render(_goal_hand(env)[None], goal[None].astype(np.float32)))
    z = np.asarray(encode_object(rgb))
    zg = np.asarray(encode_object(goal_rgb))[0]
    lat = np.linalg.norm(z - zg, axis=-1)
    pd = path_distance(path, pts, goal)
    start = (np.asarray(env.spec.object_reset_low) + np.asarray(env.spec.object_reset_high)) / 2
    profile = {"path_cm": np.round(pd * 100, 2).tolist(), "latent": np.round(lat, 4).tolist(),
               "puck_xy": np.round(pts, 4).tolist(),
               "reset_path_cm": round(float(path_distance(path, start, goal)[0] * 100), 2)}
    return {"goal": goal.tolist(), "step": step, "n": int(len(pts)),
            **profile_spearman(profile), "profile": profile}


def profile_spearman(profile: dict) -> dict:
    """Spearman of latent against path distance over the whole path, beyond and within 8 cm of
    the goal, and on the way from the puck's reset to the goal (path distance up to the
    reset's: the part a policy must push it along)."""
    from roll_jax.analysis.stats import spearman

    pd, lat = np.asarray(profile["path_cm"]) / 100, np.asarray(profile["latent"])
    parts = {"spearman": np.ones_like(pd, bool), "spearman_beyond_8cm": pd > NEAR,
             "spearman_within_8cm": pd <= NEAR,
             "spearman_on_the_way": pd <= profile["reset_path_cm"] / 100 + 1e-9}
    return {k: spearman(pd[m], lat[m]) if m.sum() > 2 else None for k, m in parts.items()}


def scene_r2(env, encode_scene, key, n: int = 1000) -> dict:
    """(b): affine R^2 of the hand's position (the axes its box spans: xy on the pushes, xyz on
    the door) and of the object's state (puck xy; door angle) from the scene latents
    (held-out, 5 folds), over states with the hand uniform in its box and the object where it
    can be (`env.random_placement`)."""
    import jax

    @jax.jit
    def draw(keys):
        def one(k):
            st = env.random_placement(*jax.random.split(k))
            return env.render(st), env.hand_pos(st), env.object_state(st)

        return jax.vmap(one)(keys)

    rgb, hand, obj = map(np.asarray, draw(jax.random.split(key, n)))
    return {"n": n, **_state_r2(env, encode_scene(rgb), hand, obj)}


def scene_r2_random_episodes(env, encode_scene, key, n_episodes: int = 16) -> dict:
    """(b) over what exploration sees first: every frame of `n_episodes` random-policy
    episodes from the task's reset."""
    import jax

    from envs_mjx.rollout import random_actions, rollout

    @jax.jit
    def run(keys):
        def one(k):
            k_r, k_a = jax.random.split(k)
            _, traj = rollout(env, env.reset(k_r),
                              random_actions(k_a, env.horizon, env.action_size), render=True)
            return traj.rgb, traj.hand, traj.obj

        return jax.vmap(one)(keys)

    rgb, hand, obj = (np.asarray(x).reshape((-1,) + x.shape[2:])
                      for x in run(jax.random.split(key, n_episodes)))
    return {"n": len(rgb), "episodes": n_episodes, **_state_r2(env, encode_scene(rgb), hand, obj)}


def _state_r2(env, latents, hand, obj) -> dict:
    from roll_jax.analysis.stats import affine_cv_r2

    z = np.asarray(latents, np.float64)
    axes = np.flatnonzero(np.asarray(env.spec.hand_high) > np.asarray(env.spec.hand_low))
    name = {"push": "puck", "door": "door_angle", "pickup": "cube"}[env.kind]
    hand = np.asarray(hand, np.float64)
    return {"hand_axes": "".join("xyz"[i] for i in axes),
            "hand_r2": affine_cv_r2(z, hand[:, axes], 5),
            "hand_r2_per_axis": [affine_cv_r2(z, hand[:, i:i + 1], 5) for i in axes],
            f"{name}_r2": affine_cv_r2(z, np.asarray(obj, np.float64), 5),
            f"{name}_std": np.round(np.asarray(obj).std(0), 4).tolist()}


def random_pushes(env, key, n: int = 256) -> dict:
    """(c): random-policy episodes from the reset: how often the puck moves, and moves
    towards the goal along the path."""
    import jax

    from envs_mjx.rollout import random_actions, rollout

    @jax.jit
    def run(keys):
        def one(k):
            k_r, k_a = jax.random.split(k)
            s0 = env.reset(k_r)
            _, traj = rollout(env, s0, random_actions(k_a, env.horizon, env.action_size))
            return env.object_state(s0), traj.obj[-1]

        return jax.vmap(one)(keys)

    start, end = map(np.asarray, run(jax.random.split(key, n)))
    path, goal = task_path(env.name), np.asarray(GOALS[env.name])
    gain = path_distance(path, start, goal) - path_distance(path, end, goal)
    moved = np.linalg.norm(end - start, axis=1)
    return {"n": n, "hand_reset": list(env.spec.hand_reset[:2]),
            "moved_3cm": float(np.mean(moved >= TOWARDS)),
            "towards_goal_3cm": float(np.mean(gain >= TOWARDS)),
            "mean_gain_cm": float(gain.mean() * 100)}


def door_exploration(env, key, hands: dict, n: int = 48) -> dict:
    """(c) on door_open: per named hand start (door closed), how often a random policy's
    `horizon`-step episode opens the door by >= 0.05 / 0.2 rad; needs no encoders."""
    import jax
    import jax.numpy as jnp

    from envs_mjx.rollout import random_actions, rollout

    @jax.jit
    def run(keys, hand):
        def one(k):
            s0 = env.place(hand, jnp.zeros((1,)))
            _, traj = rollout(env, s0, random_actions(k, env.horizon, env.action_size))
            return traj.obj[:, 0]

        return jax.vmap(one)(keys)

    out = {}
    for name, hand in hands.items():
        widest = np.asarray(run(jax.random.split(key, n), jnp.asarray(hand, jnp.float32))).max(1)
        out[name] = {"hand": list(hand), "n": n, "opened_0.05": float(np.mean(widest >= 0.05)),
                     "opened_0.2": float(np.mean(widest >= 0.2)),
                     "mean_widest_rad": float(widest.mean())}
    return out


def door_scene(run: str, key) -> dict:
    """(b) on door_open: the scene latents of `run`'s encoders over random placements and over
    random-policy episodes from the reset."""
    import jax

    import envs_mjx
    from roll_jax.analysis.checkpoints import load_checkpoint, model_encoders

    cfg, pre, seg = load_checkpoint(run, "door_open")
    env = envs_mjx.make("door_open")
    encode_scene, _ = model_encoders(cfg, pre, seg)
    k_p, k_e = jax.random.split(key)
    return {"scene_pretrain_data": cfg.scene_pretrain_data,
            "scene": scene_r2(env, encode_scene, k_p),
            "scene_random_episodes": scene_r2_random_episodes(env, encode_scene, k_e)}


def _centroids(images, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Intensity-weighted centroid (row, col) and mass of the pixels above `threshold` of
    float images [n, H, W, 3] in [0, 1]."""
    v = np.asarray(images, np.float64).max(-1)
    w = np.where(v > threshold, v, 0.0)
    mass = w.sum((1, 2))
    rows, cols = np.mgrid[:v.shape[1], :v.shape[2]]
    c = np.stack([(w * rows).sum((1, 2)), (w * cols).sum((1, 2))], 1) / np.maximum(mass, 1e-9)[:, None]
    return c, mass


def prior_goal_positions(env, cfg, pre, seg, key, n: int = 256) -> tuple[dict, np.ndarray]:
    """(d): decoded prior goals -> where their pucks lie. Returns (summary, decoded images)."""
    import jax

    from roll_jax.encoders import models
    from roll_jax.encoders.goal_encoding import Frozen, goal_encoder
    from roll_jax.segmentation import pipeline

    enc = goal_encoder(cfg)
    goals = enc.prior_goals(key, pre.lstm.params if pre.lstm is not None else None, n)
    decoded = np.asarray(models.decode(pre.object_vae.params, enc.object_cfg, goals))
    # Reference: pucks on a 1 cm grid over the table, hand out of view, segmented as the
    # object-VAE sees them.
    xs, ys = np.arange(-0.2, 0.2001, 0.01), np.arange(0.45, 0.8001, 0.01)
    grid = np.stack(np.meshgrid(xs, ys, indexing="ij"), -1).reshape(-1, 2).astype(np.float32)
    rgb = np.asarray(_render_fn(env)(np.repeat(_hand_away(env)[None], len(grid), 0), grid))
    frozen = Frozen(seg=seg, object_vae=pre.object_vae.params)
    seg_rgb = np.asarray(jax.jit(enc.goal_images)(frozen, rgb)) / 255.0
    ref_c, ref_mass = _centroids(seg_rgb, 0.1)
    c, mass = _centroids(decoded, 0.1)
    shown = ref_mass > 0.5 * np.median(ref_mass)
    d = np.linalg.norm(c[:, None] - ref_c[None, shown], axis=2)
    nearest = grid[shown][np.argmin(d, axis=1)]
    empty = mass < 0.25 * np.median(ref_mass[shown])
    in_region = np.zeros(n, bool)
    for lo, hi in env.spec.region:
        in_region |= np.all((nearest >= np.asarray(lo) - 0.01) & (nearest <= np.asarray(hi) + 0.01), 1)
    goal_lo, goal_hi = np.asarray(env.spec.object_goal_low), np.asarray(env.spec.object_goal_high)
    in_goal = np.all((nearest >= goal_lo - 0.01) & (nearest <= goal_hi + 0.01), 1)
    full = ~empty
    summary = {"n": n, "empty_share": float(empty.mean()),
               "in_region_share": float(in_region[full].mean()) if full.any() else None,
               "in_goal_space_share": float(in_goal[full].mean()) if full.any() else None,
               "mass_vs_real_puck": float(np.median(mass) / np.median(ref_mass[shown])),
               "puck_xy_mean": np.round(nearest[full].mean(0), 4).tolist() if full.any() else None,
               "puck_xy_std": np.round(nearest[full].std(0), 4).tolist() if full.any() else None,
               "puck_xy": np.round(nearest, 3).tolist()}
    return summary, decoded


def write_prior_png(decoded, path: str, n: int = 32) -> None:
    import cv2

    x = (np.asarray(decoded[:n]) * 255).round().astype(np.uint8)
    rows = [np.concatenate(list(x[i:i + 8]), 1) for i in range(0, len(x) - len(x) % 8, 8)]
    grid = np.concatenate(rows, 0)
    grid = cv2.resize(grid, (grid.shape[1] * 2, grid.shape[0] * 2), interpolation=cv2.INTER_NEAREST)
    cv2.imwrite(path, grid[..., ::-1])


def occlusion(enc, frozen, scene_params, lstm_params, path: dict) -> dict:
    """(e) with the LSTM `lstm_params`: the empty image's latent distance to the goal against
    the visible puck's along the path, and the LSTM's memory of a puck hidden after
    `OCC_VISIBLE` visible frames. `path`: (a)'s result plus `visible_latents` [P, d] and
    `goal_frame_latent` [d], the object-VAE means of its images and of the goal image."""
    import jax
    import jax.numpy as jnp

    empty = enc.frame_latents(frozen, scene_params, jnp.zeros((1, 48, 48, 3), jnp.float32))
    vis = jnp.asarray(path["visible_latents"])  # [P, d]
    goal_z = np.asarray(enc.single(lstm_params, jnp.asarray(path["goal_frame_latent"])[None]))[0]
    z_empty = np.asarray(enc.single(lstm_params, empty))[0]
    d_empty = float(np.linalg.norm(z_empty - goal_z))
    lat = np.linalg.norm(np.asarray(enc.single(lstm_params, vis)) - goal_z, axis=-1)
    pcm = np.asarray(path["profile"]["path_cm"])
    seq = jnp.concatenate([jnp.repeat(vis[:, None], OCC_VISIBLE, 1),
                           jnp.repeat(empty[None], vis.shape[0], 0).repeat(OCC_HIDDEN, 1)], 1)
    z = np.asarray(jax.vmap(lambda x: enc.sequence(lstm_params, x))(seq))  # [P, T, d]
    z_vis = z[:, OCC_VISIBLE - 1]
    gap = np.linalg.norm(z_empty[None] - z_vis, axis=-1)
    err = np.linalg.norm(z[:, OCC_VISIBLE:] - z_vis[:, None], axis=-1)  # [P, hidden]
    memory = 1.0 - err / np.maximum(gap, 1e-6)[:, None]
    beaten = pcm[lat < d_empty]
    return {"empty_latent_distance": round(d_empty, 4),
            "share_of_path_worse_than_empty": round(float((lat > d_empty).mean()), 3),
            "visible_beats_empty_within_cm": float(beaten.max()) if beaten.size else 0.0,
            "memory_first_hidden_frame": round(float(np.median(memory[:, 0])), 3),
            "memory_last_hidden_frame": round(float(np.median(memory[:, -1])), 3),
            "memory_per_hidden_frame": [round(float(m), 3) for m in np.median(memory, 0)]}


def diagnose(task: str, run: str, seed: int = 0, png: str | None = None) -> dict:
    import jax

    import envs_mjx
    from roll_jax.analysis.checkpoints import load_checkpoint, model_encoders

    if task not in GOALS:
        raise ValueError(f"diagnose covers the push tasks {sorted(GOALS)}, got {task!r}")
    cfg, pre, seg = load_checkpoint(run, task)
    env = envs_mjx.make(task)
    encode_scene, encode_object = model_encoders(cfg, pre, seg)
    k_b, k_c, k_d = jax.random.split(jax.random.PRNGKey(seed), 3)
    out = {"task": task, "run": run, "seed": seed,
           "hand_box": [list(env.spec.hand_low[:2]), list(env.spec.hand_high[:2])],
           "path": latent_along_path(env, encode_object),
           "scene": scene_r2(env, encode_scene, k_b),
           "random_pushes": random_pushes(env, k_c)}
    if pre.object_vae is not None and pre.lstm is not None:
        out["prior_goals"], decoded = prior_goal_positions(env, cfg, pre, seg, k_d)
        if png:
            write_prior_png(decoded, png)
        enc, frozen, scene_params, lstm_params, full = _occlusion_inputs(env, cfg, pre, seg,
                                                                         out["path"])
        out["occlusion"] = occlusion(enc, frozen, scene_params, lstm_params, full)
        trained = trained_lstm(run)
        if trained is not None:  # the LSTM as online training left it (seed 0)
            out["occlusion_trained_lstm"] = occlusion(enc, frozen, scene_params, trained, full)
    return out


def trained_lstm(run: str):
    """Seed 0's LSTM parameters from a train.py run's latest checkpoint (None for a
    pretraining directory or a run without a checkpoint)."""
    import jax

    from roll_jax.analysis.checkpoints import is_run

    if not is_run(run):
        return None
    from roll_jax.analysis import evaluation

    try:
        loaded = evaluation.load_run(run)
    except FileNotFoundError:  # no checkpoint yet
        return None
    if loaded.state.lstm is None:
        return None
    return jax.tree.map(lambda x: x[0], loaded.state.lstm.params)


def _occlusion_inputs(env, cfg, pre, seg, path: dict):
    """(e)'s arguments: the goal encoder, and (a)'s result with the object-VAE means of its
    images (hand away) and the goal image's encoding."""
    from roll_jax.encoders.goal_encoding import Frozen, goal_encoder

    enc = goal_encoder(cfg)
    frozen = Frozen(seg=seg, object_vae=pre.object_vae.params)
    scene_params, lstm_params = pre.scene_vae.params, pre.lstm.params
    render = _render_fn(env)
    pts = np.asarray(path["profile"]["puck_xy"], np.float32)
    away = np.repeat(_hand_away(env)[None], len(pts), 0)

    def latents(hand, puck):
        return enc.frame_latents(frozen, scene_params, enc.goal_images(frozen, render(hand, puck)))

    goal = np.asarray(path["goal"], np.float32)[None]
    full = {**path, "visible_latents": latents(away, pts),
            "goal_frame_latent": latents(_goal_hand(env)[None], goal)[0]}
    return enc, frozen, scene_params, lstm_params, full


def plot_paths(results: dict, png: str) -> None:
    """(a)'s profiles side by side: per task, the latent distance to the goal against the path
    distance, one line per labelled result (`results`: [(label, `diagnose` output)])."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tasks = sorted({r["task"] for _, r in results})
    fig, axes = plt.subplots(1, len(tasks), figsize=(4.5 * len(tasks), 3.4), squeeze=False)
    for ax, task in zip(axes[0], tasks):
        for label, r in results:
            if r["task"] != task:
                continue
            prof = r["path"]["profile"]
            order = np.argsort(prof["path_cm"])
            ax.plot(np.asarray(prof["path_cm"])[order], np.asarray(prof["latent"])[order],
                    marker=".", label=f"{label} (Spearman {r['path']['spearman']:.2f})")
        ax.axvline(NEAR * 100, color="grey", lw=0.5, ls="--")
        ax.set(title=task, xlabel="path distance to the goal (cm)",
               ylabel="latent distance to the goal image")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(prog="roll-analysis diagnose", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--plot", nargs="+", metavar="LABEL=JSON", default=None,
                   help="instead of measuring: plot (a)'s profiles of written results into "
                        "--png, e.g. --plot before=a.json after=b.json")
    p.add_argument("--task", choices=sorted(GOALS) + ["pickup", "door_open"],
                   help="a push task, or pickup (roll_jax/analysis/diagnose_pickup.py); "
                        "required to measure; door_open measures (c) from its reset "
                        "and the reference's, and with --run (b)")
    p.add_argument("--n", type=int, default=48, help="door_open: random episodes per start")
    p.add_argument("--run", help="directory with segmentation/ and encoders/ (pretrain --out "
                                 "or a run); required to measure (door_open: optional)")
    p.add_argument("--out", default=None, help="JSON file to write (default: print only)")
    p.add_argument("--png", default=None, help="PNG of 32 decoded prior goals (push tasks); "
                                               "with --plot, the figure")
    p.add_argument("--seed", type=int, default=0, help="seed of the random draws")
    a = p.parse_args(argv)
    if a.plot:
        if not a.png:
            p.error("--plot needs --png")
        results = []
        for item in a.plot:
            label, sep, path = item.partition("=")
            if not sep:
                p.error(f"--plot takes LABEL=JSON, got {item!r}")
            with open(path) as f:
                results.append((label, json.load(f)))
        if all("grasp" in r for _, r in results):
            from roll_jax.analysis.diagnose_pickup import plot_grasps

            plot_grasps(results, a.png)
        elif any("grasp" in r for _, r in results):
            p.error("--plot takes either pickup results or push-task results, not both")
        else:
            plot_paths(results, a.png)
        return
    if a.task == "door_open":
        import jax

        import envs_mjx
        from envs_mjx.tasks import DOOR_REFERENCE_RESET

        if a.n < 1:
            p.error(f"--n must be positive, got {a.n}")
        env = envs_mjx.make("door_open")
        k_c = jax.random.PRNGKey(a.seed)
        k_b = jax.random.fold_in(k_c, 1)
        res = {"task": "door_open", "random_episodes": door_exploration(
            env, k_c,
            {"task reset": env.spec.hand_reset, "reference reset": DOOR_REFERENCE_RESET}, a.n)}
        if a.run:
            res.update(run=a.run, **door_scene(a.run, k_b))
    elif not (a.task and a.run):
        p.error("--task and --run are required to measure")
    elif a.task == "pickup":
        from roll_jax.analysis.diagnose_pickup import diagnose_pickup

        res = diagnose_pickup(a.run, a.seed)
    else:
        res = diagnose(a.task, a.run, a.seed, a.png)
    brief = {k: ({kk: vv for kk, vv in v.items() if kk not in ("profile", "puck_xy")}
                 if isinstance(v, dict) else v) for k, v in res.items()}
    print(json.dumps(brief, indent=1))
    if a.out:
        os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
        with open(a.out, "w") as f:
            json.dump(res, f, indent=1)


if __name__ == "__main__":
    main()
