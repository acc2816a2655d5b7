"""train.py (the command line): flags reach the TrainConfig; bad values fail in argparse."""

import os

import pytest


@pytest.mark.parametrize("algo", ["roll", "skewfit"])
def test_n_envs_reaches_the_train_config(train_cli, tmp_path, capsys, algo):
    out = str(tmp_path / "run")
    _, default, _ = train_cli.parse_args(["--algo", algo, "--devices", "1", "--out", out])
    _, cfg, _ = train_cli.parse_args(["--algo", algo, "--n-envs", "5", "--devices", "1",
                                      "--out", out])
    assert default.n_envs == 10 and cfg.n_envs == 5
    assert cfg.epoch_env_steps == default.epoch_env_steps  # only n_envs changed
    # 500 env steps per chunk is not whole episodes of 3 envs x 50 steps: argparse says so.
    with pytest.raises(SystemExit):
        train_cli.parse_args(["--algo", algo, "--n-envs", "3", "--devices", "1", "--out", out])
    err = capsys.readouterr().err
    assert "--n-envs 3: " in err and "multiple of n_envs * horizon = 3 * 50" in err
    with pytest.raises(SystemExit):
        train_cli.parse_args(["--algo", algo, "--n-envs", "0", "--devices", "1", "--out", out])
    assert "--n-envs 0: TrainConfig.n_envs must be positive, got 0" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        train_cli.parse_args(["--algo", algo, "--n-envs", "5", "--set", "n_envs=2", "--out", out])
    assert "both set n_envs" in capsys.readouterr().err
    assert not os.path.exists(out)
