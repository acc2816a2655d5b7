"""Diagnosis of pickup's pretrained encoders (`roll-analysis diagnose --task pickup`).

pickup has no corridor: the policy must lower the open claw onto the cube, close it and lift.
Four measurements, each a question a failed pickup run raises:

(a) `grasp`: does ROLL's reward pay for the grasp or only for hiding the cube? A scripted
    grasp from the reset (`envs_mjx.scripts.pickup_lift`: lower, close, lift) is encoded
    frame by frame like a goal image (segment -> object-VAE -> one LSTM step) and its latent
    distance taken to the goal image whose cube is nearest the lifted one. `lower_share`: the
    share of the whole fall (first frame to last) that lowering the open claw onto the cube
    already earns, the cube unmoved; `close_penalty_share`: the share that closing the claw
    then gives back. A reward that pays for the lift has both near 0.
(b) `goal_pairs`: over pairs of goal images, Spearman of the latent distance against the
    cube's distance (and against its y and z distances alone).
(c) `scene`: affine R^2 of hand and cube (y, z) from the scene-VAE means of goal images.
(d) `prior_goals`: N(0, I) samples through one LSTM step, each matched to the nearest goal
    image's latent: the share whose nearest goal holds the cube in the air, and how far they
    lie from any goal against the goals' own spacing.
"""

from __future__ import annotations

import numpy as np

N_GOALS = 512


def grasp_phases(actions) -> tuple[int, int]:
    """(first step that closes the claw, first step that lifts) of a pickup action sequence
    [T, 3] (a[1] dz, a[2] > 0 closes), 0-based."""
    actions = np.asarray(actions)
    close = int(np.argmax(actions[:, 2] > 0))
    return close, close + int(np.argmax(actions[close:, 1] > 0))


def _grasp(env):
    """(frames [T, 48, 48, 3], cube (y, z) [T, 2], grasp_phases) of the scripted grasp from
    the reset."""
    import jax
    import jax.numpy as jnp

    from envs_mjx.rollout import rollout
    from envs_mjx.scripts import pickup_lift

    actions = pickup_lift(30)
    s0 = env.reset(jax.random.PRNGKey(1))
    _, traj = jax.jit(lambda s, a: rollout(env, s, a, render=True))(s0, jnp.asarray(actions))
    return np.asarray(traj.rgb), np.asarray(traj.obj)[:, 1:], grasp_phases(actions)


def grasp_profile(latents, goal_latent, cube, goal_cube, first_close: int) -> dict:
    """(a) from the grasp's frame latents [T, d] and the goal's [d]; `first_close`: the first
    step that closes the claw."""
    from roll_jax.analysis.stats import spearman

    lat = np.linalg.norm(latents - goal_latent, axis=1)
    true = np.linalg.norm(cube - goal_cube, axis=1)
    fall = lat[0] - lat[-1]
    if fall <= 0:
        raise ValueError(f"the latent distance does not fall over the scripted grasp "
                         f"({lat[0]:.3f} -> {lat[-1]:.3f}): no reward for the lift at all")
    low = lat[:first_close].min()
    return {"spearman": spearman(true, lat),
            "lower_share": float((lat[0] - low) / fall),
            "close_penalty_share": float((lat[first_close] - low) / fall),
            "latent": np.round(lat, 4).tolist(), "cube_cm": np.round(true * 100, 2).tolist()}


def goal_pairs(z, cube, n: int = 4000) -> dict:
    """(b): latent against cube distance over random pairs of goals."""
    from roll_jax.analysis.stats import spearman

    rng = np.random.default_rng(0)
    i, j = rng.integers(0, len(z), n), rng.integers(0, len(z), n)
    lat = np.linalg.norm(z[i] - z[j], axis=1)
    return {"spearman": spearman(np.linalg.norm(cube[i] - cube[j], axis=1), lat),
            "spearman_y": spearman(np.abs(cube[i, 0] - cube[j, 0]), lat),
            "spearman_z": spearman(np.abs(cube[i, 1] - cube[j, 1]), lat)}


def prior_goals(z_prior, z_goals, cube) -> dict:
    """(d): the prior goals against the goal images' latents."""
    from envs_mjx.tasks import PICKUP_AIR_Z

    d = np.linalg.norm(z_prior[:, None] - z_goals[None], axis=2)
    nearest = np.argmin(d, 1)
    own = np.linalg.norm(z_goals[:, None] - z_goals[None], axis=2)
    np.fill_diagonal(own, np.inf)
    return {"share_nearest_in_air": float((cube[nearest, 1] >= PICKUP_AIR_Z).mean()),
            "nearest_goal_distance_median": float(np.median(d.min(1))),
            "goal_spacing_median": float(np.median(own.min(1)))}


