"""What the benchmarks share: timing a jitted function, running a CLI in its own process,
the machine a result was measured on, writing a results JSON."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


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
    """What a results JSON records of the machine it was measured on: JAX's backend, device and
    version, the CPU and its core count, and the load average when the benchmark started."""
    import platform

    import jax

    device = jax.devices()[0]
    return {"jax_backend": jax.default_backend(), "jax_device": str(device),
            "device_kind": device.device_kind, "jax_version": jax.__version__,
            "cpu": platform.processor() or platform.machine(), "cpu_model": cpu_model(),
            "cpu_count": os.cpu_count(), "load_average_at_start": list(os.getloadavg())}


def run_module(args: list[str]) -> tuple[float, str]:
    """`python -m ARGS` in its own process, in the repository root -> (wall seconds, stdout);
    stops with its stderr's tail if it fails."""
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", *args], cwd=REPO, capture_output=True,
                          text=True)
    if proc.returncode:
        raise SystemExit(f"{' '.join(args)} failed:\n{proc.stderr[-3000:]}")
    return time.perf_counter() - t0, proc.stdout


def last_json(text: str) -> dict:
    """The JSON object a CLI printed last (its summary)."""
    start = text.rfind("\n{")
    return json.loads(text[start + 1 if start >= 0 else 0:])


def write_results(path: str, res: dict) -> None:
    """Stamp the load average at the end (was the machine shared?), write `res` to `path`
    (creating its folder) and say so."""
    res["load_average_at_end"] = list(os.getloadavg())
    res.setdefault("cpu_model", cpu_model())
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as f:
        json.dump(res, f, indent=2)
    print(f"wrote {path}")


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
