"""XLA's own CPU kernels for the small reductions and products of our programs.

XLA's CPU backend hands some fusions (sums over an axis, small dot products) to its YNN
library. For our programs' shapes (a sum over two or three coordinates, a 3 × 3 product,
thousands of small kernels a call) XLA's own kernels are faster: on a 2-core CPU a live
Shelf-like frame takes 1.3–2.2 ms less and the warm benchmark grid about a fifth less
(9.6–9.7 s against 12.0–12.5 s on both cores), with the same
groups, labels and points (sums whose terms are added in another order may round the last
bit of a reprojection error or σ differently).

The package's programs that are called from the host (one scene, a batch, the classes'
scenes, the σ fit, a live frame's tracker step, the benchmark sweep) ask for them one by
one (:func:`jit`: XLA's compile options of that program alone), so a library call gets them
without any process-wide setting. JAX refuses compile options on a ``jit`` traced inside
another, so the functions a user may call inside their own ``jit`` or ``vmap`` (geometry,
the stages, synthetic scenes, ``track_sequence``, calibration) keep a plain ``jax.jit``.
The command line also sets the switch for its whole process (:func:`use_xla_kernels`: XLA
reads ``XLA_FLAGS`` once, when JAX starts its backend), which covers those too; both ways
compile the same code.
"""

from __future__ import annotations

import functools
import importlib.metadata
import importlib.util
import os
from collections.abc import Callable
from typing import Any

import jax
import jaxlib
from jax._src import xla_bridge

FLAG = "--xla_cpu_experimental_ynn_fusion_type="
"""The switch (an empty list of fusion kinds for the YNN library)."""

MEASURED_JAXLIB = ("0.10.",)
"""jaxlib releases the switch was measured with. An XLA that does not know a flag stops
the process when it starts (or refuses a program's compile option), so the switch is used
only on these."""


def _measured_jaxlib() -> bool:
    return str(getattr(jaxlib, "__version__", "")).startswith(MEASURED_JAXLIB)


def _cpu_is_the_backend() -> bool:
    """Whether JAX will run on its CPU backend, known without starting it: the first of the
    platforms chosen (``JAX_PLATFORMS``, ``jax_platforms``) is the CPU, or none is chosen
    and no accelerator plugin is installed (JAX finds GPU plugins in the ``jax_plugins``
    namespace or entry points, TPUs through ``libtpu``)."""
    chosen = os.environ.get("JAX_PLATFORMS") or jax.config.jax_platforms or ""
    if chosen:
        return chosen.split(",")[0].strip().lower() == "cpu"
    if importlib.metadata.entry_points(group="jax_plugins"):
        return False
    return all(importlib.util.find_spec(name) is None for name in ("jax_plugins", "libtpu"))


COMPILER_OPTIONS: dict[str, str] | None = (
    {FLAG.strip("-").rstrip("="): ""} if _measured_jaxlib() and _cpu_is_the_backend() else None
)
"""XLA compile options of every program the package compiles (:func:`jit`): the switch,
as one program's option, where JAX runs on its CPU (it was measured there; an accelerator's
compiler is left its own choices); None on a jaxlib not in :data:`MEASURED_JAXLIB`."""


def jit(fun: Callable | None = None, /, **options: Any) -> Any:
    """``jax.jit(fun, **options)`` compiling with :data:`COMPILER_OPTIONS`; also a
    decorator, bare or through ``functools.partial(jit, static_argnames=...)``.

    Only for programs called from the host: traced inside another ``jit`` (or under
    ``vmap`` within one), JAX refuses it (``ValueError``).
    """
    if fun is None:
        return functools.partial(jit, **options)
    return jax.jit(fun, compiler_options=COMPILER_OPTIONS, **options)


def use_xla_kernels() -> bool:
    """Set :data:`FLAG` in ``XLA_FLAGS`` for this process, before JAX starts its backend.

    Returns whether it did: not once JAX has run an operation (its flags are read), where
    ``XLA_FLAGS`` already chooses the YNN fusions, or on a jaxlib not in
    :data:`MEASURED_JAXLIB`.
    """
    flags = os.environ.get("XLA_FLAGS", "")
    if xla_bridge.backends_are_initialized() or "ynn_fusion_type" in flags:
        return False
    if not _measured_jaxlib():
        return False
    os.environ["XLA_FLAGS"] = f"{flags} {FLAG}".strip()
    return True
