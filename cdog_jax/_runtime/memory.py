"""Peak memory of the compiled pipeline, known from the shapes before compiling.

The pipeline works on dense tables over the ``N = M·P`` detection slots of a scene: the
epipolar distance table ``d (M, P, M, P)`` and its masked copy (floats), the proposal and
adjacency matrices ``(N, N)`` (bools), and, depending on the method's stages, the second
association's ``(G, M, N)`` member-to-node distances (``G = N/2``), the recovery's
``(G, N, 2)`` reprojection differences and the support filter's ``(G, M, P, 2)`` ones.
Its peak memory is therefore ``c · N²`` bytes plus terms linear in ``N·M``, with ``c`` set
by the float size and the stages. :func:`estimate_peak_bytes` adds these tensors up per
stage (the coefficients were checked against XLA's own ``memory_analysis()`` of the
compiled program, ALGORITHM.md §14); :func:`check_memory` refuses, before anything is
compiled, a call whose estimate exceeds the budget of :func:`memory_budget_bytes`.
"""

from __future__ import annotations

import ctypes
import os

import jax
import numpy as np

from .._method import Method

ENV_BUDGET = "CDOG_JAX_MEMORY_BUDGET"
"""Environment variable: the memory budget in GB (10⁹ bytes), e.g. ``"8"``."""

BUDGET_FRACTION = 0.8
"""Default budget: this share of the accelerator's memory, or of the machine's physical
memory on CPU."""

_MARGIN = 1.1  # the estimate sits 5–40 % above XLA's number on the shapes checked
_BATCH_EXTRA = 1.0  # float tables per scene that vmap adds (a cond runs both branches)


def quadratic_bytes(M: int, method: Method, itemsize: int, batched: bool = False) -> float:
    """Bytes per ``N²`` (``N = M·P``) at the peak of one scene's run of ``method``
    (:meth:`Method.table_bytes`), plus what ``vmap`` adds."""
    coeff = method.table_bytes(M, itemsize)
    if batched:
        coeff += _BATCH_EXTRA * float(itemsize)
    return coeff


def estimate_peak_bytes(
    M: int,
    P: int,
    method: Method,
    *,
    dtype=np.float32,
    batch_size: int = 1,
    vmapped: bool | None = None,
) -> int:
    """Estimated peak bytes of :func:`cdog_jax.associate` on ``M`` views of ``P`` slots, or
    of :func:`cdog_jax.associate_batch` (``vmapped``; default ``batch_size > 1``), which
    runs ``batch_size`` scenes at a time. A pure function of the shapes and the method.s
    structure."""
    itemsize = np.dtype(dtype).itemsize
    N = M * P
    vmapped = batch_size > 1 if vmapped is None else vmapped
    per_scene = (
        quadratic_bytes(M, method, itemsize, batched=vmapped) * N * N + 16.0 * itemsize * M * N
    )
    return int(_MARGIN * batch_size * per_scene)


