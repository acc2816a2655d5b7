"""The reproduction grid without training: argument refusals, skipping finished runs,
resuming unfinished ones, and the figures/table from synthetic metrics.csv files."""

import csv
import json
import os

import numpy as np
import pytest

from configs.train import build_config
from roll_jax.training import reproduce, run_dir


class FakeRun:
    """Stands in for driver.run: records calls, writes what a finished run leaves."""

    def __init__(self):
        self.calls = []

    def __call__(self, cfg, out, resume=False, seg_ckpt=None, seed=0, devices="all", **kw):
        self.calls.append({"task": cfg.task, "out": out, "resume": resume, "seeds": cfg.seeds,
                           "seg_ckpt": seg_ckpt, "devices": devices, "use_lstm": cfg.use_lstm})
        os.makedirs(out, exist_ok=True)
        with open(os.path.join(out, "config.json"), "w") as f:
            json.dump(run_dir.config_json(cfg), f)
        run_dir.write_inputs(out, seg_ckpt, None, seed)
        _write_metrics(out, {1000: [0.5] * cfg.seeds})
        with open(os.path.join(out, run_dir.COMPLETE_MARKER), "w") as f:
            f.write("{}")
        return []


def _write_metrics(out, values: dict[int, list[float]]):
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "metrics.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["env_steps", "seed", "final_distance", "q_loss"])
        w.writeheader()
        for step, vals in values.items():
            for s, v in enumerate(vals):
                w.writerow({"env_steps": step, "seed": s, "final_distance": v, "q_loss": 1.0})


def _text(path) -> str:
    with open(path) as f:
        return f.read()


def _table(path) -> list[dict]:
    with open(path) as f:
        return list(csv.DictReader(f))


def _args(out, *extra):
    return ["--preset", "smoke", "--out", str(out), *extra]


@pytest.mark.parametrize("extra, msg", [
    (["--tasks", "puck_push", "nope"], "unknown --tasks 'nope'"),
    (["--algos", "ppo"], "unknown --algos 'ppo'"),
    (["--algos", "roll", "roll"], "--algos lists a value twice"),
    (["--set", "seeds=3"], "--set seeds: the grid sets these itself"),
    (["--set", "use_lstm=False"], "--set use_lstm: the grid sets these itself"),
    (["--report-only", "--dry-run"], "--report-only and --dry-run contradict"),
    (["--seeds", "0"], "--seeds must be >= 1"),
    (["--set", "sac.replay_size=10"], "replay_size=10 is smaller than one chunk"),
    (["--set", "nonsense=1"], "--set nonsense: unknown field of TrainConfig"),
    (["--devices", "0"], "'all' or a positive integer"),
])
def test_rejects_before_running(tmp_path, capsys, extra, msg):
    fake = FakeRun()
    out = tmp_path / "grid"
    with pytest.raises(SystemExit) as e:
        reproduce.main(_args(out, "--tasks", "puck_push", *extra) if "--tasks" not in extra
                       else _args(out, *extra), run_fn=fake)
    assert e.value.code == 2
    assert msg in capsys.readouterr().err
    assert fake.calls == [] and not out.exists()


def test_unknown_preset_rejected(tmp_path, capsys):
    with pytest.raises(SystemExit):
        reproduce.main(["--preset", "huge", "--out", str(tmp_path / "g")], run_fn=FakeRun())
    assert "unknown --preset 'huge'" in capsys.readouterr().err


def test_refuses_dir_of_other_config(tmp_path, capsys):
    """A finished run of another config (here 3 seeds, the grid asks 2) is never overwritten:
    the whole grid is refused before anything runs."""
    fake = FakeRun()
    out = tmp_path / "grid"
    cfg3 = build_config("puck_push", "skewfit", "smoke", seeds=3)
    FakeRun()(cfg3, reproduce.run_dir(str(out), "puck_push", "skewfit"))
    before = (out / "runs/puck_push__skewfit/config.json").read_text()
    with pytest.raises(SystemExit):
        reproduce.main(_args(out, "--tasks", "puck_push", "--seeds", "2"), run_fn=fake)
    err = capsys.readouterr().err
    assert "holds a finished run made with other settings" in err and "'seeds'" in err
    assert fake.calls == []
    assert (out / "runs/puck_push__skewfit/config.json").read_text() == before


