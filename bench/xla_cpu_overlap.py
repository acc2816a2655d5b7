"""Does XLA:CPU run two independent loops of one program side by side?

The chunk's SAC updates within an env step do not depend on that step's physics, render or
encodings, so the program leaves XLA free to run them beside each other on the two cores. This
times toy stand-ins in one process: a loop of small matmuls (the updates) and a loop of small
elementwise ops (the env work), each alone and both in one program; then the same inside an
outer scan with the matmul loop under a `lax.cond`, as the chunk runs its updates; then with
either loop unrolled. "together" near "sum" means one after the other; near the larger of the
two, side by side.

    python bench/xla_cpu_overlap.py      # ~30 s; writes bench/results/xla_cpu_overlap.json
"""
from __future__ import annotations

import json
import os
import sys

import jax
import jax.numpy as jnp

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench.common import machine_info, time_best  # noqa: E402

RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results",
                       "xla_cpu_overlap.json")
INNER, OUTER = 20, 100


def matmul_loop(x, n=INNER):
    return jax.lax.scan(lambda c, _: (jnp.tanh(c @ c * 0.01), None), x, None, length=n)[0]


def elementwise_loop(y, n=INNER):
    return jax.lax.scan(lambda c, _: (jnp.sin(c) * 1.0001 + 0.001, None), y, None, length=n)[0]


def matmul_unrolled(x):
    for _ in range(INNER):
        x = jnp.tanh(x @ x * 0.01)
    return x


def elementwise_unrolled(y):
    for _ in range(INNER):
        y = jnp.sin(y) * 1.0001 + 0.001
    return y


def best_ms(f, *args) -> float:
    return round(1e3 * time_best(f, *args, repeats=7)[1], 2)


def nested(fa, fb, use_a: bool = True, use_b: bool = True):
    """OUTER steps, each running fb on y and fa on x under a cond (as the chunk's updates)."""
    def body(carry, _):
        x, y = carry
        if use_b:
            y = fb(y)
        if use_a:
            x = jax.lax.cond(x[0, 0] > -1, fa, lambda v: v, x)
        return (x, y), None
    return jax.jit(lambda x, y: jax.lax.scan(body, (x, y), None, length=OUTER)[0])


def main() -> None:
    info = machine_info()
    x, y = jnp.full((64, 64), 0.1), jnp.ones((48, 48))
    rows = []
    a = jax.jit(lambda x: matmul_loop(x, INNER * OUTER))
    b = jax.jit(lambda y: elementwise_loop(y, INNER * OUTER))
    both = jax.jit(lambda x, y: (matmul_loop(x, INNER * OUTER), elementwise_loop(y, INNER * OUTER)))
    for rnd in range(2):
        ta, tb, tab = best_ms(a, x), best_ms(b, y), best_ms(both, x, y)
        rows.append({"form": "two top-level loops", "round": rnd, "matmul_ms": ta,
                     "elementwise_ms": tb, "sum_ms": round(ta + tb, 2), "together_ms": tab})
    for name, fa, fb in (("in an outer scan, matmul loop under a cond", matmul_loop,
                          elementwise_loop),
                         ("the same, elementwise ops unrolled", matmul_loop, elementwise_unrolled),
                         ("the same, both unrolled", matmul_unrolled, elementwise_unrolled)):
        ta = best_ms(nested(fa, fb, use_b=False), x, y)
        tb = best_ms(nested(fa, fb, use_a=False), x, y)
        tab = best_ms(nested(fa, fb), x, y)
        rows.append({"form": name, "matmul_ms": ta, "elementwise_ms": tb,
                     "sum_ms": round(ta + tb, 2), "together_ms": tab})
    for r in rows:
        print(json.dumps(r))
    os.makedirs(os.path.dirname(RESULTS), exist_ok=True)
    with open(RESULTS, "w") as f:
        json.dump({"what": __doc__.splitlines()[0], **info, "rows": rows}, f, indent=1)
    print("wrote", RESULTS)


if __name__ == "__main__":
    main()
