"""Presets live in configs/presets.py: every CLI takes each of them, and they mean the same
thing everywhere (no module keeps a copy)."""

import json

import pytest

from configs import presets
from configs.segmentation import segmentation_config
from configs.train import TASKS, make_config


def test_every_preset_builds_every_task_and_algo():
    for name in presets.PRESETS:
        for task in TASKS:
            for algo in ("roll", "skewfit", "oracle"):
                cfg = make_config(task, algo, name)
                assert cfg.preset == name


def test_preset_values_reach_the_configs():
    cpu = presets.get("cpu")
    cfg = make_config("puck_push", "roll", "cpu")
    for group, fields in (("sac", cfg.sac), ("scene_vae", cfg.scene_vae),
                          ("object_vae", cfg.object_vae), ("lstm", cfg.lstm),
                          ("segmentation", cfg.segmentation)):
        for k, v in cpu.for_task(group, "puck_push").items():
            if k == "matching_coef_factor":  # scales the task's Table 2 value
                assert fields.matching_coef == v * 400.0
                continue
            assert getattr(fields, k) == v, (group, k)
    for k, v in cpu.for_task("train", "puck_push").items():
        assert getattr(cfg, k) == v, k
    # The paper preset overrides nothing: the tagged defaults.
    paper = make_config("puck_push", "roll", "paper")
    assert paper.sac.hidden == (400, 300) and paper.total_env_steps == 300_000
    assert segmentation_config("puck_push", "cpu").n_frames == cpu["segmentation"]["n_frames"]
    # The cpu preset's smaller VAE batches keep the paper's per-image scaling beta / B with
    # the paper's B; the object-VAE's beta itself is the preset's (5, not Table 3's 20).
    assert paper.object_vae.effective_beta == 20.0 / 128
    assert cfg.object_vae.effective_beta == cpu["object_vae"]["beta"] / 128
    assert cfg.scene_vae.effective_beta == paper.scene_vae.effective_beta == 20.0 / 64


def test_per_task_values_resolve_per_task_and_name_a_missing_task():
    pre = presets.Preset("x", "", {"object_vae": {
        "beta": 3.0, "pretrain_occluded_fraction": presets.PerTask({"puck_push": 0.0,
                                                                    "hurdle_top": 0.3})}})
    assert pre.for_task("object_vae", "hurdle_top") == {"beta": 3.0,
                                                        "pretrain_occluded_fraction": 0.3}
    assert pre.for_task("object_vae", "puck_push")["pretrain_occluded_fraction"] == 0.0
    with pytest.raises(ValueError, match="object_vae.pretrain_occluded_fraction.*'door_open'"):
        pre.for_task("object_vae", "door_open")
    # TASK_DEFAULT leaves the task's own value in place
    keep = presets.Preset("y", "", {"train": {"scene_pretrain_data": presets.PerTask(
        {t: "placements" if t == "puck_push" else presets.TASK_DEFAULT for t in TASKS})}})
    assert keep.for_task("train", "puck_push") == {"scene_pretrain_data": "placements"}
    assert keep.for_task("train", "hurdle_top") == {}
    # The presets' own per-task values reach each task's config.
    for task in ("hurdle_top", "hurdle_bottom"):
        assert make_config(task, "roll", "cpu").object_vae.pretrain_occluded_fraction == 0.3
    assert make_config("puck_push", "roll", "cpu").object_vae.pretrain_occluded_fraction == 0.0
    for name in presets.PRESETS:
        for group in ("object_vae", "scene_vae", "lstm", "sac"):
            for k, v in presets.get(name)[group].items():
                if isinstance(v, presets.PerTask):
                    for task in TASKS:
                        cfg = make_config(task, "roll", name)
                        assert getattr(getattr(cfg, group), k) == v.get(task, k), (task, k)


def test_unknown_preset_names_the_known_ones():
    with pytest.raises(ValueError, match="unknown preset 'gpu'; expected one of smoke, cpu, paper"):
        presets.get("gpu")
    with pytest.raises(ValueError, match="unknown group"):
        presets.Preset("x", "", {"trian": {}})


