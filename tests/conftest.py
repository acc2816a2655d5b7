"""Test-wide settings: CPU only, faster-compiling XLA options, a persistent compilation cache."""
import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("MUJOCO_GL", "disable")

from roll_jax.training import compiler  # noqa: E402  (no jax import at module level)

# XLA:CPU options that cut the suite's compiles without slowing what it runs: the older
# elemental emitters, and LLVM at -O1 instead of -O2 (the figures in docs/development.md,
# "The test suite"). Set before jax starts, and only where this jaxlib knows them: XLA
# aborts on an unknown flag.
FAST_COMPILE_FLAGS = ("--xla_cpu_use_fusion_emitters=false", "--xla_backend_optimization_level=1")


def _with_fast_compile(flags: str) -> str:
    missing = [f for f in FAST_COMPILE_FLAGS if f.split("=")[0] not in flags]
    if not missing:
        return flags
    together = " ".join([flags, *missing]).strip()
    if not compiler.xla_flags_refusal(together):
        return together
    for flag in missing:  # one of them is unknown to this jaxlib: keep those it accepts
        candidate = f"{flags} {flag}".strip()
        if not compiler.xla_flags_refusal(candidate):
            flags = candidate
    return flags


os.environ["XLA_FLAGS"] = _with_fast_compile(os.environ.get("XLA_FLAGS", ""))

import jax  # noqa: E402
import pytest  # noqa: E402

_CACHE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), ".jax_cache")
jax.config.update("jax_compilation_cache_dir", _CACHE)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)

# The longest files run first, the slowest two one per worker: `pytest -n 2 --dist loadfile
# --no-loadscope-reorder` (make test) hands a worker its next file when it is nearly done,
# so the short files come last and even out the two workers' finishing times.
_SLOW_FIRST = ("test_train.py", "test_sharding.py", "test_multihost.py",
               "test_segmentation_pipeline.py", "test_run_logging.py", "test_envs.py",
               "test_oracle.py", "test_losses.py", "test_skewfit_ablations.py",
               "test_analysis.py", "test_gpu_check.py", "test_envs_render.py")


def pytest_collection_modifyitems(config, items):
    def rank(item):
        name = os.path.basename(str(item.fspath))
        return _SLOW_FIRST.index(name) if name in _SLOW_FIRST else len(_SLOW_FIRST)

    items.sort(key=rank)  # stable: keeps the order inside each file


@pytest.fixture
def train_cli():
    """The training command (train.py, roll-train): roll_jax/training/cli.py."""
    from roll_jax.training import cli

    return cli
