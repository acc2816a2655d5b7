"""Packages that name their public API without importing it (PEP 562): `import roll_jax` or
`import roll_jax.training` loads no JAX, so the commands answer --help at once and the test
suite sets XLA's flags before JAX starts; a name is imported from its module on first use."""

from __future__ import annotations

import importlib


def lazy_api(package: str, api: dict[str, tuple[str, ...]]):
    """(__all__, __getattr__, __dir__) of a package's __init__ that exports each name of
    `api` (module -> names; a module name starting with "." is relative to `package`)."""
    where = {name: module for module, names in api.items() for name in names}

    def __getattr__(name: str):
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(where[name], package), name)

    def __dir__():
        return sorted(where)

    return list(where), __getattr__, __dir__