def physical_memory() -> int | None:
    """This machine's physical memory in bytes, or None where the system does not say."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def memory_budget_bytes(budget_gb: float | None = None) -> tuple[float, str]:
    """The budget in bytes and where it comes from: ``budget_gb`` if given, else the
    environment variable ``CDOG_JAX_MEMORY_BUDGET`` (GB), else ``BUDGET_FRACTION`` of the
    default device's memory limit (accelerators) or of physical memory (CPU); ``inf``
    when none of these is known."""
    if budget_gb is None and os.environ.get(ENV_BUDGET):
        text = os.environ[ENV_BUDGET]
        try:
            budget_gb = float(text)
        except ValueError:
            raise ValueError(f"{ENV_BUDGET} must be a number of GB; got {text!r}") from None
        source = f"{ENV_BUDGET}={text}"
    else:
        source = "memory_budget_gb"
    if budget_gb is not None:
        if not budget_gb > 0:
            raise ValueError(f"the memory budget must be > 0 GB; got {budget_gb!r} ({source})")
        return float(budget_gb) * 1e9, source

    device = jax.devices()[0]
    limit = None
    if device.platform != "cpu":
        stats = device.memory_stats() or {}
        limit = stats.get("bytes_limit")
        where = f"{device.platform} memory"
    if limit is None:
        limit = physical_memory()
        where = "physical memory"
    if limit is None:
        return float("inf"), "unknown memory size"
    return BUDGET_FRACTION * limit, f"{BUDGET_FRACTION:.0%} of {limit / 1e9:.1f} GB {where}"


def largest_capacity(
    M: int, method: Method, dtype, batch_size: int, budget: float, vmapped: bool | None = None
) -> int:
    """The largest ``P`` whose estimate fits ``budget`` bytes (0 if none)."""
    lo, hi = 0, 1
    fits = lambda p: (
        estimate_peak_bytes(M, p, method, dtype=dtype, batch_size=batch_size, vmapped=vmapped)
        <= budget
    )  # noqa: E731
    while fits(hi) and hi < 1 << 40:
        lo, hi = hi, 2 * hi
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    return lo


def check_memory(
    where: str,
    M: int,
    P: int,
    method: Method,
    dtype,
    batch_size: int = 1,
    budget_gb: float | None = None,
    vmapped: bool | None = None,
) -> int:
    """Raise ``MemoryError`` before compiling when the estimate for ``M`` views of ``P`` slots
    (``batch_size`` scenes at a time) exceeds the budget; return the estimate (bytes)."""
    need = estimate_peak_bytes(M, P, method, dtype=dtype, batch_size=batch_size, vmapped=vmapped)
    budget, source = memory_budget_bytes(budget_gb)
    if need <= budget:
        return need
    scenes = f", {batch_size} scenes at a time" if batch_size > 1 else ""
    fit = largest_capacity(M, method, dtype, batch_size, budget, vmapped)
    changes = [
        f"a smaller capacity P (at most {fit} slots per view fits)"
        if fit
        else "a smaller capacity P",
        "fewer views",
    ]
    if batch_size > 1:
        changes.append("a smaller batch_size")
    raise MemoryError(
        f"{where}: {M} views × {P} slots{scenes} need about {need / 1e9:.1f} GB (estimated from the shapes: "
        f"dense tables over the N² = {(M * P) ** 2:.2g} slot pairs), more than the memory budget of "
        f"{budget / 1e9:.1f} GB ({source}). Use "
        + ", ".join(changes)
        + f", or raise the budget (memory_budget_gb=, or the {ENV_BUDGET} environment variable, in GB)."
    )


# The C heap of a long run. glibc gives each thread that allocates its own heap ("arena",
# up to eight per core), and memory freed in one stays mapped until that arena's top is
# free: a recording associated part by part, each part's arrays freed, still grew by a
# quarter of a GiB between its first part and its second (XLA's threads allocate in many
# arenas). And glibc serves a block of more than its mmap threshold from a mapping of its
# own, unmapped when freed, but raises that threshold (up to 32 MiB) each time such a block
# is freed: after the first part the tables of every part came from the arenas, fragmented
# them, and the peak grew with the recording's length (Shelf's 3,010 frames in parts of 500:
# 602 MiB against 495 for its 301). A command's own process therefore caps the arenas and
# fixes the threshold at 1 MiB at the start, and hands the free pages back between parts.
# Nothing here runs for a library call (the process is the user's), and elsewhere than
# glibc (macOS, musl) all three are no-ops.
HEAP_ARENAS = 2
MMAP_THRESHOLD_BYTES = 1 << 20
_M_ARENA_MAX = -8  # glibc's mallopt parameter numbers
_M_MMAP_THRESHOLD = -3


def _glibc():
    """glibc's C library (``ctypes``), or None under another C library."""
    try:
        libc = ctypes.CDLL("libc.so.6")
    except OSError:
        return None
    return libc if hasattr(libc, "malloc_trim") and hasattr(libc, "mallopt") else None


def limit_heap_arenas(count: int = HEAP_ARENAS) -> bool:
    """Let the C heap (glibc) make at most ``count`` arenas from now on; called before any
    thread starts allocating (before JAX starts its backend). True where it took effect."""
    libc = _glibc()
    return bool(libc is not None and libc.mallopt(_M_ARENA_MAX, int(count)))


def map_large_blocks(threshold: int = MMAP_THRESHOLD_BYTES) -> bool:
    """Let the C heap (glibc) serve every block of ``threshold`` bytes or more from a mapping
    of its own, returned to the system when freed (a fixed threshold: glibc's own grows).
    True where it took effect."""
    libc = _glibc()
    return bool(libc is not None and libc.mallopt(_M_MMAP_THRESHOLD, int(threshold)))


def release_freed_memory() -> bool:
    """Hand the C heap's free pages back to the system (glibc's ``malloc_trim``), e.g.
    between the parts of a long recording. True where memory was released."""
    libc = _glibc()
    return bool(libc is not None and libc.malloc_trim(0))
