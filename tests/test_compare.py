"""roll-analysis compare: the paired figures of two runs' metrics rows and of two runs' final
policies on shared goals."""

import numpy as np
import pytest

from roll_jax.analysis import compare


def _rows(dist):  # dist[eval][seed]
    return [{"env_steps": 1000 * i, "seed": s, "final_distance": d}
            for i, per_seed in enumerate(dist) for s, d in enumerate(per_seed)]


def test_compare_pairs_evaluations_and_counts_wins():
    goals = np.array([[0.10, 0.08], [0.12, 0.06], [0.05, 0.09], [0.11, 0.07]])  # shared jitter
    a, b = goals - 0.01, goals + 0.01
    a[3, 0] += 0.05  # one evaluation where A is worse
    out = compare.compare(_rows(a.tolist()), _rows(b.tolist()), from_steps=1000)
    assert out["n_evaluations"] == 3 and out["evaluations_a_below_b"] == 2
    np.testing.assert_allclose(out["paired_diff_mean"], (-0.02 * 6 + 0.05) / 6, atol=1e-12)
    assert out["corr_per_seed_eval"] > 0.5  # the goals' jitter shows in both runs
    np.testing.assert_allclose(out["median_a"][0], np.median(a[0]))


def test_compare_refuses_runs_that_do_not_pair():
    with pytest.raises(ValueError, match="do not share evaluation steps and seeds"):
        compare.compare(_rows([[0.1, 0.1]]), _rows([[0.1, 0.1], [0.1, 0.1]]))
    short = compare.compare(_rows([[0.1], [0.2], [0.3]]), _rows([[0.2], [0.1]]), to_steps=1000)
    assert short["env_steps"] == [0, 1000] and short["evaluations_a_below_b"] == 1
    with pytest.raises(ValueError, match="--from-steps 5000 is past the last evaluation 0"):
        compare.compare(_rows([[0.1]]), _rows([[0.2]]), from_steps=5000)


def test_final_policy_difference_is_per_episode():
    b = np.array([[4.0, 8.0, 2.0], [6.0, 3.0, 9.0]])  # [seeds, goals] cm
    a = b - np.array([[1.0, 2.0, -1.0], [1.0, 1.0, 1.0]])
    out = compare.difference(a, b)
    d = np.array([-1.0, -2.0, 1.0, -1.0, -1.0, -1.0])
    assert out["n"] == 6 and out["share_a_closer"] == pytest.approx(5 / 6)
    assert out["mean_a_minus_b_cm"] == pytest.approx(d.mean())
    assert out["standard_error_cm"] == pytest.approx(d.std(ddof=1) / np.sqrt(6))
    assert out["median_a_minus_b_cm"] == pytest.approx(-1.0)


def _finished_runs(tmp_path, shifts: dict, task: str = "puck_push") -> list[str]:
    """Finished 2-seed run directories of `task` whose final distances are 0.1 - 0.01 i + shift
    at evaluation i (500 env steps apart), one per name -> shift."""
    from configs.train import build_config
    from roll_jax.training import run_dir

    cfg = build_config(task, "roll", "smoke", seeds=2)
    runs = []
    for name, shift in shifts.items():
        d = tmp_path / name
        d.mkdir()
        run_dir.write_config(str(d), cfg)
        run_dir.append_rows(str(d / "metrics.csv"), [
            {"env_steps": 500 * i, "seed": s, "final_distance": 0.1 - 0.01 * i + shift,
             "start_distance": 0.1} for i in range(3) for s in range(2)])
        (d / run_dir.COMPLETE_MARKER).write_text("{}")
        runs.append(str(d))
    return runs


def test_compare_command_pairs_two_run_directories_and_plots_them(tmp_path, capsys):
    import json

    runs = _finished_runs(tmp_path, {"a": -0.01, "b": 0.01})
    out, png = tmp_path / "cmp.json", tmp_path / "fig" / "cmp.png"
    assert compare.main([*runs, "--out", str(out), "--plot", str(png)]) == 0
    assert png.stat().st_size > 0 and f"wrote {png}" in capsys.readouterr().out
    res = json.loads(out.read_text())
    assert res["evaluations_a_below_b"] == 3
    assert res["paired_diff_mean"] == pytest.approx(-0.02)


