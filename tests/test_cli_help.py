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

def flags_without_help(parser):
    out = [a.option_strings[-1] for a in parser._actions if a.option_strings and not a.help]
    for a in parser._actions:  # and those of its subcommands
        if isinstance(a, argparse._SubParsersAction):
            for sub in a.choices.values():
                out += flags_without_help(sub)
    return out

def parse_args(self, *args, **kwargs):
    undocumented.extend(flags_without_help(self))
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


# The commands whose --help must not wait for JAX (the console script -> its module): all.
LIGHT = {"roll-train": "roll_jax.training.cli", "roll-evaluate": "roll_jax.analysis.evaluate",
         "roll-reproduce": "roll_jax.training.reproduce",
         "roll-segmentation": "roll_jax.segmentation.__main__",
         "roll-pretrain": "roll_jax.encoders.cli", "roll-analysis": "roll_jax.analysis.__main__",
         "roll-compare": "roll_jax.analysis.compare"}
ANALYSES = ("latent-vs-distance", "occlusion", "reward-probe", "diagnose", "compare",
            "policy-panel")


def test_console_scripts_point_at_mains():
    import importlib

    got = scripts()
    assert set(got) == set(LIGHT)
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


@pytest.mark.parametrize("cmd", ANALYSES)
def test_every_analysis_explains_every_flag_without_jax(cmd):
    out, _, report = probe("roll_jax.analysis.__main__", cmd, "--help")
    assert report == {"code": 0, "heavy": [], "undocumented": []}, report
    assert f"roll-analysis {cmd}" in out


def test_module_forms_answer_help_without_jax():
    """`python -m roll_jax.encoders.pretrain --help` runs the module itself: its command
    parses before the module's JAX imports."""
    code = ("import runpy, sys; sys.argv = ['pretrain', '--help']\n"
            "try:\n    runpy.run_module('roll_jax.encoders.pretrain', run_name='__main__')\n"
            "except SystemExit as e:\n    assert e.code == 0, e.code\n"
            f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "usage: roll-pretrain" in proc.stdout and proc.stdout.splitlines()[-1] == "[]"


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
    from configs.encoders import ALGOS as PRETRAIN_ALGOS
    from configs.encoders import HURDLE_TASKS

    out, _, _ = probe("roll_jax.encoders.cli", "--help")
    flat = " ".join(out.split())
    assert f"one of {', '.join(TASKS)}" in flat
    assert f"one of {', '.join(PRETRAIN_ALGOS)} (default roll)" in flat
    assert f"one of {', '.join(PRESETS)} (configs/presets.py; default cpu)" in flat
    for cmd, tasks in (("latent-vs-distance", TASKS), ("occlusion", HURDLE_TASKS)):
        out, _, _ = probe("roll_jax.analysis.__main__", cmd, "--help")
        flat = " ".join(out.split())
        assert f"one of {', '.join(tasks)}" in flat and f"one of {', '.join(PRESETS)}" in flat
        assert "--ckpt DIR" in flat and "--run RUN" in flat


def test_the_default_preset_is_cpu(train_cli, tmp_path):
    from roll_jax.training import reproduce
    from roll_jax.segmentation import __main__ as seg_cli

    a, cfg, out = train_cli.parse_args(["--print-config"])
    assert a.preset == cfg.preset == "cpu" and out == os.path.join("runs", "puck_push_roll_cpu")
    assert reproduce.parse_args(["--out", str(tmp_path)])[0].preset == "cpu"
    assert seg_cli.parse_args(["--task", "puck_push", "--out", str(tmp_path)]).preset == "cpu"
    from roll_jax.encoders import cli as pretrain_cli

    assert pretrain_cli.make_parser().parse_args(
        ["--task", "puck_push", "--out", str(tmp_path)]).preset == "cpu"


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


def test_analyses_read_a_run_or_a_pretraining_directory_and_never_guess_its_preset(
        tmp_path, capsys):
    """A pretraining directory says its task and preset in pretrain.json, a run in its
    config.json; a directory that says neither is refused (it once fell back to the paper
    preset, whose encoder sizes are not the cpu preset's), unless --preset is given."""
    from roll_jax.analysis import __main__ as analysis
    from roll_jax.analysis import checkpoints
    from roll_jax.training import run_dir

    bare = tmp_path / "bare"
    bare.mkdir()
    with pytest.raises(ValueError, match="no pretrain.json .* nor config.json .* give --preset"):
        checkpoints.checkpoint_preset(str(bare), "puck_push")
    assert checkpoints.checkpoint_config(str(bare), "puck_push", "cpu").preset == "cpu"
    for argv, msg in (
            (["latent-vs-distance", "--ckpt", str(bare)], "give --task"),
            (["latent-vs-distance", "--ckpt", str(bare), "--task", "puck_push"],
             "give --preset"),
            (["occlusion", "--ckpt", str(bare), "--task", "puck_push"], "unknown --task")):
        with pytest.raises(SystemExit) as e:
            analysis.main(argv)
        assert msg in str(e.value) + capsys.readouterr().err, argv
    # A run directory: its config and the inputs it trained with.
    run = tmp_path / "run"
    run.mkdir()
    cfg = build_config("hurdle_top", "roll", "smoke", overrides=["sac.batch_size=32"])
    run_dir.write_config(str(run), cfg)
    run_dir.write_inputs(str(run), None, str(tmp_path / "enc"), 0)
    assert checkpoints.checkpoint_config(str(run)) == cfg
    assert checkpoints.checkpoint_task(str(run)) == "hurdle_top"
    assert checkpoints.checkpoint_paths(str(run)) == (str(run / "segmentation"),
                                                      str(tmp_path / "enc"))
    with pytest.raises(ValueError, match="trained task 'hurdle_top', not 'puck_push'"):
        checkpoints.checkpoint_config(str(run), "puck_push")
    with pytest.raises(ValueError, match="preset 'smoke', not 'paper'"):
        checkpoints.checkpoint_preset(str(run), "hurdle_top", "paper")
    for argv, msg in (
            (["occlusion", "--run", str(run)], "--run needs --out"),
            (["occlusion", "--run", str(run), "--out", str(run / "a")], "inside the run"),
            (["occlusion", "--run", str(bare), "--out", str(tmp_path / "a")],
             "not a train.py run directory"),
            (["occlusion", "--run", str(run), "--ckpt", str(bare)], "not allowed with")):
        with pytest.raises(SystemExit):
            analysis.main(argv)
        assert msg in capsys.readouterr().err, argv
