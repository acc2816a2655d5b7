"""TensorBoard event files of a run: `DIR/tb/`, written with tensorboardX (no TensorFlow).

    train/KEY                   every chunk: its training metrics (losses, alpha, ...), the
                                mean over seeds, at the env steps after the chunk
    train_per_seed/KEY/seed_S   the same per seed
    time/env_steps_per_s        every chunk: env steps of all seeds per wall second, chunk end
                                to chunk end (the first chunk includes its compile)
    time/chunk_s, time/wall_s   the chunk's wall seconds; the run's since it started (resumed
                                runs continue the count)
    eval/KEY                    every evaluation (final_distance, final_distance_median,
                                start_distance): the mean over seeds, at the env steps of
                                the evaluated policy, as in metrics.csv
    eval_per_seed/KEY/seed_S    the same per seed
    config                      the TrainConfig as JSON text (at step 0)

`tensorboard --logdir runs` shows every run under runs/. A resumed run first removes from the
event files what the chunks past its checkpoint had logged (as metrics.csv drops their rows),
so no step is logged twice. `read_scalars` reads the files back (tests, notebooks).
"""

from __future__ import annotations

import glob
import itertools
import json
import os
import struct

TB_DIR = "tb"
_PREFIX = "events.out.tfevents."
_COUNTER = itertools.count()


class EventDirNotWritable(OSError):
    """DIR/tb cannot be created or written."""


def event_dir(out: str) -> str:
    return os.path.join(out, TB_DIR)


def check_writable(out: str) -> str:
    """Create `out`/tb and prove a file can be written there; EventDirNotWritable naming the
    directory otherwise (before any work is done)."""
    logdir = event_dir(out)
    probe = os.path.join(logdir, f".write_test.{os.getpid()}")
    try:
        os.makedirs(logdir, exist_ok=True)
        with open(probe, "w") as f:
            f.write("")
        os.remove(probe)
    except OSError as e:
        raise EventDirNotWritable(
            f"cannot write TensorBoard events to {logdir}: {e.strerror or e}") from None
    return logdir


def event_files(logdir: str) -> list[str]:
    """The directory's event files in TensorBoard's order (by name: they start with a time)."""
    return sorted(p for p in glob.glob(os.path.join(logdir, _PREFIX + "*"))
                  if not p.endswith(".tmp"))


def _records(path: str):
    """The serialized records of a TFRecord file; a record cut short or failing its checksum
    (the process was killed while writing it) ends the file."""
    from tensorboardX.record_writer import masked_crc32c

    with open(path, "rb") as f:
        while True:
            header = f.read(12)
            if len(header) < 12:
                return
            (length,) = struct.unpack("<Q", header[:8])
            if struct.unpack("<I", header[8:])[0] != masked_crc32c(header[:8]):
                return
            data = f.read(length)
            crc = f.read(4)
            if len(data) < length or len(crc) < 4 or \
                    struct.unpack("<I", crc)[0] != masked_crc32c(data):
                return
            yield data


def read_events(path: str) -> list:
    """The `Event` protos of one event file."""
    from tensorboardX.proto import event_pb2

    out = []
    for data in _records(path):
        e = event_pb2.Event()
        e.ParseFromString(data)
        out.append(e)
    return out


def read_scalars(logdir: str) -> dict[str, list[tuple[int, float]]]:
    """{tag: [(step, value), ...]} of every scalar in the directory's event files, in the
    order written."""
    scalars: dict[str, list[tuple[int, float]]] = {}
    for path in event_files(logdir):
        for e in read_events(path):
            for v in e.summary.value:
                if v.HasField("simple_value"):
                    scalars.setdefault(v.tag, []).append((int(e.step), float(v.simple_value)))
    return scalars


def _kept(tag: str, step: int, keep: int, final: bool) -> bool:
    """Whether an event logged before a resume from env step `keep` stays: an evaluation at
    step s is of the chunk that starts at s (kept below `keep`, and at it when the run had
    finished: its final evaluation); everything else at s is of the chunk that ends at s."""
    if tag.startswith("eval"):
        return step < keep or (final and step == keep)
    return step <= keep


