"""`--set KEY=VALUE` command-line overrides of config dataclasses (train.py, reproduce,
the segmentation CLI, benchmarks)."""
from __future__ import annotations

import ast
import dataclasses
import difflib

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


def _split_top(text: str, sep: str) -> list[str]:
    """`text` split at `sep` outside brackets ("tuple[int, int] | None" -> 2 parts at " | ")."""
    parts, depth, start, i = [], 0, 0, 0
    while i < len(text):
        c = text[i]
        depth += (c == "[") - (c == "]")
        if depth == 0 and text.startswith(sep, i):
            parts.append(text[start:i].strip())
            i += len(sep)
            start = i
            continue
        i += 1
    return parts + [text[start:].strip()]


def _fits(annotation: str, value) -> bool | None:
    """Whether `value` is of the type `annotation` names (int, float, bool, str, None, unions
    and tuple[...] of those); None for an annotation this does not check (e.g. a config class)."""
    alternatives = _split_top(annotation, "|")
    unchecked = False
    for alt in alternatives:
        if alt == "None":
            ok = value is None
        elif alt in _SCALARS:
            kinds = _SCALARS[alt]
            ok = isinstance(value, kinds) and (bool in kinds or not isinstance(value, bool))
        elif alt.startswith("tuple[") and alt.endswith("]"):
            items = _split_top(alt[len("tuple["):-1], ",")
            if not isinstance(value, tuple):
                ok = False
            elif len(items) == 2 and items[1] == "...":
                fits = [_fits(items[0], v) for v in value]
                ok = None if None in fits else all(fits)
            else:
                fits = [_fits(t, v) for t, v in zip(items, value)]
                ok = None if None in fits else (len(value) == len(items) and all(fits))
        else:
            ok = None
        if ok:
            return True
        unchecked |= ok is None
    return None if unchecked else False


def unknown(name: str, known, what: str, prefix: str = "") -> str:
    """"unknown WHAT" with the nearest of `known` to `name` (difflib) and all of them."""
    known = list(known)
    near = difflib.get_close_matches(name, known, n=1)
    hint = f"; did you mean {prefix}{near[0]}?" if near else "."
    return f"unknown {what}{hint} Valid: {', '.join(known)}"


def check_field(cls, name: str, value, label: str | None = None) -> None:
    """ValueError naming `--set LABEL` (LABEL defaults to `name`; "sac.batch_size" for a
    nested field) when `name` is not a field of the config dataclass `cls` (with the nearest
    field and all of them) or `value` is not of its annotated type (naming the field, the
    value and the type)."""
    fields = {f.name: f.type for f in dataclasses.fields(cls)}
    label = name if label is None else label
    if name not in fields:
        what = f"field of {cls.__name__}"
        raise ValueError(f"--set {label}: {unknown(name, fields, what, label[:-len(name)])}")
    t = fields[name]
    annotation = t if isinstance(t, str) else getattr(t, "__name__", str(t))
    if annotation.removesuffix(" | None").endswith("Config"):
        raise ValueError(f"--set {label}={value!r}: {label} is a group of fields "
                         f"({annotation}); set one of them: --set {label}.FIELD=VALUE")
    if _fits(annotation, value) is False:
        hint = " (Python literals: True, False)" if (
            isinstance(value, str) and value.lower() in ("true", "false")) else ""
        got = "None" if value is None else type(value).__name__
        raise ValueError(f"--set {label}: {cls.__name__}.{name} takes {annotation}, got "
                         f"{value!r} ({got}){hint}")


def field_overrides(cls, items) -> dict:
    """KEY=VALUE overrides of the flat config dataclass `cls` -> {field: value}; ValueError
    naming the item for a group, an unknown field or a value of the wrong type."""
    over = parse_overrides(items)
    groups = sorted(g for g in over if g)
    if groups:
        raise ValueError(f"--set {groups[0]}.*: {cls.__name__} has no nested configs")
    out = over.get("", {})
    for name, value in out.items():
        check_field(cls, name, value)
    return out
