"""Occlusion retrieval (appendix A "Occlusion analysis"), on a hurdle task: puck-moving
trajectories; one random frame t >= 1 per trajectory loses 85% of its object pixels; each
model encodes that frame (the LSTMs with the trajectory's history), the nearest clean frame
in latent space is retrieved from the pool of all clean frames, and the error is the true
puck distance between the retrieved frame and the occluded one. Models: (1) LSTM trained
with the matching loss, (2) the same LSTM trained without it, (3) the object-VAE alone;
all three on the same object-VAE, trained on the same trajectories. The models are also
scored along the LSTMs' training (`curve`).

    roll-analysis occlusion --ckpt DIR [--out DIR]

The core functions take encoders as plain callables (`occlusion_models` builds them), so
tests can feed synthetic images and ideal encoders. The two LSTMs train with the encoders'
own epoch (`steps.lstm_fit_epoch`, the matching loss's occlusions from
`steps.OcclusionSource`), as pretraining does.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import os
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from configs.encoders import HURDLE_TASKS, OCCLUSION_DROP  # noqa: F401 (occlusion.HURDLE_TASKS)
from roll_jax.analysis.checkpoints import batched, encode_frames, load_checkpoint
from roll_jax.analysis.stats import paired_difference, rounded_list
from roll_jax.encoders import steps
from roll_jax.encoders.models import lstm_encode
from roll_jax.segmentation import pipeline

# Appendix A, Fig. S1(a): estimation error of the occluded puck position (cm).
PAPER_ERROR_CM = {"lstm_matching": 1.0, "lstm": 2.2, "vae": 3.1}
OCCLUSION_MODELS = ("lstm_matching", "lstm", "vae")
# OCCLUSION_DROP (Appendix A: "removing 85% of the pixels") and HURDLE_TASKS live in configs/,
# which the command's parser reads without importing JAX.
# LSTM training steps at which the occlusion command also scores the three models (below
# the run's own length, which is scored too): the auto-encoder LSTM's retrieval changes with
# how far it has learned to copy its input (docs/analysis.md).
CURVE_STEPS = (0, 100, 200, 500, 1000, 2000, 5000)
HAND_BEHIND = 0.057  # puck radius 0.04 + claw radius 0.015 + 2 mm: the hand touching the puck


def puck_paths(key, task: str, n: int, horizon: int, speed=(0.003, 0.008), jitter: float = 0.005):
    """Kinematic pushes along the task's hurdle path (`envs_mjx.scenes.hurdle_path`): per
    trajectory a random start on the path, a random speed (m/step, +-30% per-step noise)
    and a constant random offset of up to `jitter` per axis; the puck stops at the end of
    the path. The hand stays just behind the
    puck (against the direction of motion), as when pushing it.

    Returns numpy (puck xy [n, T, 2], hand xy [n, T, 2])."""
    from envs_mjx.scenes import hurdle_path

    way = np.asarray(hurdle_path(task), np.float64)  # ValueError for a task without a hurdle
    rng = np.random.default_rng(int(jax.random.randint(key, (), 0, 2**31 - 1)))
    seg = np.diff(way, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    cum = np.r_[0.0, np.cumsum(seg_len)]
    total = cum[-1]
    v = rng.uniform(*speed, size=(n, 1))
    step_len = v * rng.uniform(0.7, 1.3, size=(n, horizon))
    s0 = rng.uniform(0.0, total - 0.05, size=(n, 1))
    s = np.clip(s0 + np.cumsum(step_len, axis=1) - step_len[:, :1], 0.0, total)
    i = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
    frac = (s - cum[i]) / seg_len[i]
    offset = rng.uniform(-jitter, jitter, size=(n, 1, 2))
    puck = way[i] + frac[..., None] * seg[i] + offset
    tangent = seg[i] / seg_len[i][..., None]
    hand = puck - HAND_BEHIND * tangent
    return puck.astype(np.float32), hand.astype(np.float32)


def render_pushes(env, puck, hand, chunk: int = 256) -> np.ndarray:
    """uint8 [n, T, 48, 48, 3]: each (puck xy, hand xy) placed with `env.place` and rendered."""
    lo, hi = env.hand_bounds
    shape = puck.shape[:-1]
    hand3 = np.concatenate([hand.reshape(-1, 2), np.full((hand[..., 0].size, 1), lo[2])], -1)
    hand3 = np.clip(hand3, lo, hi).astype(np.float32)
    both = np.concatenate([hand3, puck.reshape(-1, 2)], -1)

    @jax.jit
    def run(x):
        return jax.vmap(lambda r: env.render(env.place(r[:3], r[3:])))(x)

    return batched(run, both, chunk).reshape(shape + (48, 48, 3))


def occlude_frames(key, images, masks, drop: float = OCCLUSION_DROP, min_t: int = 1):
    """`steps.occlusion_frames` as numpy: (t [B], occluded frames [B, 48, 48, 3]) of
    segmented uint8 images [B, T, 48, 48, 3] with masks [B, T, 48, 48] (or None)."""
    t, occ = steps.occlusion_frames(key, jnp.asarray(images),
                                       None if masks is None else jnp.asarray(masks), min_t, drop)
    return np.asarray(t), np.asarray(occ)


def retrieval_errors(clean_codes, query_codes, positions, occ_t, exclude_own: bool = False
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Nearest clean frame (L2 in code space, over all B*T frames, or with `exclude_own` over
    the frames of the other trajectories) of each query; returns (position error per query
    [B] in the units of `positions`, retrieved flat index [B]).

    clean_codes [B, T, d]; query_codes [B, d]; positions [B, T, k]; occ_t [B]."""
    clean = np.asarray(clean_codes, np.float64)
    b, t_len, d = clean.shape
    pool = clean.reshape(b * t_len, d)
    q = np.asarray(query_codes, np.float64)
    d2 = (np.sum(q * q, 1)[:, None] - 2.0 * q @ pool.T + np.sum(pool * pool, 1)[None, :])
    if exclude_own:
        d2[np.arange(b * t_len)[None, :] // t_len == np.arange(b)[:, None]] = np.inf
    nn = np.argmin(d2, axis=1)
    pos = np.asarray(positions, np.float64)
    truth = pos[np.arange(b), np.asarray(occ_t)]
    err = np.linalg.norm(pos.reshape(b * t_len, -1)[nn] - truth, axis=-1)
    return err, nn


def occlusion_queries(key, images, masks, frame_encoder: Callable,
                      drop: float = OCCLUSION_DROP, min_t: int = 1):
    """The queries of `occlusion_retrieval`: (per-frame latents of the clean trajectories
    [B, T, d], the same with frame occ_t[b] replaced by its occluded latent, occ_t [B])."""
    images = np.asarray(images)
    b, t_len = images.shape[:2]
    occ_t, occluded = occlude_frames(key, images, masks, drop, min_t)
    lat = np.asarray(frame_encoder(images.reshape((-1,) + images.shape[2:])))
    lat = lat.reshape(b, t_len, -1)
    occ_seq = lat.copy()
    occ_seq[np.arange(b), occ_t] = np.asarray(frame_encoder(occluded))
    return lat, occ_seq, occ_t


def score_heads(lat, occ_seq, occ_t, positions, heads: dict[str, Callable],
                scale: float = 100.0, exclude_own: bool = False) -> dict:
    """Retrieval error of each head on the queries of `occlusion_queries` (keys as
    `occlusion_retrieval`'s; `exclude_own`: retrieve from the other trajectories only)."""
    b, t_len = lat.shape[:2]
    pos = np.asarray(positions, np.float64)
    truth = pos[np.arange(b), occ_t]
    chance = np.linalg.norm(pos.reshape(1, b * t_len, -1) - truth[:, None], axis=-1).mean()
    out = {"error_cm": {}, "median_cm": {}, "errors_cm": {}, "retrieved": {}, "occ_t": occ_t,
           "n_queries": int(b), "pool_size": int(b * t_len), "chance_cm": float(chance * scale)}
    for name, head in heads.items():
        clean = np.asarray(head(lat))
        query = np.asarray(head(occ_seq))[np.arange(b), occ_t]
        err, nn = retrieval_errors(clean, query, positions, occ_t, exclude_own)
        err = err * scale
        out["errors_cm"][name] = err
        out["retrieved"][name] = nn
        out["error_cm"][name] = [float(err.mean()), float(err.std())]
        out["median_cm"][name] = float(np.median(err))
    return out


def occlusion_retrieval(key, images, masks, positions, frame_encoder: Callable,
                        heads: dict[str, Callable], drop: float = OCCLUSION_DROP,
                        min_t: int = 1, scale: float = 100.0) -> dict:
    """Appendix A. images: segmented uint8 [B, T, 48, 48, 3] (clean trajectories); masks
    their object masks [B, T, 48, 48] (or None); positions the true puck xy [B, T, 2] (m).

    frame_encoder: images [N, 48, 48, 3] -> per-frame latents [N, d] (the object-VAE mean);
    heads: name -> f(latents [B, T, d]) -> codes [B, T, d'] (an LSTM over each trajectory, or
    the identity for the VAE alone). For each trajectory one frame t >= min_t is occluded
    (`drop` of its object pixels removed); its code is the head's output at t on the
    trajectory with frame t replaced; the nearest clean code among all B*T frames is
    retrieved. Returns {"error_cm": {name: [mean, std]}, "median_cm": {name: median},
    "errors_cm": {name: [B]}, "occ_t",
    "retrieved", "n_queries", "pool_size", "chance_cm"} (errors in positions' units times
    `scale`; chance_cm: the mean error of a uniformly random pick from the pool)."""
    lat, occ_seq, occ_t = occlusion_queries(key, images, masks, frame_encoder, drop, min_t)
    return score_heads(lat, occ_seq, occ_t, positions, heads, scale)


def ordering_holds(res: dict) -> bool:
    """The paper's ordering LSTM + matching < LSTM < object-VAE by mean error, each step
    separated by more than two standard errors of the paired difference."""
    e = res["errors_cm"]
    return all(d[0] + 2.0 * d[1] < 0.0 for d in (paired_difference(e["lstm_matching"], e["lstm"]),
                                                 paired_difference(e["lstm"], e["vae"])))


# --- the three models --------------------------------------------------------------------
@functools.partial(jax.jit, static_argnames=("cfg",))
def _finetune_vae(state, key, images, masks, cfg):
    return steps.vae_fit_epoch(state, key, images, cfg, masks)


def finetune_vae(key, state: steps.ModelState, cfg, images, masks, n_steps: int,
                 batch: int | None = None, chunk: int = 100):
    """`n_steps` object-VAE steps (its config's loss: beta-VAE + VAE matching; the trajectory
    frames have no arm-pair partners) on frames [N, 48, 48, 3] with object masks [N, 48, 48].
    Returns (state, losses [n_steps])."""
    images, masks = jnp.asarray(images), jnp.asarray(masks)
    batch = batch or cfg.batch_size
    hist = []
    for i in range(0, n_steps, chunk):
        c = dataclasses.replace(cfg, batch_size=batch, batches_per_epoch=min(chunk, n_steps - i),
                                arm_pair_coef=0.0)
        state, m = _finetune_vae(state, jax.random.fold_in(key, i), images, masks, c)
        hist.append(np.asarray(m["loss"]))
    return state, (np.concatenate(hist) if hist else np.zeros((0,)))


# Jitted once per config: the LSTM steps of every segment between snapshots share a program.
_fit_lstm = jax.jit(steps.lstm_fit_epoch, static_argnames=("cfg", "batches"))


def train_occlusion_lstms(key, vae_params, vae_cfg, lstm_cfg, images, masks, n_steps: int,
                          batch: int = 25, chunk: int = 100, snapshot_steps=()):
    """Two LSTMs from the same initialisation on the same batches of the same trajectories
    (segmented uint8 [B, T, 48, 48, 3], masks [B, T, 48, 48]) over the same object-VAE: one
    with auto-encoder + matching loss (synthetic occlusion from `make_occlusion`, drop
    lstm_cfg.occlusion_drop), one with the auto-encoder loss only.

    Returns ({"lstm_matching": params, "lstm": params}, {name: losses [n_steps]},
    {step: {name: params}} after each of `snapshot_steps` (0 = the initialisation))."""
    bad = [s for s in snapshot_steps if not 0 <= s <= n_steps]
    if bad:
        raise ValueError(f"snapshot_steps {bad} outside 0..n_steps={n_steps}")
    images, masks = jnp.asarray(images), jnp.asarray(masks)
    latents = encode_frames(vae_params, vae_cfg, images)
    k_init, k_train = jax.random.split(key)
    init = steps.init_lstm(k_init, lstm_cfg, latents.shape[-1])
    # Segments of `chunk` steps, also cut at the snapshots; a segment's batches come from its
    # first step's key, so snapshots at multiples of `chunk` leave the training unchanged.
    starts = sorted(set(range(0, n_steps, chunk)) | {s for s in snapshot_steps if s < n_steps})
    params, hist = {}, {}
    snapshots = {int(s): {} for s in snapshot_steps}
    cfg = dataclasses.replace(lstm_cfg, batch_size=batch)
    source = steps.OcclusionSource(images, masks, vae_params, vae_cfg)
    for name, occlusions in (("lstm_matching", source), ("lstm", None)):
        st, h = init, []
        for i, end in zip(starts, starts[1:] + [n_steps]):
            if i in snapshots:
                snapshots[i][name] = st.params
            st, m = _fit_lstm(st, jax.random.fold_in(k_train, i), latents, cfg, end - i,
                              occlusions)
            h.append(np.asarray(m["loss"]))
        if n_steps in snapshots:
            snapshots[n_steps][name] = st.params
        params[name] = st.params
        hist[name] = np.concatenate(h) if h else np.zeros((0,))
    return params, hist, snapshots


_lstm_codes = jax.jit(lambda p, z: lstm_encode(p, z))  # one program for every set of weights


def occlusion_models(vae_params, vae_cfg, lstm_params: dict) -> tuple[Callable, dict]:
    """(frame_encoder, heads) for `occlusion_retrieval`: the object-VAE mean per frame; the
    two LSTMs over each trajectory (from the zero state) and the identity for the VAE alone."""
    def frame_encoder(x):
        return np.asarray(encode_frames(vae_params, vae_cfg, x))

    heads = {name: functools.partial(lambda p, z: np.asarray(_lstm_codes(p, jnp.asarray(z))), p)
             for name, p in lstm_params.items()}
    heads["vae"] = lambda z: np.asarray(z)
    return frame_encoder, heads


def write_occlusion(result: dict, out_dir: str, task: str, extra: dict | None = None
                    ) -> tuple[str, str]:
    """Bar plot (mean +- std per model, paper values as markers) and JSON."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(out_dir, exist_ok=True)
    png = os.path.join(out_dir, f"occlusion_{task}.png")
    js = os.path.join(out_dir, f"occlusion_{task}.json")
    names = list(result["error_cm"])
    labels = {"lstm_matching": "LSTM +\nmatching loss", "lstm": "LSTM", "vae": "object-VAE"}
    mean = [result["error_cm"][k][0] for k in names]
    std = [result["error_cm"][k][1] for k in names]
    fig, ax = plt.subplots(figsize=(4.2, 3.4))
    xs = np.arange(len(names))
    ax.bar(xs, mean, yerr=std, capsize=4, color=["tab:blue", "tab:orange", "tab:green"][:len(names)],
           alpha=0.8, label="this run")
    paper = [PAPER_ERROR_CM.get(k, np.nan) for k in names]
    ax.scatter(xs, paper, marker="D", s=30, color="crimson", zorder=3, label="paper (App. A)")
    if result.get("chance_cm") is not None:
        ax.axhline(result["chance_cm"], color="grey", ls="--", lw=1, label="random frame")
    ax.set_xticks(xs)
    ax.set_xticklabels([labels.get(k, k) for k in names], fontsize=8)
    ax.set_ylabel("puck position error (cm)")
    ax.set_title(f"{task}: occluded-frame retrieval (n={result['n_queries']})", fontsize=9)
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)
    summary = {"task": task, "error_cm": result["error_cm"], "median_cm": result["median_cm"],
               "n_queries": result["n_queries"], "pool_size": result["pool_size"],
               "chance_cm": result.get("chance_cm"),
               "paper_error_cm": PAPER_ERROR_CM, **(extra or {}),
               "errors_cm": {k: rounded_list(v) for k, v in result["errors_cm"].items()},
               "occ_t": [int(t) for t in result["occ_t"]]}
    with open(js, "w") as f:
        json.dump(summary, f, indent=1)
    return png, js


def curve_row(step: int, res: dict, hist: dict, others: dict | None = None,
              clean: dict | None = None, window: int = 20) -> dict:
    """One point of the occlusion command's curve: `res` (`score_heads`) after `step` LSTM
    steps, with the paired differences, the share of queries for which the auto-encoder LSTM
    retrieves the very frame the object-VAE does, each LSTM's mean training loss over the
    `window` steps before (None at step 0), `others` (`score_heads` on the other
    trajectories' frames) under "other_trajectories" and `clean` (the same for the clean
    frames at the occluded steps) under "clean_frames"."""
    e, r = res["errors_cm"], res["retrieved"]
    extra = {} if others is None else {"other_trajectories": {
        "error_cm": others["error_cm"], "median_cm": others["median_cm"],
        "ordering_holds": ordering_holds(others)}}
    if clean is not None:
        extra["clean_frames"] = {"error_cm": clean["error_cm"], "median_cm": clean["median_cm"]}
    return {"lstm_steps": int(step), "error_cm": res["error_cm"], "median_cm": res["median_cm"],
            **extra,
            "lstm_matching_minus_lstm_cm": paired_difference(e["lstm_matching"], e["lstm"]),
            "lstm_minus_vae_cm": paired_difference(e["lstm"], e["vae"]),
            "lstm_retrieves_vae_frame": float(np.mean(r["lstm"] == r["vae"])),
            "ordering_holds": ordering_holds(res),
            "loss": {k: (float(np.mean(np.asarray(h)[max(0, step - window):step])) if step
                         else None) for k, h in hist.items()}}


def write_occlusion_curve(curve: list[dict], out_dir: str, task: str) -> str:
    """Mean retrieval error of the three models against the LSTMs' training steps -> PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lstm_steps = np.array([c["lstm_steps"] for c in curve], np.float64)
    fig, ax = plt.subplots(figsize=(5.2, 3.8))
    styles = {"lstm_matching": ("LSTM + matching loss", "tab:blue"),
              "lstm": ("LSTM", "tab:orange"), "vae": ("object-VAE", "tab:green")}
    for name, (label, color) in styles.items():
        mean = np.array([c["error_cm"][name][0] for c in curve])
        ax.plot(lstm_steps, mean, "o-", color=color, label=label, ms=4)
        ax.axhline(PAPER_ERROR_CM[name], color=color, ls=":", lw=1)
        if all("other_trajectories" in c for c in curve):
            other = [c["other_trajectories"]["error_cm"][name][0] for c in curve]
            ax.plot(lstm_steps, other, "s--", color=color, ms=3, lw=1, alpha=0.7,
                    label=f"{label}, other trajectories' frames")
    ax.set_xscale("symlog", linthresh=100)
    ax.set_xlabel("LSTM training steps (0: the shared initialisation)")
    ax.set_ylabel("mean puck position error (cm)")
    ax.set_title(f"{task}: retrieval along the LSTMs' training (dotted: paper)", fontsize=9)
    ax.legend(fontsize=6)
    ax.set_ylim(bottom=0)
    fig.tight_layout()
    os.makedirs(out_dir, exist_ok=True)
    png = os.path.join(out_dir, f"occlusion_curve_{task}.png")
    fig.savefig(png, dpi=120)
    plt.close(fig)
    return png


def run_occlusion(ckpt: str, out: str, task: str = "hurdle_top", n_train: int = 64,
                  n_eval: int = 64, horizon: int | None = None, lstm_steps: int = 200,
                  vae_steps: int = 200, batch: int = 25, drop: float = OCCLUSION_DROP,
                  seed: int = 0, preset: str | None = None) -> dict:
    """Trajectories -> segment -> (fine-tune the object-VAE) -> two LSTMs -> retrieval."""
    import time

    import envs_mjx

    t0 = time.perf_counter()
    cfg, pre, seg = load_checkpoint(ckpt, task, preset)
    if pre.object_vae is None:
        raise ValueError("the occlusion analysis needs a checkpoint with an object-VAE")
    env = envs_mjx.make(task)
    horizon = horizon or env.horizon
    key = jax.random.PRNGKey(seed)
    k_path, k_vae, k_lstm, k_occ = jax.random.split(key, 4)
    puck, hand = puck_paths(k_path, task, n_train + n_eval, horizon)
    rgb = render_pushes(env, puck, hand)
    seg_fn = functools.partial(jax.jit(pipeline.segment), seg)  # params as arguments
    masks = batched(seg_fn, rgb.reshape((-1,) + rgb.shape[2:]), 256).reshape(rgb.shape[:-1])
    images = np.where(masks[..., None], rgb, 0).astype(np.uint8)
    t_data = time.perf_counter() - t0
    tr, ev = slice(0, n_train), slice(n_train, n_train + n_eval)
    vcfg = cfg.object_vae
    vae_state, vae_hist = finetune_vae(k_vae, pre.object_vae, vcfg,
                                       images[tr].reshape((-1, 48, 48, 3)),
                                       masks[tr].reshape((-1, 48, 48)), vae_steps)
    curve_steps = [s for s in CURVE_STEPS if s < lstm_steps] + [lstm_steps]
    _, lstm_hist, snaps = train_occlusion_lstms(
        k_lstm, vae_state.params, vcfg, cfg.lstm, images[tr], masks[tr], lstm_steps, batch,
        snapshot_steps=curve_steps)  # snaps[lstm_steps]: the final weights
    t_train = time.perf_counter() - t0 - t_data
    frame_encoder, _ = occlusion_models(vae_state.params, vcfg, {})
    queries = occlusion_queries(k_occ, images[ev], masks[ev], frame_encoder, drop,
                                min_t=cfg.lstm.min_occlusion_t)
    lat, _, occ_t = queries
    curve = []
    for step in curve_steps:
        heads = occlusion_models(vae_state.params, vcfg, snaps[step])[1]
        res = score_heads(*queries, puck[ev], heads)
        # The paper's pool holds the query's own clean trajectory, whose LSTM codes share
        # the query's history; retrieving from the other trajectories only checks that the
        # codes locate the puck rather than the trajectory.
        others = score_heads(*queries, puck[ev], heads, exclude_own=True)
        # The same frames unoccluded, from the other trajectories: how well each code
        # locates the puck it is shown, the baseline of the occluded frames' errors.
        clean = score_heads(lat, lat, occ_t, puck[ev], heads, exclude_own=True)
        curve.append(curve_row(step, res, lstm_hist, others, clean))
    # res, others and clean are now the final weights' (curve_steps ends at lstm_steps).
    seg_px = masks.reshape(masks.shape[0], masks.shape[1], -1).sum(-1)
    extra = {"preset": cfg.preset, "ckpt": os.path.abspath(ckpt), "seed": seed,
             "n_train_trajectories": n_train, "n_eval_trajectories": n_eval, "horizon": horizon,
             "drop": drop, "train_drop": cfg.lstm.occlusion_drop, "lstm_steps": lstm_steps,
             "lstm_batch": batch, "vae_steps": vae_steps,
             "segmented_pixels_mean": float(seg_px.mean()),
             "frames_without_object_pixels": float((seg_px == 0).mean()),
             "loss_first_last": {"vae": _first_last(vae_hist),
                                 **{k: _first_last(v) for k, v in lstm_hist.items()}},
             "seconds": {"data": round(t_data, 1), "train": round(t_train, 1)},
             "error_cm_other_trajectories": others["error_cm"],
             "median_cm_other_trajectories": others["median_cm"],
             "error_cm_clean_frames": clean["error_cm"],
             "ordering_holds": curve[-1]["ordering_holds"],
             "ordering_holds_at_steps": [c["lstm_steps"] for c in curve if c["ordering_holds"]],
             "curve": curve}
    png, js = write_occlusion(res, out, task, extra)
    curve_png = write_occlusion_curve(curve, out, task)
    return {"task": task, "error_cm": res["error_cm"], "png": png, "curve_png": curve_png,
            "json": js, **extra}


def _first_last(h) -> list | None:
    h = np.asarray(h)
    return [float(h[0]), float(h[-1])] if h.size else None
