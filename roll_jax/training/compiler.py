"""How programs are compiled: JAX's persistent compilation cache (a second run of the same
config loads its compiled programs; the training chunk is the largest: about a minute to
compile on a 2-core CPU) and the training chunk's own XLA:CPU options.

`train.py` uses `default_dir()` unless `--compile-cache off` (or a directory) is given; the
reproduction grid keeps its own in DIR/.jax_cache. A cache configured earlier in the process
(e.g. by the test suite) is left as it is. `xla_flags_refusal` checks XLA_FLAGS before a
process is started with them; `accepted_options` checks per-program compiler options.
"""

from __future__ import annotations

import functools
import os
import subprocess
import sys
import warnings


def default_dir() -> str:
    """$ROLL_JAX_CACHE, else $XDG_CACHE_HOME/roll_jax/jax, else ~/.cache/roll_jax/jax."""
    if os.environ.get("ROLL_JAX_CACHE"):
        return os.environ["ROLL_JAX_CACHE"]
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "roll_jax", "jax")


def use(path: str, min_compile_s: float = 1.0) -> str:
    """Cache programs that took >= `min_compile_s` to compile in `path`; returns the cache
    directory in use (the earlier one if the process configured one already)."""
    import jax

    if jax.config.jax_compilation_cache_dir:
        return jax.config.jax_compilation_cache_dir
    os.makedirs(path, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", min_compile_s)
    return path


def xla_flags_refusal(flags: str) -> str | None:
    """None if a fresh Python process with XLA_FLAGS=`flags` starts JAX; else XLA's last
    message (XLA aborts the process on a flag it does not know)."""
    proc = subprocess.run([sys.executable, "-c", "import jax; jax.numpy.zeros(1) + 1"],
                          env=dict(os.environ, XLA_FLAGS=flags), capture_output=True,
                          text=True, check=False)
    if proc.returncode == 0:
        return None
    return (proc.stderr.strip().splitlines() or ["(no message)"])[-1][-300:]


@functools.lru_cache(maxsize=None)
def accepted_options(options: tuple[tuple[str, object], ...]) -> dict | None:
    """The options of `options` that this jaxlib compiles a tiny program with, as the dict
    `jax.jit(..., compiler_options=...)` takes (None if it accepts none of them). Each option is
    tried on its own, and each refused one is dropped with a warning that names it: XLA refuses
    an option it does not know, and option names change between XLA versions."""
    import jax
    import jax.numpy as jnp

    kept = {}
    for name, value in options:
        try:
            jax.jit(lambda x: x + 1, compiler_options={name: value}).lower(jnp.zeros(1)).compile()
        except Exception as e:  # noqa: BLE001  (the error type differs between jaxlib versions)
            warnings.warn(f"XLA refused the compiler option {name}={value!r} ({str(e)[:200]}); "
                          "compiling without it", stacklevel=2)
            continue
        kept[name] = value
    return kept or None


# XLA:CPU options for the chunk alone: the older elemental emitters and LLVM at -O1 compile
# the cpu preset's chunk faster and it runs faster; without the YNNPACK fusions its SAC
# updates run faster and its online LSTM steps slower, the chunk faster in all
# (docs/training.md#compiling-the-chunk). The other programs keep XLA's defaults (the VAE and U-Net
# train steps run slower with the emitters and without YNNPACK).
CHUNK_CPU_COMPILER_OPTIONS = (("xla_cpu_use_fusion_emitters", False),
                              ("xla_backend_optimization_level", 1),
                              ("xla_cpu_experimental_ynn_fusion_type", ""))


def chunk_compiler_options() -> dict | None:
    """The chunk's `compiler_options`: CHUNK_CPU_COMPILER_OPTIONS on a CPU backend (where the
    installed jaxlib accepts them), XLA's defaults elsewhere. An option the process's
    XLA_FLAGS sets is left to XLA_FLAGS (a per-program option would override it)."""
    import jax

    if jax.default_backend() != "cpu":
        return None
    flags = os.environ.get("XLA_FLAGS", "")
    options = tuple((k, v) for k, v in CHUNK_CPU_COMPILER_OPTIONS if f"--{k}" not in flags)
    return accepted_options(options) if options else None
