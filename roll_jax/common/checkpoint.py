"""Checkpoint folders: orbax pytrees beside a meta.json that says what they were fitted for."""

from __future__ import annotations

import json
import os


def write_meta(path: str, meta: dict) -> str:
    """Create `path` and write its meta.json; returns the absolute path."""
    path = os.path.abspath(path)
    os.makedirs(path, exist_ok=True)
    with open(os.path.join(path, "meta.json"), "w") as f:
        json.dump(meta, f, indent=2)
    return path


def read_meta(path: str, what: str) -> tuple[str, dict]:
    """(absolute path, meta) of a `what` checkpoint; a clear error when there is none."""
    path = os.path.abspath(path)
    meta_path = os.path.join(path, "meta.json")
    if not os.path.exists(meta_path):
        raise FileNotFoundError(f"no {what} checkpoint at {path} (missing meta.json)")
    with open(meta_path) as f:
        return path, json.load(f)


# --- the training state (a run's ckpt/) ---------------------------------------------------------

def train_state_manager(out: str, keep: int, create: bool = True):
    """orbax CheckpointManager of a run's train states in `out`/ckpt (keeps the last `keep`);
    `create=False`: read only."""
    import orbax.checkpoint as ocp

    if create:
        options = ocp.CheckpointManagerOptions(max_to_keep=keep, create=True)
    else:  # read only (evaluation): nothing saved, nothing pruned
        options = ocp.CheckpointManagerOptions(read_only=True, create=False, max_to_keep=None,
                                               save_interval_steps=0)
    return ocp.CheckpointManager(os.path.abspath(os.path.join(out, "ckpt")), options=options)


def _saveable(state) -> dict:
    """The state's leaves by flat index, without zero-size arrays (MJX data has some; orbax
    refuses them); `_unsaveable` rebuilds them from the abstract state."""
    import jax

    return {str(i): x for i, x in enumerate(jax.tree.leaves(state)) if x.size}


def _unsaveable(abstract, saved: dict):
    import jax
    import jax.numpy as jnp
    import numpy as np

    leaves, treedef = jax.tree.flatten(abstract)
    out = []
    for i, x in enumerate(leaves):
        leaf = saved[str(i)] if x.size else np.zeros(x.shape, x.dtype)
        # Placed like the abstract leaf (when it says where): an uncommitted leaf beside
        # committed ones gives the chunk another signature, so a resumed run would compile
        # its chunk again instead of hitting the compilation cache.
        sharding = getattr(x, "sharding", None)
        out.append(jnp.asarray(leaf) if sharding is None else jax.device_put(leaf, sharding))
    return jax.tree.unflatten(treedef, out)


def save_train_state(mgr, epoch: int, state) -> None:
    import orbax.checkpoint as ocp

    mgr.save(epoch, args=ocp.args.StandardSave(_saveable(state)))


def restore_train_state(mgr, abstract):
    """(epoch, state) of the latest checkpoint, `abstract` giving the state's structure."""
    import orbax.checkpoint as ocp

    step = mgr.latest_step()
    target = _saveable(abstract)
    try:
        saved = mgr.restore(step, args=ocp.args.StandardRestore(target))
    except (ValueError, KeyError) as e:
        raise ValueError(
            f"the train state in {mgr.directory}/{step} does not fit this version's "
            f"TrainState ({len(target)} arrays); it was written by another version of "
            f"roll_jax (read it with that version): {str(e)[:160]}") from e
    return step, _unsaveable(abstract, saved)
