"""The GPU check (`python -m bench gpu_check`) at tiny sizes on the CPU: its code path works
and it writes the suite's result schema, so it runs the day a GPU is lent. In its own
process, as a user runs it (the tests import nothing of bench/), with the suite's
compilation cache and XLA flags."""

import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_gpu_check_runs_at_tiny_sizes(tmp_path):
    out = tmp_path / "gpu_check.json"
    env = {**os.environ, "JAX_PLATFORMS": "cpu",
           "JAX_COMPILATION_CACHE_DIR": os.path.join(ROOT, ".jax_cache"),
           "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "1"}
    proc = subprocess.run([sys.executable, "-m", "bench", "gpu_check", "--tiny", "--out",
                           str(out)], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=1200)
    assert proc.returncode == 0, proc.stderr[-3000:]
    res = json.loads(out.read_text())
    assert res["benchmark"] == "gpu_check" and res["command"].startswith("python -m bench")
    assert {"date", "git", "machine", "versions", "figures"} <= set(res)
    assert res["machine"]["jax_backend"] == "cpu" and res["versions"]["jax"]
    fig = res["figures"]
    assert fig["tiny"] and set(fig["rendered_env_steps"]) == {"n4"}
    assert all(r["steps_per_s"] > 0 and r["compile_s"] > 0
               for r in fig["rendered_env_steps"].values())
    chunk = fig["chunk"]
    assert chunk["compile_s"] > 0 and chunk["env_steps_per_s"] > 0 and chunk["metrics_finite"]
