"""A training run's directory (docs/architecture.md, "Training CLI and the run directory"):
what is in it and how each file is written and read.

    config.json      the TrainConfig (`dataclasses.asdict`), written at the start
    metrics.csv      one row per seed and evaluation (env_steps, seed, final_distance, ...),
                     appended as the run goes; a resumed run first drops the rows past its
                     checkpoint
    tb/              TensorBoard event files (roll_jax/training/events.py)
    videos/          eval_STEP.gif: test env 0 (observation beside the goal image)
    plots/           learning_curve.png (roll_jax/training/plots.py)
    ckpt/            orbax checkpoints of the whole train state (roll_jax/common/checkpoint.py)
    segmentation/, encoders/   the fitted segmentation and pre-trained encoders
    inputs.json      where the segmentation and encoders the run used are (its own
                     sub-directories, or the --seg-ckpt / --enc-ckpt it was given) and its
                     base seed (--seed)
    timings.json     wall and CPU seconds per phase
    complete.json    written last, atomically, when the run reached its last epoch
    train.lock       while a process trains into the directory: its pid and host
                     (`lock_run`; a second process is refused, a dead holder's lock taken over)
"""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import socket
import sys
import time

import numpy as np

from configs.train import TrainConfig, config_from_json

COMPLETE_MARKER = "complete.json"
INPUTS = "inputs.json"
LOCK = "train.lock"
INT_COLUMNS = ("env_steps", "seed")  # metrics.csv columns that are ints; the rest are floats


def warn(msg: str) -> None:
    """One line on stderr, as the commands' warnings read."""
    print(f"warning: {msg}", file=sys.stderr, flush=True)


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
    """metrics.csv as `rows` (replaced atomically; no rows: the file is removed)."""
    if not rows:
        if os.path.exists(csv_path):
            os.remove(csv_path)
        return
    _write_csv(csv_path, rows, list(rows[0]))


def _write_csv(csv_path: str, rows: list[dict], columns: list[str]) -> None:
    """The file replaced atomically by `rows` under `columns` ("nan" where one is missing)."""
    tmp = f"{csv_path}.tmp{os.getpid()}"
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns, restval="nan")
        w.writeheader()
        w.writerows(rows)
    os.replace(tmp, csv_path)


