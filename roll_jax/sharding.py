"""Seeds sharded across devices: a 1-D `Mesh` named "seeds".

The train state carries seeds as its leading (vmapped) axis; with several devices that axis,
and the per-seed PRNG keys, are split over the mesh with `NamedSharding(mesh, P("seeds"))`,
while the frozen parameters (segmentation, object-VAE) are replicated. The compiled chunk is
`jit(vmap(...))`: given committed sharded inputs, XLA's SPMD partitioner runs each device's
seeds locally (no cross-seed communication: the seeds are independent). With one device
nothing is placed and the run is exactly the unsharded one.

Multi-host: call `jax.distributed.initialize()` before anything else; `devices("all")` is
then the global device list, and `to_host` gathers the seed axis to every process.
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

AXIS = "seeds"


def parse_devices(spec) -> int | None:
    """'all' (or None) -> None (as many devices as divide the seeds); 'N' / N -> N >= 1."""
    if spec is None or spec == "all":
        return None
    try:
        n = int(spec)
    except (TypeError, ValueError):
        raise ValueError(f"--devices must be 'all' or a positive integer, got {spec!r}") from None
    if n < 1:
        raise ValueError(f"--devices must be 'all' or a positive integer, got {spec!r}")
    return n


def resolve(spec, seeds: int) -> list:
    """The devices a run of `seeds` seeds uses; errors name both numbers (before compiling)."""
    n = parse_devices(spec)
    available = jax.devices()
    if n is None:
        # 'all': as many devices as split the seeds evenly (so `--seeds 1`, the default, and
        # `make train`'s 2 seeds run on any machine); an explicit N is taken literally.
        n = max(d for d in range(1, len(available) + 1) if seeds % d == 0)
    elif n > len(available):
        raise ValueError(f"--devices {n}: only {len(available)} device(s) available "
                         f"({available[0].platform})")
    if seeds % n:
        divisors = [d for d in range(1, n + 1) if seeds % d == 0 and d <= len(available)]
        raise ValueError(f"--seeds {seeds} is not divisible by the {n} devices "
                         f"(--devices {spec if spec is not None else 'all'}); the seed axis is "
                         f"split evenly over them: use --seeds a multiple of {n} or "
                         f"--devices {max(divisors)}")
    return available[:n]


@dataclasses.dataclass(frozen=True)
class SeedSharding:
    """Placement of a [seeds, ...] state over a 1-D mesh of devices."""

    mesh: Mesh

    @classmethod
    def create(cls, devices) -> SeedSharding:
        return cls(Mesh(np.asarray(devices), (AXIS,)))

    @property
    def n_devices(self) -> int:
        return self.mesh.size

    @property
    def seeds(self) -> NamedSharding:
        return NamedSharding(self.mesh, PartitionSpec(AXIS))

    @property
    def replicated(self) -> NamedSharding:
        return NamedSharding(self.mesh, PartitionSpec())

    def shard(self, tree):
        """Every leaf split along its leading (seed) axis."""
        return jax.device_put(tree, self.seeds)

    def replicate(self, tree):
        return jax.device_put(tree, self.replicated)

    def wrap_chunk(self, chunk):
        """The compiled chunk on sharded state: inputs placed (state donated as before) and
        the output state pinned to the seed sharding, so every chunk sees the same layout
        (no recompiles) whatever XLA's propagation picked."""

        def sharded_chunk(state, frozen, plan):
            state, metrics = chunk(self.shard(state), frozen, plan)
            return self.shard(state), metrics

        return sharded_chunk


def make(spec, seeds: int) -> SeedSharding | None:
    """None for one device (today's unsharded path), else the seed sharding."""
    devs = resolve(spec, seeds)
    return None if len(devs) == 1 else SeedSharding.create(devs)


def to_host(tree):
    """numpy copy of a (possibly multi-process sharded) tree: `jax.device_get`, or an
    all-gather over processes when some shards live on other hosts."""
    leaves = jax.tree.leaves(tree)
    if all(getattr(x, "is_fully_addressable", True) for x in leaves):
        return jax.device_get(tree)
    from jax.experimental import multihost_utils

    return multihost_utils.process_allgather(tree, tiled=True)


def is_main_process() -> bool:
    """Files other than checkpoints (orbax coordinates its own) are written by process 0."""
    return jax.process_index() == 0
