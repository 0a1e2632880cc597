"""A persistent cache of compiled programs: on in the command line, one call in a script.

JAX compiles every new shape and structure on first use: seconds per program on a CPU. A
compiled program is stored on disk and loaded the next time any process needs it, so only
the first run on a machine pays for compilation. Importing ``cdog_jax`` changes no JAX
setting: the command line turns the cache on, a library user calls
:func:`cdog_jax.enable_compilation_cache` once, before the first association.

Where: the per-user cache folder of the platform (``$XDG_CACHE_HOME/cdog_jax`` or
``~/.cache/cdog_jax`` on Linux, ``~/Library/Caches/cdog_jax`` on macOS,
``%LOCALAPPDATA%\\cdog_jax\\Cache`` on Windows), one subfolder per JAX version.
``CDOG_JAX_CACHE_DIR`` moves it; ``CDOG_JAX_CACHE=0`` turns it off (as does the command
line's ``--no-cache``). A cache folder the user already configured through JAX
(``jax_compilation_cache_dir``) is left alone.

What: every program that took at least 0.1 s to compile (a whole pipeline takes seconds);
operations run one at a time outside ``jit`` compile in milliseconds and are not stored.

Safety: JAX keys every entry by the program, the compiler options, the device and the
JAX/XLA versions, so a stale entry is never loaded; entries are size-bounded and the folder
is locked (``filelock``) while an entry is read or written, so concurrent processes share it.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import jax

#: Entries beyond this total size are evicted, least recently used first (bytes).
MAX_CACHE_BYTES = 2 * 1024**3
#: Programs that compile faster than this are not stored (seconds).
MIN_COMPILE_SECONDS = 0.1


def default_cache_dir() -> Path:
    """The per-user cache folder of this platform for cdog_jax (not created here)."""
    if sys.platform == "win32":
        base = (
            Path(os.environ.get("LOCALAPPDATA", Path.home() / "AppData" / "Local"))
            / "cdog_jax"
            / "Cache"
        )
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Caches" / "cdog_jax"
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "cdog_jax"
    return base


def cache_dir_from_environment() -> Path | None:
    """Where compiled programs go according to ``CDOG_JAX_CACHE`` / ``CDOG_JAX_CACHE_DIR``;
    None when the cache is turned off."""
    if os.environ.get("CDOG_JAX_CACHE", "1").strip().lower() in ("0", "false", "no", "off"):
        return None
    root = os.environ.get("CDOG_JAX_CACHE_DIR")
    root = Path(root).expanduser() if root else default_cache_dir()
    return root / f"jax-{jax.__version__}"


def enable_compilation_cache(*, path: str | os.PathLike[str] | None = None) -> Path | None:
    """Store compiled programs on disk and load them in later processes: JAX's persistent
    compilation cache, for this whole process, in ``path`` (default: the per-user cache
    folder, or ``CDOG_JAX_CACHE_DIR``; ``CDOG_JAX_CACHE=0`` makes this call do nothing).

    Returns the folder in use, or None when the cache is off or cannot be created (then
    everything still works, only without reuse across processes). Does nothing when JAX's
    cache folder was already set by the user.
    """
    if jax.config.jax_compilation_cache_dir and path is None:
        return Path(jax.config.jax_compilation_cache_dir)
    folder = Path(path) if path is not None else cache_dir_from_environment()
    if folder is None:
        return None
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None  # read-only home, full disk: run without the cache rather than fail
    jax.config.update("jax_compilation_cache_dir", str(folder))
    # The pipeline's programs compile in 0.3-7 s each, below JAX's 1 s default. Programs of
    # one operation (what running JAX outside jit compiles, 5-50 ms each) are left out: they
    # compile about as fast as they load, and each entry makes every later write slower
    # (below).
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_SECONDS)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    # A size bound turns on JAX's file lock around every read and write of the folder; each
    # write then also reads the size and last use of every entry to evict the oldest.
    jax.config.update("jax_compilation_cache_max_size", MAX_CACHE_BYTES)
    return folder


def disable_compilation_cache() -> None:
    """Stop storing and loading compiled programs (this process)."""
    jax.config.update("jax_compilation_cache_dir", None)