def append_rows(csv_path: str, rows: list[dict]) -> None:
    """Rows appended to metrics.csv (the header first when the file is new or empty). Rows
    with columns the file lacks (a run resumed by a version that logs more) rewrite it once
    with every column, "nan" where a row has no value."""
    if not rows:
        return
    new = not os.path.exists(csv_path) or os.path.getsize(csv_path) == 0
    columns = list(rows[0])
    if not new:
        with open(csv_path, newline="") as f:
            columns = next(csv.reader(f), None) or columns
    wanted = columns + [k for r in rows for k in r if k not in columns]
    wanted = list(dict.fromkeys(wanted))
    if not new and wanted != columns:
        with open(csv_path, newline="") as f:
            old = list(csv.DictReader(f))
        _write_csv(csv_path, old, wanted)
    with open(csv_path, "a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=wanted, restval="nan")
        if new:
            w.writeheader()
        w.writerows(rows)
        f.flush()
        os.fsync(f.fileno())


def read_rows(csv_path: str, keep: int, final: bool = False) -> list[dict]:
    """The metrics.csv rows a resumed run keeps: those before env step `keep` (the checkpoint),
    and the rows at `keep` too when `final` (a finished run's final evaluation). env_steps and
    seed come back as ints (as the run logs them), the other columns as floats. A row cut
    short (the process was killed while appending it) is left out."""
    def parse(r: dict) -> dict:
        # int(float(.)): also reads the "500.0" a resumed run used to write.
        return {k: int(float(v)) if k in INT_COLUMNS else float(v) for k, v in r.items()}

    if not os.path.exists(csv_path):
        return []
    with open(csv_path, newline="") as f:
        rows = [parse(r) for r in csv.DictReader(f)
                if None not in r and "" not in r.values() and None not in r.values()]
    return [r for r in rows if r["env_steps"] < keep or (final and r["env_steps"] == keep)]


def restart_rows(csv_path: str, keep: int | None, final: bool = False) -> list[dict]:
    """metrics.csv as a run that starts at env step `keep` continues it: the rows before it
    kept (`read_rows`), those of chunks past the checkpoint dropped from the file, so the
    rows appended next follow without duplicates. `keep` None: a new run, no rows."""
    rows = [] if keep is None else read_rows(csv_path, keep, final)
    write_rows(csv_path, rows)
    return rows


# --- one training process per run directory ------------------------------------------------

class RunLocked(RuntimeError):
    """Another live process is training into the run directory."""


def _process_start(pid: int) -> str | None:
    """The process's start time in clock ticks since boot (Linux /proc; None elsewhere): with
    the pid it names one process, a reused pid does not match."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[19]
    except (OSError, IndexError):
        return None


def _alive(holder: dict) -> bool:
    """The lock's holder (on this host) is still running."""
    pid = holder["pid"]
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process: alive
        pass
    start = holder.get("start")
    return start is None or _process_start(pid) in (None, start)


def _read_lock(path: str) -> dict | None:
    """The lock file's holder, or None when it cannot be read (cut short, not ours)."""
    try:
        with open(path) as f:
            holder = json.load(f)
        holder["pid"] = int(holder["pid"])
        return holder
    except (OSError, ValueError, KeyError, TypeError):
        return None


@dataclasses.dataclass
class RunLock:
    """A held `train.lock`; `release()` removes it (if it is still this process's)."""

    path: str
    pid: int

    def release(self) -> None:
        holder = _read_lock(self.path)
        if holder is not None and holder["pid"] == self.pid and holder.get(
                "host") == socket.gethostname():
            os.remove(self.path)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()


def _create_lock(path: str, text: str) -> bool:
    """Create `path` holding `text` unless it exists (atomically: another process sees no
    half-written lock); False when it exists."""
    tmp = f"{path}.{os.getpid()}.tmp"
    with open(tmp, "w") as f:
        f.write(text)
    try:
        os.link(tmp, path)
        return True
    except FileExistsError:
        return False
    except OSError:  # a filesystem without hard links: exclusive create
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            return False
        with os.fdopen(fd, "w") as f:
            f.write(text)
        return True
    finally:
        os.remove(tmp)


def lock_run(out: str) -> RunLock:
    """Take `out`/train.lock for this process: refused (RunLocked naming the holder's pid)
    while another live process holds it, or one on another host (its pid cannot be checked
    from here); a lock whose process is gone, or that cannot be read, is taken over with a
    warning."""
    os.makedirs(out, exist_ok=True)
    path = os.path.join(out, LOCK)
    me = {"pid": os.getpid(), "host": socket.gethostname(), "start": _process_start(os.getpid()),
          "since": time.strftime("%Y-%m-%d %H:%M:%S")}
    for _ in range(3):
        if _create_lock(path, json.dumps(me)):
            return RunLock(path, me["pid"])
        holder = _read_lock(path)
        if holder is not None and holder.get("host") != me["host"]:
            raise RunLocked(
                f"{out} is locked by pid {holder['pid']} on host {holder.get('host')} (since "
                f"{holder.get('since')}): another training process may be writing it. If that "
                f"process has ended, delete {path}")
        if holder is not None and _alive(holder):
            raise RunLocked(
                f"{out} is being written by another training process (pid {holder['pid']}, "
                f"since {holder.get('since')}); wait for it to end or train into another --out")
        why = ("cannot be read" if holder is None else
               f"was held by pid {holder['pid']}, which is no longer running")
        warn(f"taking over the stale lock {path} (it {why})")
        try:
            os.remove(path)
        except FileNotFoundError:
            pass
    raise RunLocked(f"could not take the lock {path}: other processes keep taking it")


def write_gif(path: str, video, goal) -> None:
    """Observation (left) beside the goal image (right), 4x upscaled, as an animated GIF."""
    from PIL import Image

    frames = []
    for f in np.asarray(video):
        pair = np.concatenate([f, np.full((f.shape[0], 2, 3), 255, np.uint8), np.asarray(goal)], 1)
        frames.append(Image.fromarray(pair).resize((pair.shape[1] * 4, pair.shape[0] * 4),
                                                   Image.NEAREST))
    frames[0].save(path, save_all=True, append_images=frames[1:], duration=80, loop=0)