def test_compare_prints_the_door_in_radians_and_refuses_its_final_policies_in_cm(tmp_path,
                                                                                capsys):
    runs = _finished_runs(tmp_path, {"a": -0.01, "b": 0.01}, task="door_open")
    assert compare.main(runs) == 0
    printed = capsys.readouterr().out
    assert "A 0.090 rad  B 0.110 rad" in printed and "paired A-B -0.020 rad" in printed
    assert "cm" not in printed
    with pytest.raises(SystemExit):
        compare.main([*runs, "--n-goals", "4"])
    assert "door_open's distances are angles" in capsys.readouterr().err


def test_compare_pairs_every_further_run_with_the_first(tmp_path, capsys):
    import json

    runs = _finished_runs(tmp_path, {"a": 0.0, "b": 0.01, "c": -0.03})
    out, png = tmp_path / "cmp.json", tmp_path / "cmp.png"
    assert compare.main([*runs, "--labels", "A", "B", "C", "--out", str(out),
                         "--plot", str(png)]) == 0
    res = json.loads(out.read_text())
    assert [(p["a"], p["b"]) for p in res["pairs"]] == [(runs[0], runs[1]), (runs[0], runs[2])]
    assert res["pairs"][0]["paired_diff_mean"] == pytest.approx(-0.01)
    assert res["pairs"][1]["paired_diff_mean"] == pytest.approx(0.03)
    assert res["pairs"][1]["evaluations_a_below_b"] == 0
    assert png.stat().st_size > 0
    for bad, msg in (([runs[0]], "two or more runs"),
                     ([*runs, "--labels", "A", "B"], "2 labels for 3 runs"),
                     ([*runs, "--n-goals", "4"], "two runs' final policies")):
        with pytest.raises(SystemExit):
            compare.main(bad)
        assert msg in capsys.readouterr().err


def test_figure4_pairs_each_cell_with_roll_up_to_their_common_evaluations(tmp_path, capsys):
    """roll-analysis figure4: per-cell medians over seeds at the last evaluation, a
    Skew-Fit cell that stopped early paired with ROLL on the evaluations both have, a panel
    per task in the figure; a cell of another task or a missing file is refused by name."""
    import json

    from roll_jax.analysis import figure4

    def write(name, dist):  # dist[eval][seed]
        from roll_jax.training import run_dir

        path = tmp_path / f"{name}.csv"
        run_dir.append_rows(str(path), [dict(r, start_distance=0.1) for r in _rows(dist)])
        return str(path)

    roll = write("roll", [[0.10, 0.12, 0.11], [0.06, 0.05, 0.07], [0.03, 0.04, 0.02]])
    skew = write("skew", [[0.10, 0.12, 0.11], [0.09, 0.08, 0.10]])  # two evaluations only
    door = write("door", [[0.4, 0.4, 0.4], [0.2, 0.3, 0.1]])
    runs = _finished_runs(tmp_path, {"pp": 0.0})
    png, out = tmp_path / "f4.png", tmp_path / "f4.json"
    assert figure4.main(["--cell", "puck_push", "roll", roll, "--cell", "puck_push", "skewfit",
                         skew, "--cell", "door_open", "roll", door, "--png", str(png),
                         "--out", str(out)]) == 0
    assert png.stat().st_size > 10_000
    res = json.loads(out.read_text())["tasks"]
    assert res["puck_push"]["cells"]["roll"]["median"] == pytest.approx(0.03)
    assert res["puck_push"]["cells"]["roll"]["env_steps"] == 2000
    assert res["door_open"]["cells"]["roll"]["median"] == pytest.approx(0.2)
    pair = res["puck_push"]["paired_with_roll"]["skewfit"]
    assert pair["to_steps"] == 1000 and pair["n_evaluations"] == 2
    assert pair["paired_diff_mean"] == pytest.approx(np.mean([0, 0, 0, -0.03, -0.03, -0.03]))
    assert pair["evaluations_a_below_b"] == 1
    assert res["door_open"]["paired_with_roll"] == {}
    printed = capsys.readouterr().out  # the door in rad, the pushes in cm
    assert "median 0.200 rad (0.150 rad - 0.250 rad)" in printed
    assert "median 3.00 cm" in printed
    # a run directory is checked against the cell it is given as
    with pytest.raises(SystemExit):
        figure4.main(["--cell", "hurdle_top", "roll", runs[0], "--png", str(png)])
    assert "is a puck_push / roll run, not hurdle_top / roll" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        figure4.main(["--cell", "puck_push", "roll", str(tmp_path / "nope.csv"), "--png",
                      str(png)])
    assert "nope.csv: no such run directory or metrics.csv" in capsys.readouterr().err