def test_refuses_dir_of_other_base_seed(tmp_path, capsys):
    """The same config from another base seed is another run: refused, naming both seeds."""
    out = tmp_path / "grid"
    assert reproduce.main(_args(out, "--tasks", "puck_push", "--algos", "skewfit"),
                          run_fn=FakeRun()) == 0
    fake = FakeRun()
    with pytest.raises(SystemExit):
        reproduce.main(_args(out, "--tasks", "puck_push", "--algos", "skewfit", "--seed", "1"),
                       run_fn=fake)
    err = capsys.readouterr().err
    assert "was trained with --seed 0, the command line gives --seed 1" in err
    assert fake.calls == []


def test_skips_finished_resumes_unfinished(tmp_path):
    out = tmp_path / "grid"
    argv = _args(out, "--tasks", "puck_push", "hurdle_top", "--algos", "roll", "--seeds", "2")
    a, _ = reproduce.parse_args(argv)
    cells = {(c.task, c.variant): c for c in reproduce.plan(a)}
    # puck_push roll: finished; hurdle_top roll: started (config.json, no marker).
    finished = cells[("puck_push", "roll")]
    FakeRun()(finished.cfg, finished.out)
    _write_metrics(finished.out, {500: [0.1, 0.2], 1000: [0.3, 0.4]})  # sentinel content
    paths = [os.path.join(finished.out, n) for n in os.listdir(finished.out)]
    snapshot = {p: (_text(p), os.stat(p).st_mtime_ns) for p in paths}
    started = cells[("hurdle_top", "roll")]
    os.makedirs(started.out)
    with open(os.path.join(started.out, "config.json"), "w") as f:
        json.dump(run_dir.config_json(started.cfg), f)

    fake = FakeRun()
    assert reproduce.main(argv, run_fn=fake) == 0
    assert [(c["task"], c["resume"]) for c in fake.calls] == [("hurdle_top", True)]
    assert fake.calls[0]["seeds"] == 2
    assert fake.calls[0]["seg_ckpt"] == os.path.join(str(out), "segmentation", "hurdle_top")
    for path, (text, mtime) in snapshot.items():
        assert _text(path) == text and os.stat(path).st_mtime_ns == mtime, path
    # Everything finished now: a rerun trains nothing; the table reads the finished run.
    again = FakeRun()
    reproduce.main(argv, run_fn=again)
    assert again.calls == []
    rows = _table(out / "results.csv")
    pp = next(r for r in rows if r["task"] == "puck_push")
    assert float(pp["median"]) == pytest.approx(0.35) and int(pp["env_steps"]) == 1000


def test_new_grid_with_ablations_runs_each_cell_once(tmp_path):
    fake = FakeRun()
    out = tmp_path / "grid"
    reproduce.main(_args(out, "--tasks", "hurdle_top", "--ablations", "--seeds", "2",
                         "--devices", "1"), run_fn=fake)
    dirs = [os.path.basename(c["out"]) for c in fake.calls]
    assert dirs == ["hurdle_top__roll", "hurdle_top__skewfit", "hurdle_top__roll_no_matching_loss",
                    "hurdle_top__roll_no_lstm", "hurdle_top__roll_no_object_vae"]
    assert all(not c["resume"] and c["devices"] == "1" for c in fake.calls)
    assert [c["use_lstm"] for c in fake.calls] == [True, True, True, False, True]
    for name in ("figure4.png", "ablations.png", "results.md", "results.csv"):
        assert (out / name).stat().st_size > 0, name


