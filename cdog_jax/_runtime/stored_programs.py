"""Single-scene programs stored with ``jax.export``, so that a later process neither traces
nor lowers them again.

The persistent compilation cache (``compile_cache.py``) skips XLA's compilation, but its
key is the lowered program: every process still traces the pipeline and lowers it to
StableHLO first (about 1 s for ``best()`` on a CPU, half of a whole ``cdog-jax associate``
run once the cache is warm). Here the lowered program itself is stored, serialised by
``jax.export``, next to the compiled ones; a later process deserialises it (milliseconds),
and its compilation is then found in the compilation cache.

Key: a hash of everything that decides the program: the package's own source files, the
JAX and jaxlib versions, the backend, the JAX options that change tracing, the function,
the static method and arguments (their ``repr``; only methods defined in this package,
whose code the source hash covers) and the structure, shapes and dtypes of the arguments. A stale entry
is therefore never loaded; an unreadable one is ignored and written again. Files are
written whole or not at all (a temporary file renamed), so concurrent processes at worst
export the same program twice. Off whenever the compilation cache is off.

Results are bitwise those of calling the jitted function directly (XLA inlines the
exported module's call; tests/test_stored_programs.py).
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import importlib
import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jaxlib
import numpy as np
from jax import export

from .compile_cache import cache_dir_from_environment
from .xla_kernels import jit

_PACKAGE_ROOT = (
    Path(__file__).resolve().parents[1]
)  # the package (this file is in its _runtime folder)
_TRACING_OPTIONS = (
    "jax_enable_x64",
    "jax_default_matmul_precision",
    "jax_numpy_dtype_promotion",
    "jax_numpy_rank_promotion",
    "jax_default_prng_impl",
)
_source_hash: str | None = None
_loaded: dict[str, tuple | None] = {}  # key → (output structure, jitted call), None: not storable
_keys: dict[tuple, str] = {}  # call signature → key, this process


def loaded_programs() -> int:
    """Programs this process has looked up here (loaded, exported, or found not storable)."""
    return len(_loaded)


def stored_programs_dir() -> Path | None:
    """Where exported programs are kept: ``exported/`` in the compilation cache's folder,
    or None when the compilation cache is off (then nothing is stored)."""
    if not jax.config.jax_compilation_cache_dir:
        return None
    folder = cache_dir_from_environment()
    return None if folder is None else folder / "exported"


def call_stored(jitted: Callable, args: tuple, method=None, **static) -> Any:
    """``jitted(*args, method=method, **static)`` (a ``jax.jit`` whose static arguments
    are ``method`` and ``static``'s, hashable values with a deterministic ``repr``; without
    a ``method``, ``jitted(*args, **static)``), its lowered program loaded from disk where
    an earlier process stored it (and stored here otherwise).

    The function returns a dataclass pytree of arrays (e.g. an ``Association``) or a tuple
    of arrays; ``args`` may hold pytrees and None. Falls back to ``jitted`` itself where
    nothing can be stored: the cache is off, the method is defined outside this package, or
    ``jax.export`` cannot serialise (its ``flatbuffers`` dependency missing, or custom calls
    it does not store).
    """
    if method is not None:
        static = dict(static, method=method)
    folder = stored_programs_dir()
    if folder is None or (
        method is not None and not type(method).__module__.startswith(f"{_PACKAGE_ROOT.name}.")
    ):
        return jitted(*args, **static)
    fun = jitted.__wrapped__
    leaves, treedef = jax.tree.flatten(args)
    avals = tuple((np.shape(leaf), _dtype(leaf)) for leaf in leaves)
    static = dict(sorted(static.items()))
    options = tuple(str(getattr(jax.config, name, None)) for name in _TRACING_OPTIONS)
    # Hashing the key takes ~0.1 ms: computed once per process for each call signature.
    signature = (fun, tuple(static.items()), treedef, avals, options)
    if signature not in _keys:
        _keys[signature] = _key(fun, static, treedef, avals, options)
    key = _keys[signature]
    if key not in _loaded:
        specs = [jax.ShapeDtypeStruct(shape, dtype) for shape, dtype in avals]
        _loaded[key] = _load_or_export(folder / f"{key}.jaxexport", fun, static, treedef, specs)
    if _loaded[key] is None:  # not storable: traced and compiled as usual
        return jitted(*args, **static)
    out_tree, call = _loaded[key]
    outputs = call(*leaves)
    return jax.tree.unflatten(out_tree, outputs)


def _dtype(leaf) -> np.dtype:
    dtype = getattr(leaf, "dtype", None)
    return np.dtype(dtype) if dtype is not None else np.asarray(leaf).dtype


def _key(fun: Callable, static: dict, treedef, avals, options: tuple) -> str:
    """A hash of everything that decides the traced program (``avals``: each argument
    leaf's shape and dtype; ``options``: the values of ``_TRACING_OPTIONS``)."""
    parts = [
        _package_source_hash(),
        jax.__version__,
        _jaxlib_version(),
        jax.default_backend(),
        repr(list(zip(_TRACING_OPTIONS, options))),
        f"{fun.__module__}.{fun.__qualname__}",
        repr(static),
        str(treedef),
        repr([(tuple(shape), str(dtype)) for shape, dtype in avals]),
    ]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:40]


