"""Segmentation benchmarks. MOG2 part: jnp MOG2 vs cv2 MOG2 speed, and long-video parity.
Segment part (--part segment): U-Net inference and the full `segment` (MOG2 foreground at
lr 0 AND NOT U-Net robot) in images/s at batch 1, 64, 1024, U-Net width from the paper config.

Writes bench/results/segmentation.json, keys "mog2" (frames/s at batch 1, 64, 1024 of
independent 48x48x3 models, ratio against cv2 measured in the same run) and "mog2_parity"
(per-frame mask agreement with cv2 over 2000+ frame synthetic videos) and "mog2_parity_scenes"
(--part scenes: the same on every scene's rendered frames, as the pipeline uses them). A run
of one part keeps the other parts' figures of an earlier run on the same device.

    python -m bench segmentation [--quick] [--part mog2|segment|scenes]
"""
from __future__ import annotations

import argparse
import os
import time

import cv2
import jax
import numpy as np

from bench.common import machine_info, read_figures, result_path, write_result
from roll_jax.segmentation import mog2
from roll_jax.segmentation import mog2_parity as mp

H = W = 48
C = 3


def _env_frames(video: np.ndarray, b: int, steps: int, start: int) -> np.ndarray:
    """[steps, b, H, W, C]: env j sees the shared video shifted by 7 j frames."""
    t = video.shape[0]
    idx = (start + np.arange(steps)[:, None] + 7 * np.arange(b)[None, :]) % t
    return video[idx]


