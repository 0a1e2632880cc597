"""Names of a package that load their module when first read (PEP 562), so that importing
the package stays quick: ``cdog_jax``'s figures, ``cdog_jax.benchmark``'s sweep."""

from __future__ import annotations

import importlib
import types
from collections.abc import Callable, Mapping


def load_on_first_use(
    namespace: dict, later: Mapping[str, str]
) -> tuple[Callable, Callable, list[str]]:
    """``(__getattr__, __dir__, __all__)`` for the package whose globals are ``namespace``:
    each name of ``later`` (name → module, relative to the package) is imported from its
    module when first read, then kept in ``namespace``. ``__dir__`` and ``__all__`` list
    these names beside the package's public globals (a star import loads them too); the
    subpackages are attributes, not names of ``__all__``."""
    package = namespace["__name__"]

    def __getattr__(name: str):
        if name not in later:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(later[name], package), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(later))

    names = {
        name
        for name, value in namespace.items()
        if not name.startswith("_") and not isinstance(value, types.ModuleType)
    }
    public = sorted(names | set(later))
    return __getattr__, __dir__, public
