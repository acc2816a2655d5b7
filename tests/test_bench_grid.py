"""bench/grid.py: its results JSON from the runs' timings.json; the committed
bench/results/grid_smoke.json is what grid.py writes and says how its wall time was taken."""

import importlib.util
import json
import os
import re

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
COMMITTED = os.path.join(ROOT, "bench", "results", "grid_smoke.json")


@pytest.fixture(scope="module")
def grid():
    path = os.path.join(ROOT, "bench", "grid.py")
    spec = importlib.util.spec_from_file_location("bench_grid", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _fake_grid(base):
    """Two runs' timings.json as roll_jax.training.driver.run writes them (phase lists, totals)."""
    for name, chunks in (("a__roll", [10.5, 1.25]), ("b__skewfit", [8.0, 1.25])):
        d = base / "runs" / name
        d.mkdir(parents=True)
        wall = {"segmentation": [3.0], "pretrain": [4.1], "init": [1.0], "chunks": chunks,
                "final_eval": [0.5]}
        (d / "timings.json").write_text(json.dumps({
            "wall_s": wall, "cpu_s": wall, "total_wall_s": 20.0, "total_cpu_s": 19.5}))


def test_summarize_only_marks_the_given_wall_time(grid, tmp_path):
    _fake_grid(tmp_path / "g")
    res_path = tmp_path / "res.json"
    assert grid.main(["--out", str(tmp_path / "g"), "--summarize-only", "--wall-s", "90.44",
                      "--results", str(res_path)]) == 0
    res = json.loads(res_path.read_text())
    assert res["wall_s"] == 90.4 and res["wall_min"] == 1.51
    assert res["wall_how"].startswith("given (--wall-s 90.44)")
    assert res["runs"] == 2 and res["sum_run_wall_s"] == 40.0
    assert res["first_chunk_wall_s"] == 18.5 and res["phase_wall_s"]["chunks"] == 21.0
    assert res["per_run"][0]["chunks_wall_s"] == 11.75
    # The committed results carry exactly the fields grid.py writes, top level and per run.
    committed = json.load(open(COMMITTED))
    assert list(committed) == list(res)
    assert [list(r) for r in committed["per_run"]] == [list(res["per_run"][0])] * committed["runs"]


def test_committed_results_are_grid_py_output(grid):
    c = json.load(open(COMMITTED))
    # Every sum is the one grid.py makes of the per-run figures (none entered by hand).
    again = grid.summarize(c["per_run"], c["command"], c["wall_s"], c["wall_how"])
    for k in ("runs", "sum_run_wall_s", "sum_run_cpu_s", "first_chunk_wall_s", "phase_wall_s",
              "per_run"):
        assert again[k] == c[k], k
    # The wall time says whether grid.py timed it or it was given by hand, and which value.
    given = re.fullmatch(r"given \(--wall-s ([0-9.]+)\): timed by hand around the same command",
                         c["wall_how"])
    assert given or c["wall_how"].startswith("timed by bench/grid.py")
    wall = float(given.group(1)) if given else c["wall_s"]
    assert round(wall, 1) == c["wall_s"] and c["wall_min"] == pytest.approx(wall / 60, abs=0.005)
