"""Per-program XLA compiler options: known ones are kept, unknown ones refused with a warning."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from roll_jax.training import compiler


def test_accepted_options_keeps_known_and_refuses_unknown_with_a_warning():
    opts = compiler.accepted_options(compiler.CHUNK_CPU_COMPILER_OPTIONS)
    assert opts == dict(compiler.CHUNK_CPU_COMPILER_OPTIONS)
    with pytest.warns(UserWarning, match="xla_no_such_option"):
        assert compiler.accepted_options((("xla_no_such_option", 1),)) is None
    # one refused option costs only itself
    with pytest.warns(UserWarning, match="xla_no_such_option_either"):
        assert compiler.accepted_options((("xla_backend_optimization_level", 1),
                                               ("xla_no_such_option_either", 1))) == {
            "xla_backend_optimization_level": 1}


def test_chunk_options_leave_what_xla_flags_sets_to_xla_flags(monkeypatch):
    monkeypatch.setenv("XLA_FLAGS", "")
    assert compiler.chunk_compiler_options() == dict(compiler.CHUNK_CPU_COMPILER_OPTIONS)
    monkeypatch.setenv("XLA_FLAGS", "--xla_backend_optimization_level=2")
    want = {k: v for k, v in compiler.CHUNK_CPU_COMPILER_OPTIONS
            if k != "xla_backend_optimization_level"}
    assert compiler.chunk_compiler_options() == want
    monkeypatch.setenv("XLA_FLAGS", " ".join(f"--{k}={v}" for k, v in (
        ("xla_cpu_use_fusion_emitters", "true"), ("xla_backend_optimization_level", 2),
        ("xla_cpu_experimental_ynn_fusion_type", ""))))
    assert compiler.chunk_compiler_options() is None


def test_a_program_built_with_the_chunk_options_computes_the_same():
    x = np.linspace(-2.0, 2.0, 64, dtype=np.float32).reshape(8, 8)

    def f(a):
        return jnp.tanh(a @ a.T).sum(0) + jnp.exp(-a).mean()

    plain = jax.jit(f)(x)
    opts = compiler.accepted_options(compiler.CHUNK_CPU_COMPILER_OPTIONS)
    built = jax.jit(f, compiler_options=opts)(x)
    np.testing.assert_allclose(np.asarray(built), np.asarray(plain), rtol=1e-6)