def _jaxlib_version() -> str:
    return str(getattr(jaxlib, "__version__", ""))


def _package_source_hash() -> str:
    """A hash of every ``.py`` file of the package (names and contents), once per process."""
    global _source_hash
    if _source_hash is None:
        digest = hashlib.sha256()
        for path in sorted(_PACKAGE_ROOT.rglob("*.py")):
            digest.update(str(path.relative_to(_PACKAGE_ROOT)).encode())
            digest.update(path.read_bytes())
        _source_hash = digest.hexdigest()
    return _source_hash


def _load_or_export(path: Path, fun: Callable, static: dict, treedef, specs):
    """``(output pytree structure, jitted call)`` of the stored program at
    ``path``, exported and written there first when missing or unreadable; None when
    ``jax.export`` cannot serialise here.

    File: one JSON line (the output dataclass and its field names, so that a later process
    rebuilds the result without tracing), then the serialised program."""
    try:
        header, blob = path.read_bytes().split(b"\n", 1)
        meta = json.loads(header)
        out_tree = dataclass_tree(_import_name(meta["output"]), meta["fields"])
        return out_tree, jit(export.deserialize(bytearray(blob)).call)
    except Exception:  # missing, or from an interrupted or foreign writer: export it (again)
        pass
    traced = {}

    def flat(*leaves):
        result = fun(*jax.tree.unflatten(treedef, leaves), **static)
        traced["type"] = type(result)
        if isinstance(result, tuple):
            traced["fields"] = len(result)
            return result
        traced["fields"] = tuple(field.name for field in dataclasses.fields(result))
        return tuple(getattr(result, name) for name in traced["fields"])

    try:
        exported = export.export(jax.jit(flat))(*specs)
        blob = exported.serialize()
    except ImportError:  # flatbuffers missing
        return None
    except ValueError as error:
        # Custom calls without a compatibility promise (e.g. a LAPACK solve of refinement):
        # jax.export refuses them; such a program is traced and compiled as usual.
        if "custom call" in str(error):
            return None
        raise
    out_type, names = traced["type"], traced["fields"]
    header = json.dumps(
        {"output": f"{out_type.__module__}:{out_type.__qualname__}", "fields": names}
    )
    _write_whole(path, header.encode() + b"\n" + bytes(blob))
    return dataclass_tree(out_type, names), jit(exported.call)


def dataclass_tree(kind: type, names) -> Any:
    """The pytree structure of a ``kind`` dataclass whose fields ``names`` are arrays, built
    without its ``__init__`` (whose shape checks a batched result would fail), as
    ``jax.tree.unflatten`` builds one."""
    if kind is tuple:  # a tuple of ``names`` (a count) arrays
        return jax.tree.structure((0,) * names)
    template = object.__new__(kind)
    for name in names:
        object.__setattr__(template, name, 0)
    return jax.tree.structure(template)


def _import_name(name: str) -> type:
    """The object ``module:qualname`` names."""
    module, qualname = name.split(":")
    found = importlib.import_module(module)
    for part in qualname.split("."):
        found = getattr(found, part)
    return found


def _write_whole(path: Path, data: bytes) -> None:
    """``data`` to ``path`` through a temporary file in its folder and a rename; a failure
    (full disk, read-only folder) leaves nothing behind and is not an error. (Not
    ``cdog_jax.io``'s ``atomic_write``: this base module may not import the file layer, and
    a cache entry needs no fsync, permissions or link handling.)"""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError:
        return
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(temporary, path)
    except OSError:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
