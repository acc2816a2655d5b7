"""The commands explain themselves before loading JAX: --help lists the names from configs/,
--print-config prints the resolved config, --set mistakes name the nearest field or the
expected type, and the grid takes or refuses each algorithm before anything runs. Nothing
here compiles; the --help checks run in fresh processes, so they see what a user's
command imports."""

import dataclasses
import json
import os
import subprocess
import sys
import tomllib

import pytest

from configs.presets import PRESETS
from configs.train import ALGOS, TASKS, build_config

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
HEAVY = ("jax", "jaxlib", "mujoco", "flax", "optax", "orbax")

# Runs MODULE's main(ARGV) as a console script does (`from MODULE import main`) and prints,
# last, a JSON line: the exit code, the heavy modules imported, and the flags of every parser
# built that have no help text.
PROBE = """
import argparse, json, sys

undocumented = []
_parse = argparse.ArgumentParser.parse_args

def parse_args(self, *args, **kwargs):
    undocumented.extend(a.option_strings[-1] for a in self._actions
                        if a.option_strings and not a.help)
    return _parse(self, *args, **kwargs)

argparse.ArgumentParser.parse_args = parse_args
main = __import__(sys.argv[1], fromlist=["main"]).main
try:
    code = main(sys.argv[2:])
except SystemExit as e:
    code = e.code
sys.stdout.flush()
heavy = sorted(m for m in %r if m in sys.modules)
print("\\n" + json.dumps({"code": code, "heavy": heavy, "undocumented": undocumented}))
""" % (HEAVY,)