def test_figures_and_table_from_metrics(tmp_path):
    """Synthetic runs with known numbers: the table's median / quartiles are numpy's."""
    out = tmp_path / "grid"
    vals = {("puck_push", "roll"): {500: [0.4, 0.3, 0.2, 0.1], 1000: [0.4, 0.1, 0.2, 0.3]},
            ("puck_push", "skewfit"): {500: [0.5, 0.6, 0.7, 0.8], 1000: [0.5, 0.6, 0.7, 0.9]},
            ("hurdle_top", "roll"): {1000: [0.0, 1.0, 2.0, 3.0]},
            ("hurdle_top", "roll_no_lstm"): {1000: [1.0, 1.0, 1.0, 5.0]}}
    for (task, variant), v in vals.items():
        _write_metrics(reproduce.run_dir(str(out), task, variant), v)
    with open(os.path.join(reproduce.run_dir(str(out), "puck_push", "roll"),
                           run_dir.COMPLETE_MARKER), "w") as f:
        f.write("{}")
    fake = FakeRun()
    assert reproduce.main(_args(out, "--tasks", "puck_push", "hurdle_top", "--ablations",
                                "--seeds", "4", "--report-only"), run_fn=fake) == 0
    assert fake.calls == []
    for name in ("figure4.png", "ablations.png"):
        with open(out / name, "rb") as f:
            assert f.read(8) == b"\x89PNG\r\n\x1a\n", name
    rows = {(r["task"], r["algo"]): r for r in _table(out / "results.csv")}
    # Cells with no metrics.csv (hurdle_top skewfit, two ablations) are left out.
    assert set(rows) == set(vals)
    for key, v in vals.items():
        final = v[max(v)]
        r = rows[key]
        assert int(r["env_steps"]) == max(v) and int(r["seeds"]) == 4
        for col, want in (("median", np.median(final)), ("q25", np.percentile(final, 25)),
                          ("q75", np.percentile(final, 75))):
            assert float(r[col]) == pytest.approx(want), (key, col)
    assert rows[("puck_push", "roll")]["complete"] == "True"
    assert rows[("puck_push", "skewfit")]["complete"] == "False"
    r = rows[("hurdle_top", "roll_no_lstm")]
    assert (float(r["median"]), float(r["q25"]), float(r["q75"])) == (1.0, 1.0, 2.0)
    md = (out / "results.md").read_text()
    # Areas under the curve per seed: (0.4 + 0.4) / 2, (0.3 + 0.1) / 2, ... over 500 steps.
    r = rows[("puck_push", "roll")]
    assert [float(r[c]) for c in ("auc_median", "auc_q25", "auc_q75")] == pytest.approx(
        [0.2, 0.2, 0.25])
    assert ("| puck_push | ROLL | 1000 | 4 | 0.2500 | 0.1750 | 0.3250 | 0.2000 | 0.2000 | "
            "0.2500 | yes |") in md
    assert ("| hurdle_top | ROLL, no LSTM | 1000 | 4 | 1.0000 | 1.0000 | 2.0000 | 1.0000 | "
            "1.0000 | 2.0000 | no |") in md


def test_dry_run_trains_nothing(tmp_path, capsys):
    fake = FakeRun()
    out = tmp_path / "grid"
    assert reproduce.main(_args(out, "--tasks", "door_open", "--dry-run"), run_fn=fake) == 0
    text = capsys.readouterr().out
    assert "new    door_open roll" in text and "door_open skewfit" in text
    assert fake.calls == [] and not out.exists()


def test_parallel_jobs_fit_each_segmentation_once_before_its_other_cells(tmp_path):
    """--jobs 2 (threads stand in for the worker processes): every cell runs once; a task's
    segmenting cells after the first wait until it has written the segmentation."""
    import concurrent.futures as cf
    import threading
    import time as _time

    from roll_jax.encoders.goal_encoding import goal_encoder

    events, lock = [], threading.Lock()

    class SegRun(FakeRun):
        def __call__(self, cfg, out, seg_ckpt=None, **kw):
            with lock:
                events.append(("start", os.path.basename(out)))
            uses = goal_encoder(cfg).segment
            if uses:  # the first segmenting cell of a task fits it; the others must find it
                fitted = os.path.exists(os.path.join(seg_ckpt, "meta.json"))
                _time.sleep(0.05)
                os.makedirs(seg_ckpt, exist_ok=True)
                with open(os.path.join(seg_ckpt, "meta.json"), "w") as f:
                    f.write("{}")
                with lock:
                    events.append(("fit" if not fitted else "load", os.path.basename(out)))
            super().__call__(cfg, out, seg_ckpt=seg_ckpt, **kw)
            with lock:
                events.append(("end", os.path.basename(out)))
            return []

    fake, out = SegRun(), tmp_path / "grid"
    assert reproduce.main(_args(out, "--tasks", "puck_push", "hurdle_top", "--ablations",
                                "--seeds", "2", "--devices", "1", "--jobs", "2"),
                          run_fn=fake, pool=cf.ThreadPoolExecutor) == 0
    ran = sorted(os.path.basename(c["out"]) for c in fake.calls)
    assert ran == sorted(["puck_push__roll", "puck_push__skewfit", "hurdle_top__roll",
                          "hurdle_top__skewfit", "hurdle_top__roll_no_matching_loss",
                          "hurdle_top__roll_no_lstm", "hurdle_top__roll_no_object_vae"])
    fits = [name for kind, name in events if kind == "fit"]
    assert sorted(fits) == ["hurdle_top__roll", "puck_push__roll"]  # once per task
    for waiter in ("hurdle_top__roll_no_matching_loss", "hurdle_top__roll_no_lstm"):
        assert events.index(("end", "hurdle_top__roll")) < events.index(("start", waiter))
        assert ("load", waiter) in events
    # Skew-Fit and the no-object-VAE ablation never segment: they need not wait.
    assert not any(name.endswith(("skewfit", "no_object_vae")) for kind, name in events
                   if kind in ("fit", "load"))
    assert (out / "results.md").stat().st_size > 0
    with pytest.raises(SystemExit):
        reproduce.main(_args(out, "--jobs", "0"), run_fn=FakeRun())