def test_every_cli_takes_preset_cpu_and_lists_the_presets(train_cli, tmp_path, capsys):
    from roll_jax.analysis import __main__ as analysis_cli
    from roll_jax.encoders import pretrain
    from roll_jax.training import reproduce
    from roll_jax.segmentation import __main__ as seg_cli

    _, cfg, _ = train_cli.parse_args(["--preset", "cpu", "--devices", "1",
                                      "--out", str(tmp_path / "r")])
    assert cfg.preset == "cpu"
    _, rollout, _ = train_cli.parse_args(["--algo", "random", "--preset", "cpu",
                                          "--out", str(tmp_path / "v")])
    assert rollout.n_envs == presets.get("cpu")["rollout"]["n_envs"]
    reproduce.main(["--preset", "cpu", "--tasks", "puck_push", "--out", str(tmp_path / "g"),
                    "--dry-run"])
    for main, argv in ((train_cli.parse_args, []), (pretrain.main, ["--task", "puck_push",
                                                                    "--out", str(tmp_path)]),
                       (reproduce.main, ["--out", str(tmp_path)]),
                       (seg_cli.main, ["--task", "puck_push", "--out", str(tmp_path)]),
                       (analysis_cli.main, ["latent-vs-distance", "--task", "puck_push",
                                        "--ckpt", str(tmp_path)])):
        capsys.readouterr()
        with pytest.raises(SystemExit):
            main(argv + ["--preset", "gpu"])
        err = capsys.readouterr().err
        assert "gpu" in err and all(name in err for name in presets.PRESETS), (main, err)


def test_cpu_preset_trains_only_skewfits_scene_vae_online():
    assert make_config("puck_push", "roll", "cpu").vae_schedule == "none"
    assert make_config("puck_push", "skewfit", "cpu").vae_schedule == "custom_schedule_2"
    assert make_config("door_open", "skewfit", "cpu").vae_schedule == "custom_schedule"
    assert make_config("puck_push", "roll", "cpu", vae_schedule="smoke").vae_schedule == "smoke"


# The reference code's pretraining data (ROLL/launch_files/launch_ROLL_*.py and their dataset
# generators): scene-VAE images, and the object-VAE / LSTM images' goal share and hand.
REFERENCE_PRETRAIN = {
    "puck_push": ("goals", 1.0, "random"),  # set-to-goal images
    "hurdle_bottom": ("region", 0.0, "away"),  # _generate_sawyerhurdlemiddle_dataset
    "hurdle_top": ("region", 0.0, "away"),  # _generate_sawyerhurdle_dataset
    "door_open": ("goals", 1.0, "random"),  # door_original_dataset.npy
    "pickup": ("goals", 1.0, "random"),  # pickup-original-dataset.npy
}


def test_every_task_pretrains_on_the_reference_data():
    for task, want in REFERENCE_PRETRAIN.items():
        for algo, preset in (("roll", "paper"), ("roll", "cpu"), ("skewfit", "cpu")):
            cfg = make_config(task, algo, preset)
            got = (cfg.scene_pretrain_data, cfg.object_vae.pretrain_goal_share,
                   cfg.object_vae.pretrain_hand)
            expect = want
            if (task, algo, preset) == ("door_open", "roll", "cpu"):
                # the cpu preset's frozen scene-VAE sees the hand off the handle on the door
                expect = ("placements",) + want[1:]
            assert got == expect, (task, algo, preset)


def test_pretrain_overrides_reach_the_analysis_config(tmp_path):
    from roll_jax.analysis import checkpoints
    from roll_jax.encoders import pretrain

    with pytest.raises(SystemExit, match="occlusion_shap"):
        pretrain.main(["--task", "puck_push", "--preset", "cpu", "--out", str(tmp_path),
                       "--set", "object_vae.occlusion_shap=edge"])
    with open(tmp_path / "pretrain.json", "w") as f:
        json.dump({"task": "hurdle_top", "preset": "cpu",
                   "overrides": ["object_vae.occlusion_shape=edge",
                                 "object_vae.matching_coef=0.0"]}, f)
    cfg = checkpoints.checkpoint_config(str(tmp_path), "hurdle_top")
    assert cfg.preset == "cpu"
    assert cfg.object_vae.occlusion_shape == "edge" and cfg.object_vae.matching_coef == 0.0
    with pytest.raises(ValueError, match="hurdle_top"):
        checkpoints.checkpoint_config(str(tmp_path), "puck_push")
