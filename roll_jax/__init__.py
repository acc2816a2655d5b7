"""ROLL (Wang et al., CoRL 2020) end to end in JAX.

The packages follow the data flow: envs_mjx simulates and renders (outside this package) ->
`segmentation` masks the object -> `encoders` encode (scene-VAE, object-VAE, LSTM; goal
encoding; pretraining) -> `agents` act and learn (SAC, replay with HER, Skew-Fit) ->
`training` runs it (the compiled chunk, its driver, the command, the grid) -> `analysis`
measures it (evaluation, Figure 5, occlusion, reward probe, comparisons). `common` holds what
they share (convolutions, checkpoint folders).

The main entry points, imported on first use (`import roll_jax` loads no JAX):

    cfg = roll_jax.build_config("puck_push", "roll", "cpu", seeds=2)   # configs/
    rows = roll_jax.run(cfg, "runs/x")          # train: segmentation, pretraining, chunks
    run = roll_jax.load_run("runs/x")           # a run's latest checkpoint
    res = roll_jax.evaluate(run, None, n_goals=8)   # its policy on sampled goals
"""

from roll_jax.common.lazy import lazy_api

__all__, __getattr__, __dir__ = lazy_api(__name__, {
    "configs.train": ("build_config", "make_config"),
    ".training.driver": ("run",),
    ".training.loop": ("make_chunk", "compile_chunk"),
    ".training.state": ("TrainState",),
    ".encoders.goal_encoding": ("goal_encoder",),
    ".encoders.pretrain": ("pretrain",),
    ".analysis.evaluation": ("load_run", "evaluate"),
})