def truncate(logdir: str, keep: int, final: bool = False) -> float:
    """Remove from the event files what chunks past env step `keep` logged (each file
    rewritten atomically; a file left without summaries is removed); returns the last
    `time/wall_s` kept (0 without one), from which a resumed run counts on."""
    from tensorboardX.record_writer import RecordWriter

    wall = 0.0
    for path in event_files(logdir):
        events = read_events(path)
        kept, changed = [], False
        for e in events:
            if e.HasField("summary"):
                values = [v for v in e.summary.value if _kept(v.tag, e.step, keep, final)]
                if len(values) != len(e.summary.value):
                    changed = True
                    if not values:
                        continue
                    del e.summary.value[:]
                    e.summary.value.extend(values)
                for v in values:
                    if v.tag == "time/wall_s":
                        wall = max(wall, v.simple_value)
            elif e.HasField("session_log") and e.step >= keep:
                changed = True
                continue
            kept.append(e)
        if not any(e.HasField("summary") for e in kept):
            os.remove(path)
            continue
        if not changed:
            continue
        tmp = path + ".tmp"
        writer = RecordWriter(tmp)
        for e in kept:
            writer.write(e.SerializeToString())
        writer.flush()
        writer.close()
        os.replace(tmp, path)
    return wall


def clear(logdir: str) -> None:
    """A new run in the directory: the event files of an earlier one removed."""
    for path in event_files(logdir):
        os.remove(path)


class EventLog:
    """The run's TensorBoard writer: per chunk and per evaluation scalars, flushed every few
    seconds and at `close`. `resume_from` (env steps of the restored checkpoint, None for a
    new run) trims what the files hold past it first (`truncate`)."""

    def __init__(self, out: str, resume_from: int | None = None, final: bool = False):
        from tensorboardX import SummaryWriter

        logdir = check_writable(out)
        if resume_from is None:
            clear(logdir)
            self.wall_offset = 0.0
        else:
            self.wall_offset = truncate(logdir, resume_from, final)
        # pid and a counter in the name: two writers opened within one second (the name's
        # time is in seconds) never write the same file.
        self.writer = SummaryWriter(logdir, flush_secs=5,
                                    filename_suffix=f".{os.getpid()}.{next(_COUNTER)}")
        self.logdir = logdir

    def config(self, cfg_json: dict) -> None:
        self.writer.add_text("config", "```\n" + json.dumps(cfg_json, indent=2) + "\n```", 0)

    def _scalars(self, step: int, prefix: str, per_seed: str, values: dict) -> None:
        import numpy as np

        for k, v in values.items():
            v = np.asarray(v, np.float64).reshape(-1)
            self.writer.add_scalar(f"{prefix}/{k}", float(v.mean()), step)
            for s, x in enumerate(v):
                self.writer.add_scalar(f"{per_seed}/{k}/seed_{s}", float(x), step)

    def chunk(self, env_steps: int, train: dict, chunk_s: float, steps_per_s: float,
              wall_s: float) -> None:
        """One chunk that ended at `env_steps`: its training metrics ([seeds] each) and speed."""
        self._scalars(env_steps, "train", "train_per_seed", train)
        self.writer.add_scalar("time/env_steps_per_s", steps_per_s, env_steps)
        self.writer.add_scalar("time/chunk_s", chunk_s, env_steps)
        self.writer.add_scalar("time/wall_s", self.wall_offset + wall_s, env_steps)

    def evaluation(self, env_steps: int, ev: dict) -> None:
        """The evaluation of the policy after `env_steps` ([seeds] each)."""
        self._scalars(env_steps, "eval", "eval_per_seed",
                      {k: ev[k] for k in ("final_distance", "final_distance_median",
                                          "start_distance")})

    def flush(self) -> None:
        self.writer.flush()

    def close(self) -> None:
        self.writer.close()
