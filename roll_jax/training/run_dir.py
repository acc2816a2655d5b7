"""A training run's directory (docs/architecture.md, "Training CLI and the run directory"):
what is in it and how each file is written and read.

    config.json      the TrainConfig (`dataclasses.asdict`), written at the start
    metrics.csv      one row per seed and evaluation (env_steps, seed, final_distance, ...)
    videos/          eval_STEP.gif: test env 0 (observation beside the goal image)
    plots/           learning_curve.png (roll_jax/training/plots.py)
    ckpt/            orbax checkpoints of the whole train state (roll_jax/common/checkpoint.py)
    segmentation/, encoders/   the fitted segmentation and pre-trained encoders
    inputs.json      where the segmentation and encoders the run used are (its own
                     sub-directories, or the --seg-ckpt / --enc-ckpt it was given) and its
                     base seed (--seed)
    timings.json     wall and CPU seconds per phase
    complete.json    written last, atomically, when the run reached its last epoch
"""

from __future__ import annotations

import csv
import dataclasses
import json
import os

import numpy as np

from configs.train import TrainConfig, config_from_json

COMPLETE_MARKER = "complete.json"
INPUTS = "inputs.json"
INT_COLUMNS = ("env_steps", "seed")  # metrics.csv columns that are ints; the rest are floats


def is_complete(out: str) -> bool:
    """The run in `out` reached its last epoch (the marker is written last)."""
    return os.path.exists(os.path.join(out, COMPLETE_MARKER))


def write_atomic(path: str, text: str) -> None:
    tmp = f"{path}.tmp{os.getpid()}"
    with open(tmp, "w") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def config_json(cfg: TrainConfig) -> dict:
    return json.loads(json.dumps(dataclasses.asdict(cfg)))


def write_config(out: str, cfg: TrainConfig) -> None:
    with open(os.path.join(out, "config.json"), "w") as f:
        json.dump(config_json(cfg), f, indent=2)


def read_config(out: str) -> TrainConfig:
    """The TrainConfig of the run in `out`; FileNotFoundError naming it when there is none."""
    path = os.path.join(out, "config.json")
    if not os.path.exists(path):
        raise FileNotFoundError(f"{out} is not a training run directory (no config.json)")
    with open(path) as f:
        return config_from_json(json.load(f))


def write_inputs(out: str, seg_ckpt: str | None, enc_ckpt: str | None, seed: int) -> None:
    with open(os.path.join(out, INPUTS), "w") as f:
        json.dump({"seg_ckpt": os.path.abspath(seg_ckpt or os.path.join(out, "segmentation")),
                   "enc_ckpt": os.path.abspath(enc_ckpt or os.path.join(out, "encoders")),
                   "seed": int(seed)}, f, indent=2)


def read_inputs(out: str) -> dict:
    """inputs.json of a run, or {} where the run has none."""
    path = os.path.join(out, INPUTS)
    if not os.path.exists(path):
        return {}
    with open(path) as f:
        return json.load(f)


def check_resume(out: str, cfg: TrainConfig, seed: int | None = None) -> None:
    """A resumed run must have the same config as the command line (before any compile), and
    the same base seed where both are known (`seed` None, or a run written before inputs.json
    held its seed: not checked)."""
    path = os.path.join(out, "config.json")
    if not os.path.exists(path):
        raise ValueError(f"--resume: no run to resume in {out} (missing config.json)")
    with open(path) as f:
        # Read back through the dataclasses: a field added since the run was written takes its
        # default, which by convention keeps the behaviour the run was made with.
        saved = config_json(config_from_json(json.load(f)))
    now = config_json(cfg)
    diff = [k for k in sorted(set(saved) | set(now)) if saved.get(k) != now.get(k)]
    if diff:
        k = diff[0]
        raise ValueError(f"--resume: config of {out} differs from the command line in {k!r}: "
                         f"saved {saved.get(k)!r}, now {now.get(k)!r}")
    saved_seed = read_inputs(out).get("seed")
    if seed is not None and saved_seed is not None and int(seed) != int(saved_seed):
        raise ValueError(f"--resume: {out} was trained with --seed {saved_seed}, the command "
                         f"line gives --seed {seed}")


def write_rows(csv_path: str, rows: list[dict]) -> None:
    with open(csv_path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def read_rows(csv_path: str, keep: int, final: bool = False) -> list[dict]:
    """The metrics.csv rows a resumed run keeps: those before env step `keep` (the checkpoint),
    and the rows at `keep` too when `final` (a finished run's final evaluation). env_steps and
    seed come back as ints (as the run logs them), the other columns as floats."""
    def parse(r: dict) -> dict:
        # int(float(.)): also reads the "500.0" a resumed run used to write.
        return {k: int(float(v)) if k in INT_COLUMNS else float(v) for k, v in r.items()}

    with open(csv_path) as f:
        rows = [parse(r) for r in csv.DictReader(f)]
    return [r for r in rows if r["env_steps"] < keep or (final and r["env_steps"] == keep)]


def write_gif(path: str, video, goal) -> None:
    """Observation (left) beside the goal image (right), 4x upscaled, as an animated GIF."""
    from PIL import Image

    frames = []
    for f in np.asarray(video):
        pair = np.concatenate([f, np.full((f.shape[0], 2, 3), 255, np.uint8), np.asarray(goal)], 1)
        frames.append(Image.fromarray(pair).resize((pair.shape[1] * 4, pair.shape[0] * 4),
                                                   Image.NEAREST))
    frames[0].save(path, save_all=True, append_images=frames[1:], duration=80, loop=0)
