"""What the benchmarks share: the one result schema and its writer, the machine and the
versions a figure was measured with, timing a jitted function.

Every benchmark writes bench/results/NAME.json (or --out) through `write_result`:

    {"benchmark": NAME, "command": "python -m bench NAME ...", "date": UTC ISO time,
     "git": the commit (and whether the tree had local changes),
     "machine": {platform, CPU model and count, JAX backend and device, load averages},
     "versions": {python, jax, jaxlib, mujoco, mujoco-mjx, flax, optax, numpy, ...},
     "figures": what the benchmark measured}

Only the latest result of each benchmark is committed: git keeps the earlier ones.
"""
from __future__ import annotations

import datetime
import json
import os
import platform
import subprocess
import sys
import time

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RESULTS = os.path.join(REPO, "bench", "results")
PACKAGES = ("jax", "jaxlib", "mujoco", "mujoco-mjx", "flax", "optax", "orbax-checkpoint",
            "numpy", "opencv-python-headless")


def result_path(name: str) -> str:
    """bench/results/NAME.json: where benchmark NAME's latest result is committed."""
    return os.path.join(RESULTS, f"{name}.json")


def cpu_model() -> str:
    """The CPU's model name (/proc/cpuinfo; "" elsewhere): this project's 2-core machines
    differ by ~2.5x in speed, so every timed figure names the one it ran on."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return ""


def machine_info() -> dict:
    """The machine a result is measured on: platform, CPU, JAX's backend and device, and the
    load average when the benchmark started (call it first: `write_result` adds the end's)."""
    import jax

    device = jax.devices()[0]
    return {"platform": platform.platform(), "cpu_model": cpu_model(),
            "cpu_count": os.cpu_count(), "jax_backend": jax.default_backend(),
            "jax_device": str(device), "device_kind": device.device_kind,
            "device_count": jax.device_count(), "load_average_at_start": list(os.getloadavg())}


def versions() -> dict:
    """Python's and the installed packages' versions (None: not installed)."""
    from importlib import metadata

    out = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def git_commit() -> str:
    """HEAD's short hash, "+local" when the working tree differs from it ("" outside git)."""
    def git(*args):
        return subprocess.run(["git", *args], cwd=REPO, capture_output=True, text=True,
                              check=False).stdout.strip()

    head = git("rev-parse", "--short", "HEAD")
    return f"{head}+local" if head and git("status", "--porcelain", "--untracked-files=no") \
        else head


def write_result(name: str, figures: dict, machine: dict, argv=None, path: str | None = None
                 ) -> str:
    """Write benchmark `name`'s figures in the suite's schema to `path` (default
    bench/results/NAME.json), measured on `machine` (`machine_info()` from the start);
    `argv`: the benchmark's arguments, for the command line. Returns the path."""
    argv = sys.argv[1:] if argv is None else list(argv)
    res = {"benchmark": name, "command": " ".join(["python -m bench", name, *argv]),
           "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
           "git": git_commit(),
           "machine": {**machine, "load_average_at_end": list(os.getloadavg())},
           "versions": versions(), "figures": figures}
    path = path or result_path(name)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as f:
        json.dump(res, f, indent=2, default=_plain)
    print(f"wrote {path}")
    return path


def _plain(x):
    """numpy scalars and arrays as JSON numbers and lists."""
    if hasattr(x, "tolist"):
        return x.tolist()
    raise TypeError(f"{type(x).__name__} is not JSON serializable")


def read_figures(path: str, machine: dict) -> dict:
    """The figures of an earlier result at `path` measured on the same device (a benchmark
    run in parts keeps the others' figures); {} when there is none."""
    if not os.path.exists(path):
        return {}
    with open(path) as f:
        earlier = json.load(f)
    same = earlier.get("machine", {}).get("jax_device") == machine["jax_device"]
    return earlier.get("figures", {}) if same else {}


def time_best(fn, *args, repeats: int = 3, min_time: float = 1.0) -> tuple[float, float]:
    """(first call incl. compile s, best s per call) of a jitted fn: at least `repeats`
    timed calls after the first, more (up to 20) until `min_time` seconds were timed."""
    import jax

    t0 = time.perf_counter()
    jax.block_until_ready(fn(*args))
    first = time.perf_counter() - t0
    best, total, n = float("inf"), 0.0, 0
    while n < repeats or (total < min_time and n < 20):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        dt = time.perf_counter() - t0
        best, total, n = min(best, dt), total + dt, n + 1
    return first, best
