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
    # The handler named: `item_metadata` then reads a step's tree without restoring it.
    return ocp.CheckpointManager(os.path.abspath(os.path.join(out, "ckpt")), options=options,
                                 item_handlers=ocp.StandardCheckpointHandler())


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


class DamagedCheckpoint(RuntimeError):
    """No checkpoint of a run can be read."""


def _short(e: BaseException) -> str:
    """One line of an orbax / TensorStore error: its cause (the read that failed), without the
    TensorStore spec it prints."""
    cause = e.__cause__ or e.__context__
    err = cause if cause is not None and str(cause) else e
    text = str(err).split("See full TensorStore details")[0].strip()
    text = text.splitlines()[0][:300] if text else ""
    # A bare key or number (a KeyError's) says nothing without its type.
    return text if " " in text else f"{type(err).__name__} {text}".strip()


_UNRAISABLE_FILTERED = False


def _quiet_failed_reads() -> None:
    """A failed restore leaves orbax's other array reads pending; when they finish after its
    event loop closed, Python prints each one's traceback ("RuntimeError: Event loop is
    closed", "Encountered error while reading array index"), hundreds of lines that say no
    more than the error already reported; a gathering future of those reads that is collected
    unread is logged by asyncio the same way ("_GatheringFuture exception was never
    retrieved"). Those, and only those, are dropped from the first restore on (installed once
    per process), from both Python's unraisable hook and the asyncio logger."""
    global _UNRAISABLE_FILTERED
    import logging
    import sys

    if _UNRAISABLE_FILTERED:
        return
    previous = sys.unraisablehook

    def left_behind(exc) -> bool:
        text = str(exc)
        return (isinstance(exc, RuntimeError) and text == "Event loop is closed") or \
            text.startswith("Encountered error while reading array")

    def hook(u):
        if not left_behind(u.exc_value):
            previous(u)

    def keep(record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        return exc is None or not left_behind(exc)

    sys.unraisablehook = hook
    logging.getLogger("asyncio").addFilter(keep)
    _UNRAISABLE_FILTERED = True


def _structure_mismatch(meta: dict, target: dict) -> str | None:
    """How a checkpoint's arrays differ from the state's (another version of the code), or
    None."""
    if set(meta) != set(target):
        return (f"{len(meta)} arrays saved, this version's TrainState has {len(target)}")
    for k in sorted(target, key=int):
        saved = tuple(getattr(meta[k], "shape", ()) or ())
        if saved != tuple(target[k].shape):
            return f"array {k} has shape {saved}, this version's is {tuple(target[k].shape)}"
    return None


def restore_train_state(mgr, abstract, on_damaged=None):
    """(epoch, state) of the newest checkpoint that can be read, `abstract` giving the state's
    structure. A step that cannot be read (a file truncated or missing) is passed to
    `on_damaged(step, reason)` and the next older one is tried; DamagedCheckpoint when none
    can be read. A checkpoint of another TrainState (another version of roll_jax) is a
    ValueError saying so."""
    import orbax.checkpoint as ocp

    target = _saveable(abstract)
    steps = sorted(mgr.all_steps(), reverse=True)
    damaged = []
    for step in steps:
        try:
            meta = dict(mgr.item_metadata(step))
        except Exception as e:  # noqa: BLE001 (unreadable metadata: damaged, whatever raised)
            reason = f"its metadata cannot be read ({_short(e)})"
        else:
            mismatch = _structure_mismatch(meta, target)
            if mismatch:
                raise ValueError(
                    f"the train state in {mgr.directory}/{step} does not fit this version's "
                    f"TrainState ({mismatch}); it was written by another version of roll_jax "
                    f"(read it with that version)")
            _quiet_failed_reads()  # before: the reads left behind report while it unwinds
            try:
                saved = mgr.restore(step, args=ocp.args.StandardRestore(target))
            except Exception as e:  # noqa: BLE001 (any read error: the step is damaged)
                reason = _short(e)
            else:
                return step, _unsaveable(abstract, saved)
        damaged.append(step)
        if on_damaged is not None:
            on_damaged(step, reason)
    raise DamagedCheckpoint(
        f"no checkpoint in {mgr.directory} can be read (damaged: "
        f"{', '.join(map(str, damaged))}); nothing was changed. To start the run again, move "
        f"or delete {mgr.directory} and train without --resume")
