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