def test_schedule_starts_the_fitter_that_releases_most_cells_first(tmp_path):
    a, _ = reproduce.parse_args(_args(tmp_path / "grid", "--tasks", "puck_push", "hurdle_top",
                                      "--ablations", "--seeds", "2"))
    start, releases = reproduce.schedule(reproduce.plan(a))
    names = [os.path.basename(c.out) for c in start]
    # hurdle_top's ROLL run fits the segmentation two ablations wait for: it goes first; of
    # the rest, the ablation that pre-trains scene-VAE and LSTM before the Skew-Fit runs.
    assert names == ["hurdle_top__roll", "puck_push__roll", "hurdle_top__roll_no_object_vae",
                     "puck_push__skewfit", "hurdle_top__skewfit"]
    released = {os.path.basename(k): sorted(os.path.basename(c.out) for c in v)
                for k, v in releases.items()}
    assert released == {"hurdle_top__roll": ["hurdle_top__roll_no_lstm",
                                             "hurdle_top__roll_no_matching_loss"],
                        "puck_push__roll": []}


# ----------------------------------------------------------------------------- timings

def _fake_grid(base):
    """Two runs' timings.json as driver.run writes them (phase lists, totals)."""
    for name, chunks in (("a__roll", [10.5, 1.25]), ("b__skewfit", [8.0, 1.25])):
        d = base / "runs" / name
        d.mkdir(parents=True)
        wall = {"segmentation": [3.0], "pretrain": [4.1], "init": [1.0], "chunks": chunks,
                "final_eval": [0.5]}
        (d / "timings.json").write_text(json.dumps({
            "wall_s": wall, "cpu_s": wall, "total_wall_s": 20.0, "total_cpu_s": 19.5}))


def test_run_timings_sum_each_runs_phases(tmp_path):
    _fake_grid(tmp_path)
    runs = reproduce.run_timings(str(tmp_path))
    assert [r["run"] for r in runs] == ["a__roll", "b__skewfit"]
    assert runs[0]["chunks_wall_s"] == 11.75 and runs[0]["first_chunk_wall_s"] == 10.5
    total = reproduce.timings_summary(runs)
    assert total["runs"] == 2 and total["sum_run_wall_s"] == 40.0
    assert total["first_chunk_wall_s"] == 18.5 and total["phase_wall_s"]["chunks"] == 21.0
    (tmp_path / "runs" / "c__oracle").mkdir()
    with pytest.raises(FileNotFoundError, match="no timings.json"):
        reproduce.run_timings(str(tmp_path))


def test_committed_grid_benchmark_sums_its_runs():
    """bench/results/grid.json (python -m bench grid) holds the sums of its per-run rows."""
    path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "bench",
                        "results", "grid.json")
    with open(path) as f:
        res = json.load(f)
    assert res["benchmark"] == "grid" and {"machine", "versions", "date"} <= set(res)
    fig = res["figures"]
    again = reproduce.timings_summary(fig["per_run"])
    assert {k: fig[k] for k in again} == again
    assert fig["wall_min"] == pytest.approx(fig["wall_s"] / 60, abs=0.005)
