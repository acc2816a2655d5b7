"""Fit and evaluate a task's unknown-object segmentation.

    python -m roll_jax.segmentation --task puck_push [--preset smoke|cpu|paper] --out DIR

(`roll-segmentation` once installed; --preset defaults to cpu.) Writes DIR/ckpt (orbax
params + meta.json), DIR/segmentation_eval.json (iou, robot_leakage, background_leakage,
timings), DIR/figure2.png (original, foreground, robot mask, object mask, segmented object)
and DIR/background.png (the MOG2 background image).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time


def parse_args(argv=None):
    from configs.presets import PRESETS
    from configs.train import TASKS

    p = argparse.ArgumentParser(prog="python -m roll_jax.segmentation", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", required=True, metavar="TASK", help=f"one of {', '.join(TASKS)}")
    p.add_argument("--preset", default="cpu", metavar="PRESET",
                   help=f"one of {', '.join(PRESETS)} (configs/presets.py; default cpu)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--seed", type=int, default=0,
                   help="PRNG seed of the fit and the evaluation states (default 0)")
    p.add_argument("--eval-states", type=int, default=None, help="override the preset")
    p.add_argument("--unet-epochs", type=int, default=None, help="override the preset")
    p.add_argument("--n-frames", type=int, default=None, help="override the preset")
    p.add_argument("--robot-threshold", type=float, default=None, help="override the task's")
    p.add_argument("--unet-features", type=int, default=None, help="override the U-Net width")
    p.add_argument("--label-background-ratio", type=float, default=None,
                   help="override the task's MOG2 background ratio for robot labels")
    p.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                   help="override any SegmentationConfig field (repeatable), e.g. "
                        "--set distractor_behind_robot=1.0")
    p.add_argument("--eval-only", action="store_true",
                   help="re-evaluate the checkpoint in DIR/ckpt instead of fitting")
    a = p.parse_args(argv)
    if a.task not in TASKS:
        p.error(f"unknown --task {a.task!r}; expected one of {', '.join(TASKS)}")
    if a.preset not in PRESETS:
        p.error(f"unknown --preset {a.preset!r}; expected one of {', '.join(PRESETS)}")
    return a


def main(argv=None) -> int:
    a = parse_args(argv)
    import jax
    import numpy as np
    from tqdm import tqdm

    import envs_mjx
    from configs.overrides import field_overrides
    from configs.segmentation import SegmentationConfig, segmentation_config
    from roll_jax.segmentation import mog2, pipeline

    overrides = {k: v for k, v in {"eval_states": a.eval_states, "unet_epochs": a.unet_epochs,
                                        "n_frames": a.n_frames,
                                        "robot_threshold": a.robot_threshold,
                                        "unet_features": a.unet_features,
                                        "label_background_ratio": a.label_background_ratio}.items()
                 if v is not None}
    try:
        overrides.update(field_overrides(SegmentationConfig, a.set))
        cfg = segmentation_config(a.task, a.preset, **overrides)
    except ValueError as e:
        sys.exit(f"error: {e}")
    os.makedirs(a.out, exist_ok=True)
    env = envs_mjx.make(a.task)
    key = jax.random.PRNGKey(a.seed)
    k_fit, k_eval = jax.random.split(key)

    t0 = time.perf_counter()
    bar = tqdm(total=cfg.unet_epochs, desc=f"{a.task} U-Net", unit="epoch")

    def progress(epoch, loss):
        bar.update(1)
        bar.set_postfix(loss=f"{loss:.4f}")

    if a.eval_only:
        bar.close()
        params, cfg = pipeline.load(os.path.join(a.out, "ckpt"), a.task)
        if a.robot_threshold is not None:
            params = params.replace(robot_threshold=np.float32(a.robot_threshold))
        info = {"unet_loss": [float("nan")], "robot_labels": np.zeros(1)}
    else:
        params, info = pipeline.fit(env, k_fit, cfg, progress=progress)
        bar.close()
        pipeline.save(os.path.join(a.out, "ckpt"), a.task, params, cfg)
    t_fit = time.perf_counter() - t0

    t1 = time.perf_counter()
    summary, arrays = pipeline.evaluate(env, params, k_eval, cfg.eval_states)
    t_eval = time.perf_counter() - t1
    robot_label_share = float(np.asarray(info["robot_labels"]).mean())
    summary.update(preset=a.preset, seed=a.seed, eval_only=a.eval_only, fit_seconds=round(t_fit, 1),
                   eval_seconds=round(t_eval, 1), n_frames=cfg.n_frames,
                   unet_epochs=cfg.unet_epochs, unet_features=cfg.unet_features,
                                      unet_loss_first=float(info["unet_loss"][0]),
                   unet_loss_last=float(info["unet_loss"][-1]),
                   robot_label_pixel_share=robot_label_share)
    with open(os.path.join(a.out, "segmentation_eval.json"), "w") as f:
        json.dump(summary, f, indent=2)
    # Show the worst, a median and the best states, so the figure does not flatter.
    order = np.argsort(arrays["iou"])
    pick = order[np.linspace(0, len(order) - 1, 4).round().astype(int)]
    pipeline.figure2({k: v[pick] for k, v in arrays.items()},
                     os.path.join(a.out, "figure2.png"))
    import cv2

    bg = np.asarray(mog2.background_image(params.background))
    cv2.imwrite(os.path.join(a.out, "background.png"),
                cv2.resize(bg[..., ::-1], (192, 192), interpolation=cv2.INTER_NEAREST))
    print(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
