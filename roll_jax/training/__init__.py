"""Run it: one compiled training chunk per epoch and the Python around it.

    loop       the chunk: collect, store, learn; make / compile it
    state      TrainState, a fresh one, ChunkPlan (what Python decides per chunk)
    collect    one episode of all envs (and the test envs beside them)
    online     online scene-VAE and LSTM training and the buffer's latent refreshes
    driver     segmentation -> pretraining -> chunks; logs, checkpoints, plots (`run`)
    cli        the training command (train.py, roll-train)
    reproduce  the paper's grid of runs, its figures and table (roll-reproduce)
    run_dir    the files of a run directory, its lock; plots: learning curves
    events     the run's TensorBoard event files (DIR/tb): write, trim on resume, read
    sharding   seeds over devices and processes; compiler: the compilation cache, the
               chunk's options
"""

from roll_jax.common.lazy import lazy_api

__all__, __getattr__, __dir__ = lazy_api(__name__, {
    ".loop": ("make_chunk", "compile_chunk"),
    ".state": ("TrainState", "ChunkPlan", "plan_chunk", "init_state"),
    ".driver": ("run", "setup", "init_seeds"),
    ".run_dir": ("read_config", "read_rows", "is_complete"),
    ".events": ("read_scalars",),
})
