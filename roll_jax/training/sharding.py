"""Seeds sharded across devices: a 1-D `Mesh` named "seeds".

The train state carries seeds as its leading (vmapped) axis; with several devices that axis,
and the per-seed PRNG keys, are split over the mesh with `NamedSharding(mesh, P("seeds"))`,
while the frozen parameters (segmentation, object-VAE) are replicated. The compiled chunk is
`jit(vmap(...))`: given committed sharded inputs, XLA's SPMD partitioner runs each device's
seeds locally (no cross-seed communication: the seeds are independent). With one device
nothing is placed and the run is exactly the unsharded one.

How a device runs its seeds is `--seed-batch`: vmapped side by side (GPU/TPU, where one wide
program fills the accelerator), or a few at a time in a `lax.map` (CPU, where the seed-vmapped
per-seed VAE convolutions become grouped convolutions and a 2-seed smoke chunk ran 2.1x slower
than one seed after the other, at 2.5x the CPU time). `over_seeds` builds either; the math per
seed is the same, the float rounding is not bit-identical between the two.

Several processes (hosts, or one per GPU): `initialize_distributed` (train.py --distributed)
before anything else asks JAX for devices; `jax.devices()` is then the global device list,
the mesh spans every process's devices, each process builds and runs its own seeds' shards, and
`to_host` gathers the metrics to every process (on a CPU over gloo). Process 0 writes the run's
files, orbax writes each process's shards of a checkpoint (tests/test_multihost.py: two
processes on one machine against one).
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

AXIS = "seeds"


def _parse_count(spec, flag: str, word: str) -> int | None:
    """`word` (or None) -> None; 'N' / N -> N >= 1; else a ValueError naming `flag`."""
    if spec is None or spec == word:
        return None
    try:
        n = int(spec)
    except (TypeError, ValueError):
        n = 0
    if n < 1:
        raise ValueError(f"{flag} must be '{word}' or a positive integer, got {spec!r}")
    return n


def parse_devices(spec) -> int | None:
    """'all' (or None) -> None (as many devices as divide the seeds); 'N' / N -> N >= 1."""
    return _parse_count(spec, "--devices", "all")


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


def parse_seed_batch(spec) -> int | None:
    """'auto' (or None) -> None; 'N' / N -> N >= 1 seeds vmapped together per device."""
    return _parse_count(spec, "--seed-batch", "auto")


def resolve_seed_batch(spec, seeds: int, n_devices: int = 1, platform: str | None = None) -> int:
    """Seeds each device runs side by side (vmapped); the rest of its seeds follow in a
    `lax.map`. 'auto': 1 on CPU, all of the device's seeds elsewhere. An explicit N must
    divide the device's seeds (errors name both numbers, before compiling)."""
    per_device = seeds // n_devices
    n = parse_seed_batch(spec)
    if n is None:
        platform = platform or jax.devices()[0].platform
        return 1 if platform == "cpu" else per_device
    if per_device % n:
        raise ValueError(f"--seed-batch {n} does not divide the {per_device} seed(s) per device "
                         f"({seeds} seeds on {n_devices} device(s))")
    return n


def over_seeds(fn, seeds: int, n_devices: int = 1, seed_batch: int | None = None):
    """fn(state, *shared) for ONE seed -> the same over a [seeds]-leading state (shared args
    un-batched): each of the `n_devices` devices runs its own seeds (device-major, as
    `SeedSharding.shard` places them) in a `lax.map` over groups of `seed_batch` vmapped
    seeds (None: all of them vmapped, no map)."""

    def vfn(state, *shared):
        return jax.vmap(fn, in_axes=(0,) + (None,) * len(shared))(state, *shared)

    local = seeds // n_devices
    per_step = local if seed_batch is None else seed_batch
    if per_step >= local:
        return vfn
    steps, width = local // per_step, n_devices * per_step
    if width == 1:  # a plain map: no vmap of batch 1 (XLA:CPU gives it other kernels)
        return lambda state, *shared: jax.lax.map(lambda s: fn(s, *shared), state)

    def split(x):  # [S] -> [steps, width]: step i holds the i-th group of every device
        x = x.reshape((n_devices, steps, per_step) + x.shape[1:]).swapaxes(0, 1)
        return x.reshape((steps, width) + x.shape[3:])

    def merge(x):
        x = x.reshape((steps, n_devices, per_step) + x.shape[2:]).swapaxes(0, 1)
        return x.reshape((seeds,) + x.shape[3:])

    def mapped(state, *shared):
        out = jax.lax.map(lambda s: vfn(s, *shared), jax.tree.map(split, state))
        return jax.tree.map(merge, out)

    return mapped


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


def initialize_distributed(coordinator_address: str | None = None,
                           num_processes: int | None = None, process_id: int | None = None) -> None:
    """`jax.distributed.initialize` with what is given (None: JAX's cluster detection, SLURM,
    Open MPI, ..., or $JAX_COORDINATOR_ADDRESS). On a CPU backend the processes' collectives
    (the metrics' all-gather) go over gloo."""
    kwargs = {k: v for k, v in (("coordinator_address", coordinator_address),
                                ("num_processes", num_processes),
                                ("process_id", process_id)) if v is not None}
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    jax.distributed.initialize(**kwargs)


def is_main_process() -> bool:
    """Files other than checkpoints (orbax coordinates its own) are written by process 0."""
    return jax.process_index() == 0