def diagnose_pickup(run: str, seed: int = 0) -> dict:
    import jax
    import jax.numpy as jnp

    import envs_mjx
    from envs_mjx.tasks import PICKUP_AIR_Z
    from roll_jax.analysis.checkpoints import load_checkpoint, model_encoders
    from roll_jax.analysis.diagnose import trained_lstm
    from roll_jax.analysis.stats import affine_cv_r2
    from roll_jax.encoders.goal_encoding import Frozen, goal_encoder

    cfg, pre, seg = load_checkpoint(run, "pickup")
    if pre.object_vae is None or pre.lstm is None:
        raise ValueError(f"{run}: the pickup diagnosis needs ROLL's object-VAE and LSTM")
    env = envs_mjx.make("pickup")
    enc = goal_encoder(cfg)
    frozen = Frozen(seg=seg, object_vae=pre.object_vae.params)
    encode_scene, _ = model_encoders(cfg, pre, seg)
    frames = jax.jit(lambda x: enc.frame_latents(frozen, pre.scene_vae.params,
                                                 enc.goal_images(frozen, x)))
    k_goals, k_prior = jax.random.split(jax.random.PRNGKey(seed))
    goals = jax.vmap(env.sample_goal)(jax.random.split(k_goals, N_GOALS))
    rgb = np.asarray(jax.jit(jax.vmap(env.render))(goals))
    cube = np.asarray(jax.vmap(env.object_state)(goals))[:, 1:]
    hand = np.asarray(jax.vmap(env.hand_pos)(goals))[:, 1:]
    goal_frames = np.asarray(frames(rgb))
    grasp_rgb, grasp_cube, phases = _grasp(env)
    grasp_frames = np.asarray(frames(grasp_rgb))
    target = int(np.argmin(np.linalg.norm(cube - grasp_cube[-1], axis=1)))
    zs = np.asarray(encode_scene(rgb), np.float64)
    out = {"task": "pickup", "run": run, "seed": seed, "n_goals": N_GOALS,
           "goal_share_in_air": float((cube[:, 1] >= PICKUP_AIR_Z).mean()),
           "grasp_goal_cube_yz": np.round(cube[target], 4).tolist(),
           "scene": {"hand_r2": affine_cv_r2(zs, hand.astype(np.float64), 5),
                     "cube_r2": affine_cv_r2(zs, cube.astype(np.float64), 5)}}
    lstms = [("", pre.lstm.params), ("_trained_lstm", trained_lstm(run))]
    for suffix, params in lstms:
        if params is None:
            continue
        z_goals = np.asarray(enc.single(params, jnp.asarray(goal_frames)))
        z_grasp = np.asarray(enc.single(params, jnp.asarray(grasp_frames)))
        out["grasp" + suffix] = grasp_profile(z_grasp, z_goals[target], grasp_cube, cube[target],
                                              phases[0])
        out["goal_pairs" + suffix] = goal_pairs(z_goals, cube)
        z_prior = np.asarray(enc.prior_goals(k_prior, params, N_GOALS))
        out["prior_goals" + suffix] = prior_goals(z_prior, z_goals, cube)
    out["grasp_cube_height_cm"] = np.round(grasp_cube[:, 1] * 100, 2).tolist()
    out["grasp_phases"] = list(phases)
    return out


def plot_grasps(results, png: str) -> None:
    """(a)'s profiles: per labelled result, the latent distance along the scripted grasp
    (over its first frame's), beside the cube's height."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    for label, r in results:
        lat = np.asarray(r["grasp"]["latent"])
        ax[0].plot(np.arange(1, len(lat) + 1), lat / lat[0], marker=".",
                   label=f"{label} (lowering earns {r['grasp']['lower_share']:.2f})")
    height = results[0][1]["grasp_cube_height_cm"]
    close, lift = results[0][1]["grasp_phases"]
    ax[1].plot(np.arange(1, len(height) + 1), height, "k.-")
    for a in ax:
        for x, txt in ((close + 0.5, "close"), (lift + 0.5, "lift")):
            a.axvline(x, color="grey", lw=0.8, ls=":")
            a.annotate(txt, (x + 0.2, 0.97), xycoords=("data", "axes fraction"), fontsize=8)
    ax[0].set(xlabel="step of the scripted grasp", ylabel="latent distance to the lifted goal "
              "/ at step 1", title="ROLL's reward signal along the grasp")
    ax[0].legend(fontsize=7, loc="lower left")
    ax[1].set(xlabel="step of the scripted grasp", ylabel="cube height (cm)",
              title=f"lowered onto (1-{close}), closed ({close + 1}-{lift}), lifted")
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)
