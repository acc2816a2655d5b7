"""Several processes, tested on one machine: two train.py processes joined by
`jax.distributed` over localhost (CPU, one device each; `--coordinator`, `--num-processes`,
`--process-id`) shard a 2-seed run's seed axis over their two devices, and give the metrics of
the same run in one process.

The state oracle's run (the cheapest that runs the whole compiled chunk: collection, SAC,
evaluation): 2 seeds x 4 chunks of 100 env steps, checkpoints every 2 chunks. Not bit-exact,
for the reason tests/test_sharding.py gives (XLA:CPU's 2-device program rounds an MJX step
differently within a float32 ulp, and training amplifies it): the step-0 evaluation, before any
training, is equal; later rows agree to 5% and each lies nearer its own seed than the other
seed (a swapped or shared seed would not).
"""

import csv
import json
import os
import socket
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SETS = ["n_envs=2", "epoch_env_steps=100", "total_env_steps=400", "n_eval_goals=2",
        "checkpoint_every_epochs=2", "keep_checkpoints=2", "sac.learning_starts=50"]
ARGV = ["train.py", "--task", "puck_push", "--algo", "oracle", "--preset", "smoke", "--seeds",
        "2", "--set", *SETS, "--compile-cache", os.path.join(ROOT, ".jax_cache")]
TIMEOUT = 900


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def _env():
    return dict(os.environ, JAX_PLATFORMS="cpu", MUJOCO_GL="disable")


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("multihost")
    single, multi = str(base / "single"), str(base / "multi")
    proc = subprocess.run([sys.executable, *ARGV, "--out", single], cwd=ROOT, env=_env(),
                          capture_output=True, text=True, timeout=TIMEOUT)
    assert proc.returncode == 0, proc.stderr[-4000:]
    port = _free_port()
    logs, procs = [], []
    for i in (0, 1):  # files, not pipes: a process blocked on a full pipe would stall both
        log = open(base / f"process_{i}.log", "w+")
        logs.append(log)
        procs.append(subprocess.Popen(
            [sys.executable, *ARGV, "--out", multi, "--coordinator", f"localhost:{port}",
             "--num-processes", "2", "--process-id", str(i)],
            cwd=ROOT, env=_env(), stdout=log, stderr=subprocess.STDOUT, text=True))
    try:
        codes = [p.wait(timeout=TIMEOUT) for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
    outputs = []
    for log in logs:
        log.seek(0)
        outputs.append(log.read())
        log.close()
    assert codes == [0, 0], "\n".join(o[-3000:] for o in outputs)
    return single, multi, outputs


def _rows(run):
    with open(os.path.join(run, "metrics.csv"), newline="") as f:
        return [{k: float(v) for k, v in r.items()} for r in csv.DictReader(f)]


def _summary(output):
    """The JSON summary train.py prints at the end (other lines may follow it)."""
    start = output.rindex('{\n  "out":')
    return json.JSONDecoder().raw_decode(output[start:])[0]


def test_two_processes_shard_the_seeds(runs):
    single, multi, outputs = runs
    with open(os.path.join(multi, "complete.json")) as f:
        assert json.load(f)["devices"] == 2  # one device per process, seeds split over both
    with open(os.path.join(single, "complete.json")) as f:
        assert json.load(f)["devices"] == 1
    # Every process gets every seed's metrics (gathered), process 0 alone writes the files,
    # and each process writes its own shards of the checkpoints.
    finals = [_summary(o)["final_distance_per_seed"] for o in outputs]
    assert finals[0] == finals[1] and len(finals[0]) == 2
    step = os.path.join(multi, "ckpt", "4", "default")
    assert {"ocdbt.process_0", "ocdbt.process_1"} <= set(os.listdir(step))
    assert len(os.listdir(os.path.join(multi, "tb"))) == 1
    assert not os.path.exists(os.path.join(multi, "train.lock"))


def test_sharded_over_processes_equals_one_process(runs):
    single, multi, _ = runs
    a, b = _rows(multi), _rows(single)
    assert [(r["env_steps"], r["seed"]) for r in a] == [(r["env_steps"], r["seed"]) for r in b]
    assert len(a) == 10  # 2 seeds x evaluations at 0, 100, ..., 400 env steps
    assert a[:2] == b[:2]  # before any training: the same evaluation
    assert all(r["q_loss"] > 0 for r in a[2:])  # SAC did learn
    for ra, rb in zip(a, b):
        for k in ra:
            np.testing.assert_allclose(ra[k], rb[k], rtol=0.05, atol=1e-5, err_msg=k)
    keys = [k for k in a[0] if k not in ("env_steps", "seed")]
    for i in range(2, len(a), 2):  # each seed nearest its own: no seed swapped or shared
        for s in (0, 1):
            mine = np.array([a[i + s][k] for k in keys])
            own = np.array([b[i + s][k] for k in keys])
            other = np.array([b[i + 1 - s][k] for k in keys])
            assert np.linalg.norm(mine - own) < np.linalg.norm(mine - other), (i, s)