def bench_mog2(batches=(1, 64, 1024), warmup=30) -> dict:
    video = mp.synthetic_video("mixed", t=300, h=H, w=W, c=C, seed=0)
    out = {"frame_shape": [H, W, C], "history": 500, "learning_rate": -1.0,
           "cv2_threads": cv2.getNumThreads(), "load_average_at_start": os.getloadavg()[0],
           "note": "frames/s = model-frames per second; batch = independent models (one per "
                   "env) stepped together by apply_batch; cv2 = a Python loop over as many "
                   "cv2 subtractors; both on this machine's CPU in the same run",
           "batches": {}}
    for b in batches:
        steps = max(4, min(200, 20000 // b))
        warm = _env_frames(video, b, warmup, 0)
        timed = _env_frames(video, b, steps, warmup)

        # jnp: B independent models stepped together (apply_batch = vmap of the per-frame step).
        model = mog2.init_batch(b, H, W, C)
        for f in warm:
            model, mask = mog2.apply_batch(model, jax.device_put(f))
        jax.block_until_ready(mask)
        timed_dev = jax.device_put(timed)
        best = float("inf")
        for _ in range(3):
            m = model
            t0 = time.perf_counter()
            for i in range(steps):
                m, mask = mog2.apply_batch(m, timed_dev[i])
            jax.block_until_ready((m, mask))
            best = min(best, time.perf_counter() - t0)
        jax_fps = b * steps / best

        # cv2: a Python loop over B subtractors, one apply each per step.
        subs = [mp.cv2_subtractor(500, 16.0, True) for _ in range(b)]
        for f in warm:
            for j, s in enumerate(subs):
                s.apply(f[j], learningRate=-1)
        cv_steps = max(2, min(steps, 4000 // b))
        t0 = time.perf_counter()
        for i in range(cv_steps):
            for j, s in enumerate(subs):
                s.apply(timed[i, j], learningRate=-1)
        cv2_fps = b * cv_steps / (time.perf_counter() - t0)
        out["batches"][str(b)] = {"jax_fps": jax_fps, "cv2_fps": cv2_fps,
                                  "ratio_jax_over_cv2": jax_fps / cv2_fps, "steps": steps}
        print(f"mog2 batch {b:5d}: jax {jax_fps:10.0f} frames/s  cv2 {cv2_fps:10.0f} frames/s"
              f"  ratio {jax_fps / cv2_fps:6.2f}", flush=True)

    # One model over a video: apply_video (lax.scan) vs cv2 frame loop.
    frames = jax.device_put(video)
    model = mog2.init(H, W, C)
    jax.block_until_ready(mog2.apply_video(model, frames))
    t0 = time.perf_counter()
    jax.block_until_ready(mog2.apply_video(model, frames))
    scan_fps = len(video) / (time.perf_counter() - t0)
    sub = mp.cv2_subtractor(500, 16.0, True)
    t0 = time.perf_counter()
    for f in video:
        sub.apply(f, learningRate=-1)
    cv_fps = len(video) / (time.perf_counter() - t0)
    out["video_scan_batch1"] = {"jax_fps": scan_fps, "cv2_fps": cv_fps,
                                "ratio_jax_over_cv2": scan_fps / cv_fps}
    print(f"mog2 apply_video (scan, 1 model): jax {scan_fps:.0f} frames/s  cv2 {cv_fps:.0f}"
          f"  ratio {scan_fps / cv_fps:.2f}", flush=True)

    # Test-time use: a fitted model, many frames at lr 0 (foreground is vmapped over frames).
    model, _ = mog2.apply_video(model, frames)
    test = jax.device_put(np.concatenate([video] * 4))
    jax.block_until_ready(mog2.foreground(model, test))
    t0 = time.perf_counter()
    jax.block_until_ready(mog2.foreground(model, test))
    fg_fps = test.shape[0] / (time.perf_counter() - t0)
    t0 = time.perf_counter()
    for f in np.asarray(test):
        sub.apply(f, learningRate=0)
    cv_fps = test.shape[0] / (time.perf_counter() - t0)
    out["foreground_lr0"] = {"jax_fps": fg_fps, "cv2_fps": cv_fps,
                             "ratio_jax_over_cv2": fg_fps / cv_fps, "frames": int(test.shape[0])}
    print(f"mog2 foreground (lr 0, {test.shape[0]} frames): jax {fg_fps:.0f} frames/s  cv2 "
          f"{cv_fps:.0f}  ratio {fg_fps / cv_fps:.2f}", flush=True)
    return out


def parity_mog2(fit=2000, test=300, kinds=("mixed", "shadows", "flicker", "multimodal",
                                           "late_object", "noise")) -> dict:
    """ROLL's use on long videos: fit at lr -1 with history = fit frames, then lr 0."""
    runs = []
    lrs = np.where(np.arange(fit + test) < fit, -1.0, 0.0)
    cases = [(k, 3) for k in kinds] + [("mixed", 1)]
    for kind, c in cases:
        frames = mp.synthetic_video(kind, t=fit + test, h=H, w=W, c=c, seed=11)
        for shadows in (True, False):
            r = mp.compare(frames, lrs, history=fit, detect_shadows=shadows)
            runs.append({"kind": kind, "channels": c, **_parity_row(r, fit, shadows)})
            print(f"parity {kind:12s} c={c} shadows={int(shadows)}: min {r.min:.6f} "
                  f"mean {r.mean:.6f} background {r.background_equal:.6f}", flush=True)
    return _parity_summary(runs, [H, W], fit, test)


def _parity_row(r: mp.ParityResult, fit: int, shadows: bool) -> dict:
    """One video's agreement figures: fit frames (lr -1) first, then the lr-0 frames."""
    return {"detect_shadows": shadows, "frames": len(r.agreement), "min": r.min, "mean": r.mean,
            "min_fit": float(r.agreement[:fit].min()),
            "min_lr0": float(r.agreement[fit:].min()),
            "frames_not_exact": int((r.agreement < 1).sum()),
            "background_image_equal": r.background_equal}


def _parity_summary(runs: list[dict], frame_shape, fit: int, test: int) -> dict:
    return {"frame_shape": frame_shape, "history": fit, "fit_frames_lr_-1": fit,
            "test_frames_lr_0": test, "runs": runs,
            "min": min(r["min"] for r in runs), "mean": float(np.mean([r["mean"] for r in runs]))}


def parity_scenes(fit=2000, test=300, tasks=None) -> dict:
    """ROLL's own use on every scene: fit at lr -1 (history = fit) on the empty-scene random
    walks that `pipeline.fit` records, then lr 0 on random states with the object; cv2 on the
    same frames, shadows on and off."""
    import envs_mjx
    from roll_jax.segmentation import pipeline

    runs = []
    lrs = np.where(np.arange(fit + test) < fit, -1.0, 0.0)
    for task in tasks or envs_mjx.TASK_NAMES:
        env = envs_mjx.make(task)
        k_fit, k_test = jax.random.split(jax.random.PRNGKey(3))
        empty = np.asarray(pipeline.record_empty_scene(env, k_fit, fit, n_envs=40))
        scene, _ = pipeline.random_object_states(env, k_test, test)
        frames = np.concatenate([empty, scene])
        for shadows in (True, False):
            r = mp.compare(frames, lrs, history=fit, detect_shadows=shadows)
            runs.append({"task": task, **_parity_row(r, fit, shadows),
                         "foreground_share_lr0": float((r.cv2_masks[fit:] > 0).mean())})
            print(f"parity {task:14s} shadows={int(shadows)}: min {r.min:.6f} mean {r.mean:.6f} "
                  f"not exact {runs[-1]['frames_not_exact']} background {r.background_equal:.6f}",
                  flush=True)
    return _parity_summary(runs, [48, 48, 3], fit, test)


def _rate(fn, *args, reps: int = 3) -> float:
    """Best-of-`reps` calls per second (after one warm-up call that compiles)."""
    jax.block_until_ready(fn(*args))
    best = float("inf")
    for _ in range(reps):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        best = min(best, time.perf_counter() - t0)
    return 1.0 / best


def bench_segment(batches=(1, 64, 1024)) -> dict:
    """U-Net inference and full `segment` throughput (weights do not change the speed, so a
    fresh U-Net and a MOG2 fitted on a synthetic video stand in for a fitted pipeline)."""
    from configs.segmentation import SegmentationConfig
    from roll_jax.segmentation import pipeline, unet

    cfg = SegmentationConfig()
    video = mp.synthetic_video("mixed", t=300, h=H, w=W, c=C, seed=0)
    bg, _ = mog2.apply_video(mog2.init(H, W, C, history=300), jax.device_put(video))
    params = pipeline.SegParams(background=bg,
                                unet=unet.init_unet(jax.random.PRNGKey(0), cfg.unet_features, H, W),
                                robot_threshold=jax.numpy.float32(0.5))
    seg = jax.jit(pipeline.segment)
    prob = jax.jit(unet.robot_probability)
    out = {"unet_features": cfg.unet_features, "jax_backend": jax.default_backend(),
           "jax_device": str(jax.devices()[0]), "load_average_at_start": os.getloadavg()[0],
           "batches": {}}
    for b in batches:
        imgs = jax.device_put(video[np.arange(b) % len(video)])
        u = b * _rate(prob, params.unet, imgs)
        s = b * _rate(seg, params, imgs)
        out["batches"][str(b)] = {"unet_images_per_s": u, "segment_images_per_s": s}
        print(f"segment batch {b:5d}: U-Net {u:9.0f} images/s  segment {s:9.0f} images/s",
              flush=True)
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="python -m bench segmentation", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="small batches and short videos")
    ap.add_argument("--part", choices=("all", "mog2", "segment", "scenes"), default="all",
                    help="what to measure (default all)")
    ap.add_argument("--out", default=result_path("segmentation"), help="result file")
    args = ap.parse_args(argv)
    machine = machine_info()
    results = read_figures(args.out, machine)
    if args.part in ("all", "segment"):
        results["segment"] = bench_segment((1, 64) if args.quick else (1, 64, 1024))
    if args.part in ("all", "scenes"):
        results["mog2_parity_scenes"] = (parity_scenes(fit=300, test=50, tasks=("puck_push",))
                                         if args.quick else parity_scenes())
    if args.part in ("segment", "scenes"):
        pass
    elif args.quick:
        results["mog2"] = bench_mog2(batches=(1, 64), warmup=5)
        results["mog2_parity"] = parity_mog2(fit=300, test=50, kinds=("mixed",))
    else:
        results["mog2"] = bench_mog2()
        results["mog2_parity"] = parity_mog2()
    p = results.get("mog2_parity", {"runs": [], "min": float("nan"), "mean": float("nan")})
    print(f"mog2 parity over {len(p['runs'])} videos: min per-frame agreement {p['min']:.6f}, "
          f"mean {p['mean']:.6f}")
    write_result("segmentation", results, machine, argv, args.out)


if __name__ == "__main__":
    main()