def probe(module: str, *argv: str) -> tuple[str, str, dict]:
    """(stdout before the probe's line, stderr, the probe's report) of MODULE's main(ARGV)."""
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    proc = subprocess.run([sys.executable, "-c", PROBE, module, *argv], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    out, _, last = proc.stdout.rstrip().rpartition("\n")
    return out, proc.stderr, json.loads(last)


def scripts() -> dict[str, str]:
    with open(os.path.join(ROOT, "pyproject.toml"), "rb") as f:
        return tomllib.load(f)["project"]["scripts"]


# The commands whose --help must not wait for JAX (the console script -> its module).
LIGHT = {"roll-train": "roll_jax.training.cli", "roll-evaluate": "roll_jax.analysis.evaluate",
         "roll-reproduce": "roll_jax.training.reproduce",
         "roll-segmentation": "roll_jax.segmentation.__main__"}


def test_console_scripts_point_at_mains():
    import importlib

    got = scripts()
    assert set(got) == {"roll-train", "roll-evaluate", "roll-reproduce", "roll-pretrain",
                        "roll-analysis", "roll-segmentation"}
    for name, target in got.items():
        module, _, func = target.partition(":")
        assert callable(getattr(importlib.import_module(module), func)), name
        if name in LIGHT:
            assert module == LIGHT[name]


@pytest.mark.parametrize("script", sorted(LIGHT))
def test_help_explains_every_flag_without_jax(script):
    out, _, report = probe(LIGHT[script], "--help")
    assert report == {"code": 0, "heavy": [], "undocumented": []}, report
    assert "usage:" in out and "--help" in out


def test_train_help_lists_the_tasks_algorithms_and_presets():
    out, _, _ = probe("roll_jax.training.cli", "--help")
    flat = " ".join(out.split())  # argparse wraps the help lines
    assert f"one of {', '.join(TASKS)} (default puck_push)" in flat
    assert f"one of {', '.join((*ALGOS, 'random'))} (default roll)" in flat
    assert f"one of {', '.join(PRESETS)} (configs/presets.py; default cpu)" in flat
    out, _, _ = probe("roll_jax.training.reproduce", "--help")
    flat = " ".join(out.split())
    assert f"some of {', '.join(TASKS)}" in flat and f"some of {', '.join(ALGOS)}" in flat
    assert f"one of {', '.join(PRESETS)}" in flat


def test_the_default_preset_is_cpu(train_cli, tmp_path):
    from roll_jax.training import reproduce
    from roll_jax.segmentation import __main__ as seg_cli

    a, cfg, out = train_cli.parse_args(["--print-config"])
    assert a.preset == cfg.preset == "cpu" and out == os.path.join("runs", "puck_push_roll_cpu")
    assert reproduce.parse_args(["--out", str(tmp_path)])[0].preset == "cpu"
    assert seg_cli.parse_args(["--task", "puck_push", "--out", str(tmp_path)]).preset == "cpu"


def test_print_config_prints_the_resolved_config_and_runs_nothing(tmp_path):
    run = tmp_path / "run"
    argv = ["--preset", "smoke", "--algo", "skewfit", "--seeds", "2", "--n-envs", "5", "--out",
            str(run), "--set", "total_env_steps=2000", "sac.batch_size=128", "--print-config"]
    out, _, report = probe("roll_jax.training.cli", *argv)
    assert report == {"code": 0, "heavy": [], "undocumented": []}, report
    printed = json.loads(out)
    expected = build_config("puck_push", "skewfit", "smoke", seeds=2,
                            overrides=["total_env_steps=2000", "sac.batch_size=128", "n_envs=5"])
    assert printed == json.loads(json.dumps(dataclasses.asdict(expected)))
    assert printed["sac"]["batch_size"] == 128 and printed["n_envs"] == 5
    assert not run.exists()  # nothing written
    # the same through the top-level train.py
    proc = subprocess.run([sys.executable, "train.py", *argv], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0 and json.loads(proc.stdout) == printed, proc.stderr
    # the random-policy viewer's config too
    out, _, report = probe("roll_jax.training.cli", "--algo", "random", "--print-config")
    assert report["code"] == 0 and json.loads(out)["n_envs"] == 8  # the cpu preset's rollout


def _error(train_cli, capsys, *argv) -> str:
    with pytest.raises(SystemExit) as e:
        train_cli.parse_args([*argv, "--print-config"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if "error:" in line]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_unknown_set_field_names_the_nearest_and_the_valid_ones(train_cli, capsys):
    msg = _error(train_cli, capsys, "--set", "total_env_step=20000")
    assert ("--set total_env_step: unknown field of TrainConfig; did you mean total_env_steps?"
            in msg)
    assert "Valid: task, algo, preset, horizon, total_env_steps, epoch_env_steps, n_envs" in msg
    msg = _error(train_cli, capsys, "--set", "sac.batchsize=128")
    assert "unknown field of SACConfig; did you mean sac.batch_size?" in msg
    assert "replay_size" in msg
    msg = _error(train_cli, capsys, "--set", "sca.batch_size=128")
    assert "unknown config group; did you mean sac? Valid: segmentation, scene_vae" in msg
    msg = _error(train_cli, capsys, "--set", "zzz=1")
    assert "--set zzz: unknown field of TrainConfig. Valid: task, " in msg  # nothing near


def test_wrong_set_type_names_field_value_and_type(train_cli, capsys):
    msg = _error(train_cli, capsys, "--set", "total_env_steps=lots")
    assert msg.endswith("--set total_env_steps: TrainConfig.total_env_steps takes int, "
                        "got 'lots' (str)")
    msg = _error(train_cli, capsys, "--set", "sac.hidden=(64, 1.5)")
    assert msg.endswith("--set sac.hidden: SACConfig.hidden takes tuple[int, ...], got (64, 1.5) "
                        "(tuple)")
    msg = _error(train_cli, capsys, "--set", "segmentation.detect_shadows=true")
    assert "takes bool, got 'true' (str) (Python literals: True, False)" in msg
    msg = _error(train_cli, capsys, "--set", "sac=(64, 64)")
    assert "sac is a group of fields (SACConfig); set one of them: --set sac.FIELD=VALUE" in msg
    msg = _error(train_cli, capsys, "--seeds", "2", "--set", "seeds=3")
    assert msg.endswith("--set seeds: given by the command's --seeds, not --set")


def test_reproduce_takes_every_algorithm_the_configs_name(tmp_path):
    """`--algos roll oracle --dry-run` once died with KeyError 'oracle'."""
    out = tmp_path / "grid"
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    proc = subprocess.run([sys.executable, "-m", "roll_jax.training.reproduce", "--algos", "roll", "oracle",
                           "--dry-run", "--out", str(out)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    planned = [line.split()[1:3] for line in proc.stdout.splitlines()]
    assert planned == [[t, v] for t in TASKS for v in ("roll", "oracle")]
    assert not out.exists()
    _, _, report = probe("roll_jax.training.reproduce", "--algos", *ALGOS, "--dry-run", "--out", str(out))
    assert report["code"] == 0 and report["heavy"] == []


def test_reproduce_runs_and_reports_an_oracle_cell(tmp_path):
    import csv

    from roll_jax.training import reproduce, run_dir

    calls = []

    def fake_run(cfg, out, resume=False, seed=0, **kw):
        calls.append((cfg.task, cfg.algo, out))
        os.makedirs(out, exist_ok=True)
        with open(os.path.join(out, "config.json"), "w") as f:
            json.dump(run_dir.config_json(cfg), f)
        with open(os.path.join(out, "metrics.csv"), "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=["env_steps", "seed", "final_distance"])
            w.writeheader()
            w.writerows({"env_steps": 1000, "seed": s, "final_distance": 0.02}
                        for s in range(cfg.seeds))
        with open(os.path.join(out, run_dir.COMPLETE_MARKER), "w") as f:
            f.write("{}")

    grid = tmp_path / "grid"
    assert reproduce.main(["--preset", "smoke", "--tasks", "puck_push", "--algos", "oracle",
                           "--out", str(grid)], run_fn=fake_run) == 0
    assert calls == [("puck_push", "oracle", str(grid / "runs" / "puck_push__oracle"))]
    assert "| puck_push | state oracle | 1000 | 2 |" in (grid / "results.md").read_text()
