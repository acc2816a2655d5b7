"""ROLL training end to end on CPU: a tiny config, 2 seeds, 2 chunks; resume; trace count;
seed axis; config validation."""

import csv
import json
import os

import jax
import numpy as np
import pytest

from configs.sac import SACConfig
from configs.segmentation import segmentation_config
from configs.train import make_config
from roll_jax.training import driver, loop, run_dir, sharding
from roll_jax.training.state import plan_chunk


def tiny(**kw):
    seg = segmentation_config("puck_push", "smoke", n_frames=300, unet_epochs=2, eval_states=8)
    return make_config("puck_push", "roll", "smoke", **{
        "seeds": 2, "total_env_steps": 1000, "n_eval_goals": 2, "segmentation": seg, **kw})


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("train")
    cfg = tiny()
    full = str(base / "full")
    loop.TRACE_COUNTS.clear()
    rows = driver.run(cfg, full, progress=False)
    traces = loop.TRACE_COUNTS["chunk"]
    shared = {"seg_ckpt": os.path.join(full, "segmentation"),
                  "enc_ckpt": os.path.join(full, "encoders"), "progress": False}
    part = str(base / "part")
    driver.run(cfg, part, stop_after_epochs=1, **shared)
    resumed = driver.run(cfg, part, resume=True, **shared)
    return cfg, full, rows, part, resumed, traces


