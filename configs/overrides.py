"""`--set KEY=VALUE` command-line overrides of config dataclasses (train.py, reproduce,
the segmentation CLI, benchmarks)."""
from __future__ import annotations

import ast
import dataclasses

# Annotation (a string under `from __future__ import annotations`) -> accepted value types.
_SCALARS = {"int": (int,), "float": (int, float), "bool": (bool,), "str": (str,)}


def parse_overrides(items) -> dict:
    """KEY=VALUE (top-level fields) or GROUP.KEY=VALUE (a nested config, e.g. sac.) ->
    {group: {field: Python literal}} ('' = top level)."""
    out: dict = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"--set {item!r}: expected KEY=VALUE")
        key, raw = item.split("=", 1)
        try:
            value = ast.literal_eval(raw)
        except (ValueError, SyntaxError):
            value = raw
        group, _, field = key.rpartition(".")
        out.setdefault(group, {})[field] = value
    return out


def field_overrides(cls, items) -> dict:
    """KEY=VALUE overrides of the flat config dataclass `cls` -> {field: value}; ValueError
    naming the item for a group, an unknown field or a value of the wrong type."""
    fields = {f.name: f.type for f in dataclasses.fields(cls)}
    over = parse_overrides(items)
    groups = sorted(g for g in over if g)
    if groups:
        raise ValueError(f"--set {groups[0]}.*: {cls.__name__} has no nested configs")
    out = over.get("", {})
    for name, value in out.items():
        if name not in fields:
            raise ValueError(f"--set {name}: unknown field; {cls.__name__} has "
                             f"{', '.join(fields)}")
        kinds = _SCALARS.get(str(fields[name]))
        if kinds and (not isinstance(value, kinds) or (bool not in kinds and isinstance(value, bool))):
            raise ValueError(f"--set {name}={value!r}: expected a {fields[name]}")
    return out