def _csv(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def test_writes_all_outputs(runs):
    _cfg, full, _rows, *_ = runs
    for name in ("config.json", "metrics.csv", "plots/learning_curve.png",
                 "videos/eval_00000000.gif", "videos/eval_00000500.gif",
                 "videos/eval_00001000.gif",
                 "segmentation/meta.json", "encoders/meta.json"):
        assert os.path.exists(os.path.join(full, name)), name
    assert sorted(os.listdir(os.path.join(full, "ckpt")))  # orbax steps
    with open(os.path.join(full, "timings.json")) as f:
        times = json.load(f)
    assert [len(times["wall_s"][k]) for k in ("segmentation", "pretrain", "init", "chunks",
                                               "final_eval")] == [1, 1, 1, 2, 1]
    assert times["cpu_s"]["chunks"][0] > 0 and times["total_wall_s"] >= sum(
        sum(v) for v in times["wall_s"].values())
    table = _csv(os.path.join(full, "metrics.csv"))
    # One row per seed per evaluation: the initial policy, after each of the 2 chunks.
    assert [int(r["env_steps"]) for r in table] == [0, 0, 500, 500, 1000, 1000]
    for r in table:
        assert np.isfinite(float(r["final_distance"])) and 0 <= float(r["final_distance"]) < 1
        for k in ("q_loss", "alpha", "vae_loss", "lstm_loss"):
            assert np.isfinite(float(r[k])), k
    # Losses are those of the chunk that ended at env_steps: none before any training; then
    # learning started (learning_starts 200 < 500 steps), so not the zero filler.
    assert all(float(r["q_loss"]) == 0 for r in table[:2])
    assert all(float(r["q_loss"]) > 0 for r in table[2:])


def test_every_evaluation_of_a_seed_chases_the_same_goals(runs):
    """The test envs' starts and goals are fixed per seed (state.eval_key): the start-to-goal
    distance is the same in all 3 evaluations of a seed, differs between seeds, and the
    policy's final distances are measured on them."""
    _, _, rows, *_ = runs
    start = {s: [r["start_distance"] for r in rows if r["seed"] == s] for s in (0, 1)}
    for s in (0, 1):
        assert len(start[s]) == 3 and start[s][0] > 0.01
        np.testing.assert_allclose(start[s], start[s][0], rtol=1e-6)
    assert abs(start[0][0] - start[1][0]) > 1e-4


def test_chunk_traced_once(runs):
    *_, traces = runs
    assert traces == 1


def test_seeds_differ(runs):
    _, _, rows, *_ = runs
    by_seed = {s: [r["q_loss"] for r in rows if r["seed"] == s] for s in (0, 1)}
    assert by_seed[0] != by_seed[1]


def test_resume_continues_exactly(runs):
    _, _, rows, _, resumed, _ = runs
    assert len(resumed) == len(rows)
    for a, b in zip(rows, resumed):
        assert a.keys() == b.keys()
        for k in a:
            np.testing.assert_allclose(a[k], b[k], rtol=0, atol=0, err_msg=k)


def test_resume_refuses_other_config(runs, tmp_path):
    _, full, *_ = runs
    with pytest.raises(ValueError, match="differs from the command line in 'n_eval_goals'"):
        run_dir.check_resume(full, tiny(n_eval_goals=3))
    with pytest.raises(ValueError, match="no run to resume"):
        run_dir.check_resume(str(tmp_path), tiny())
    # The base seed is a run's input too (inputs.json); unknown (None) is not checked.
    run_dir.check_resume(full, tiny(), seed=0)
    run_dir.check_resume(full, tiny(), seed=None)
    with pytest.raises(ValueError, match="was trained with --seed 0, the command line gives "
                                         "--seed 3"):
        run_dir.check_resume(full, tiny(), seed=3)


def test_resume_accepts_a_run_written_before_a_field_existed(tmp_path):
    import dataclasses

    cfg = tiny()
    saved = run_dir.config_json(cfg)
    del saved["object_vae"]["occlusion_shape"]  # a run written before the field was added
    with open(tmp_path / "config.json", "w") as f:
        json.dump(saved, f)
    run_dir.check_resume(str(tmp_path), cfg)  # the default is the old behaviour: same run
    run_dir.check_resume(str(tmp_path), cfg, seed=5)  # no inputs.json: its seed is unknown
    other = dataclasses.replace(cfg, object_vae=dataclasses.replace(cfg.object_vae,
                                                                    occlusion_shape="edge"))
    with pytest.raises(ValueError, match="differs from the command line in 'object_vae'"):
        run_dir.check_resume(str(tmp_path), other)

def test_equal_keys_give_equal_seeds(runs):
    """Two seeds with the same key stay identical through a chunk (no cross-seed leakage
    through the seed axis)."""
    cfg, full, *_ = runs
    import envs_mjx

    env = envs_mjx.make(cfg.task)
    frozen, pre = driver.setup(cfg, env, jax.random.PRNGKey(0), full, progress=False)
    key = jax.random.PRNGKey(7)
    # Built as driver.init_seeds builds it, so the chunk's input types are the run's and its
    # compiled program comes from the persistent cache instead of a second compile.
    state = driver.init_states(cfg, env, jax.numpy.stack([key, key]), pre)
    chunk = loop.compile_chunk(cfg, env, 1, sharding.resolve_seed_batch("auto", cfg.seeds))
    state, m = chunk(state, frozen, plan_chunk(cfg, 0))
    for leaf in jax.tree.leaves((state.sac, m)):
        np.testing.assert_array_equal(np.asarray(leaf[0]), np.asarray(leaf[1]))


def test_reproduce_trains_a_real_cell(runs, tmp_path):
    """The grid's real path (no fake run function): the fixture's tiny config as a one-cell
    grid through `reproduce.main`. Its segmentation and pre-training go through the grid's
    shared dirs, and it gives the fixture's run's metrics exactly (same seed)."""
    from roll_jax.training import reproduce

    _cfg, _full, rows, *_ = runs
    out = tmp_path / "grid"
    assert reproduce.main(["--preset", "smoke", "--out", str(out), "--tasks", "puck_push",
                           "--algos", "roll", "--seeds", "2", "--set", "n_eval_goals=2",
                           "segmentation.unet_epochs=2", "segmentation.eval_states=8"]) == 0
    for name in ("figure4.png", "results.md", "results.csv", "runs/puck_push__roll/complete.json",
                 "runs/puck_push__roll/timings.json", "segmentation/puck_push/meta.json"):
        assert (out / name).exists(), name
    assert len(list((out / "pretrain").glob("*.npz"))) == 5  # scene/object data, 2 VAEs, LSTM
    grid = reproduce.read_metrics(str(out / "runs" / "puck_push__roll" / "metrics.csv"))
    assert [(r["env_steps"], r["seed"], r["final_distance"], r["q_loss"]) for r in grid] == [
        (r["env_steps"], r["seed"], r["final_distance"], r["q_loss"]) for r in rows]


@pytest.mark.parametrize("kw, msg", [
    ({"task": "nope"}, "unknown task 'nope'"),
    ({"algo": "ppo"}, "unknown algo 'ppo'"),
    ({"preset": "huge"}, "unknown preset 'huge'"),
    ({"seeds": 0}, "seeds must be positive, got 0"),
    ({"n_envs": 3}, "must be a multiple of n_envs \\* horizon"),
    ({"algo": "skewfit", "use_lstm": False}, "--no-lstm ablate ROLL; they contradict --algo skewfit"),
    ({"use_lstm": False, "use_object_vae": False}, "--no-lstm and --no-object-vae together"),
    ({"algo": "oracle", "matching_loss": False}, "contradict --algo oracle"),
    ({"total_env_steps": 5000}, "learning_starts=10000 is not below total_env_steps=5000"),
    ({"eval_every_epochs": 50}, "eval_every_epochs=50 is longer than the run .* 40 epochs"),
    ({"sac": SACConfig(replay_size=400)}, "replay_size=400 is smaller than one chunk "
                                          "\\(epoch_env_steps=500\\)"),
    ({"reward_norm": "l1"}, "unknown reward_norm 'l1'"),
])
def test_config_rejects_bad_values(kw, msg):
    from configs.train import TrainConfig

    base = {"task": "puck_push", "algo": "roll", "preset": "smoke", "horizon": 50,
            "total_env_steps": 20000}
    with pytest.raises(ValueError, match=msg):
        TrainConfig(**{**base, **kw})


def test_read_rows_keeps_int_columns(tmp_path):
    # metrics.csv as run() writes it: int env_steps and seed, float metrics; 2 seeds x 3 evals.
    path = str(tmp_path / "metrics.csv")
    written = [{"env_steps": e, "seed": s, "final_distance": 0.5 + e / 1000 + s, "q_loss": 0.0}
               for e in (0, 500, 1000) for s in (0, 1)]

    def write(rows):
        with open(path, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        with open(path) as f:
            return f.read()

    text = write(written)
    kept = run_dir.read_rows(path, 1000)
    assert kept == written[:4]  # before the checkpoint at 1000 env steps
    assert all(type(r["env_steps"]) is int and type(r["seed"]) is int for r in kept)
    assert all(type(r["final_distance"]) is float for r in kept)
    assert run_dir.read_rows(path, 1000, final=True) == written  # a finished run: the last eval too
    # Rewriting the restored rows gives the same file (no "500.0" among "1000").
    assert write(run_dir.read_rows(path, 1000, final=True)) == text
    assert "500.0" not in text
    # A file an earlier resume wrote with float env steps reads back as ints.
    legacy = text.replace("\n500,", "\n500.0,").replace("\n0,", "\n0.0,")
    assert "\n500.0," in legacy and "\n0.0," in legacy
    with open(path, "w", newline="") as f:
        f.write(legacy)
    assert run_dir.read_rows(path, 1000, final=True) == written


def test_check_finite_stops_on_a_nan_gradient_with_finite_losses():
    ok = {"q_loss": np.array([0.1, 0.2]), "policy_loss": np.array([1.0, 1.0]),
          "finite": np.array([1.0, 1.0])}
    driver.check_finite(ok, 500, 0, "/ckpt")
    bad_grad = {**ok, "finite": np.array([1.0, 0.999])}  # one update of seed 1 out of 1000
    with pytest.raises(driver.TrainingDiverged, match="SAC gradient was NaN/inf for seed 1 at "
                                                     "env step 500 .* /ckpt is kept"):
        driver.check_finite(bad_grad, 500, 0, "/ckpt")
    with pytest.raises(driver.TrainingDiverged, match="q_loss is nan for seed 0 at env step 1000"):
        driver.check_finite({**ok, "q_loss": np.array([np.nan, 0.1])}, 1000, 1, "/ckpt")


# --- python -m roll_jax.analysis.evaluate on the run's checkpoint ---------------------------------------

def _tree_snapshot(root):
    return sorted((os.path.relpath(os.path.join(d, f), root), os.path.getmtime(os.path.join(d, f)),
                   os.path.getsize(os.path.join(d, f)))
                  for d, _, files in os.walk(root) for f in files)


def test_evaluate_writes_outputs_and_is_deterministic(runs, tmp_path):
    from PIL import Image

    from roll_jax.analysis import evaluate, evaluation

    _cfg, full, *_ = runs
    before = _tree_snapshot(full)
    # one goal at a time throughout: every call below runs the same compiled rollout
    argv = ["--run", full, "--n-goals", "1", "--out", str(tmp_path / "sampled")]
    assert evaluate.main(argv) == 0
    summary = json.loads((tmp_path / "sampled" / "evaluation.json").read_text())
    assert summary["checkpoint_epoch"] == 2 and summary["seeds"] == 2
    for name in ("evaluation.json", "goal_00.png", "goal_00_seed1.gif", "final_00_seed0.png"):
        assert os.path.exists(tmp_path / "sampled" / name), name
    dist = np.array([g["final_distance"] for g in summary["goals"]])
    assert dist.shape == (1, 2) and np.all(np.isfinite(dist)) and np.all(dist >= 0)
    # A user's goal image of another size: resized (noted), and the same image twice gives
    # the same distances.
    big = Image.open(tmp_path / "sampled" / "goal_00.png").resize((96, 96))
    big.save(tmp_path / "goal.png")
    loaded = evaluation.load_run(full)
    img, note = evaluation.read_goal_image(str(tmp_path / "goal.png"))
    assert img.shape == (48, 48, 3) and "96x96" in note
    first = evaluation.evaluate(loaded, [img], 1)
    again = evaluation.evaluate(loaded, [img], 1)
    np.testing.assert_array_equal(first["latent_distance"], again["latent_distance"])
    assert "final_distance" not in first  # no goal state behind a user's image
    assert _tree_snapshot(full) == before  # nothing in the run directory was written


def test_evaluate_refuses_bad_input(runs, tmp_path, capsys):
    import shutil

    from PIL import Image

    from roll_jax.analysis import evaluate, evaluation

    _cfg, full, *_ = runs
    Image.new("L", (48, 48)).save(tmp_path / "gray.png")
    Image.new("RGBA", (48, 48)).save(tmp_path / "rgba.png")
    (tmp_path / "text.png").write_text("not an image")
    for name, msg in (("gray.png", "1 channel(s)"), ("rgba.png", "4 channel(s)"),
                      ("text.png", "not an image")):
        with pytest.raises(SystemExit):
            evaluate.main(["--run", full, "--goal-image", str(tmp_path / name),
                           "--out", str(tmp_path / "o")])
        assert msg in capsys.readouterr().err, name
    bare = tmp_path / "bare"
    bare.mkdir()
    with pytest.raises(FileNotFoundError, match="no config.json"):
        evaluation.load_run(str(bare))
    shutil.copy(os.path.join(full, "config.json"), bare / "config.json")
    with pytest.raises(FileNotFoundError, match="no checkpoint"):
        evaluation.load_run(str(bare))
    other = tmp_path / "other_enc"
    shutil.copytree(os.path.join(full, "encoders"), other)
    meta = json.loads((other / "meta.json").read_text())
    (other / "meta.json").write_text(json.dumps({**meta, "task": "hurdle_top"}))
    with pytest.raises(ValueError, match="task='hurdle_top'"):
        evaluation.load_run(full, enc_ckpt=str(other))
    with pytest.raises(SystemExit):
        evaluate.main(["--run", full, "--out", os.path.join(full, "eval")])
    assert "inside the run directory" in capsys.readouterr().err


def test_run_records_its_inputs(runs):
    _cfg, full, _rows, part, *_ = runs
    with open(os.path.join(part, run_dir.INPUTS)) as f:
        inputs = json.load(f)
    assert inputs == {"seg_ckpt": os.path.join(full, "segmentation"),
                      "enc_ckpt": os.path.join(full, "encoders"), "seed": 0}
    with pytest.raises(FileNotFoundError, match="enc_ckpt"):
        driver.setup(_cfg, None, jax.random.PRNGKey(0), part, enc_ckpt=os.path.join(part, "nope"))
    with pytest.raises(FileNotFoundError, match="seg_ckpt"):
        driver.check_given(seg_ckpt=os.path.join(part, "nope"))


def test_reward_encoder_correlations_rank_what_the_encoder_sees():
    from roll_jax.analysis import reward_probe

    rng = np.random.default_rng(0)
    d_obj, d_hand = rng.uniform(0, 0.2, 64), rng.uniform(0, 0.2, 64)
    a = np.zeros((64, 48, 48, 3), np.uint8)
    b = np.broadcast_to((d_obj * 1000).astype(np.uint8)[:, None, None, None], a.shape).copy()
    r = reward_probe.correlations(lambda x: x.reshape(x.shape[0], -1)[:, :1].astype(
        np.float32), (a, b, d_obj, d_hand))
    assert r["spearman_object"] > 0.99 and abs(r["spearman_hand"]) < 0.3


def test_reward_probe_command(runs, tmp_path):
    from roll_jax.analysis import reward_probe

    _cfg, full, *_ = runs
    summary = reward_probe.main(["--run", full, "--n", "16", "--out", str(tmp_path)])
    (row,) = summary["runs"]
    assert row["label"] == "roll" and -1 <= row["spearman_object"] <= 1
    assert np.isfinite(row["spearman_hand"])
    assert os.path.exists(tmp_path / "reward_probe.png")


def test_config_json_round_trip():
    from configs.train import config_from_json

    for cfg in (tiny(), make_config("hurdle_top", "skewfit", "cpu"),
                make_config("door_open", "roll", "paper", use_lstm=False)):
        assert config_from_json(run_dir.config_json(cfg)) == cfg
    with pytest.raises(ValueError, match="unknown TrainConfig field"):
        config_from_json({**run_dir.config_json(tiny()), "bogus": 1})
