"""The ``cdog-jax`` command line (also ``python -m cdog_jax``): the parser and the entry point.

One module per command, each with ``add_parser(subparsers)`` that declares its arguments
and sets ``func`` to its ``run(args) -> int``; register new ones in ``_SUBCOMMANDS``.

Commands:
    demo       built-in rig → synthetic scene → :func:`cdog_jax.associate` → summary, metrics
               (docs/BENCHMARK.md §2), timings and a PNG figure; ``--save-scene`` writes files
               (``_demo_command.py``).
    benchmark  the benchmark grid (docs/BENCHMARK.md §1) for several methods, one compiled program per bucket → tables, saved
               results, figures (``_benchmark_command.py``).
    calibrate  perturb the built-in rig, refine it from associations, before/after table and
               a convergence figure (``_calibrate_command.py``).
    associate  your rig file and detections file → groups, 3D points (JSON/NPZ/CSV), figure.
    rig        describe a rig file (centres, directions, baselines, warnings), draw it
               (both in ``_associate_command.py``).
    track      frames streamed as JSON lines on standard input → one JSON line per frame
               (groups, track ids, 3D points), flushed as each frame is done
               (``_track_command.py``).

Errors: a user error (a bad file, path or value: ``ValueError``, which includes
:class:`cdog_jax.io.InputError`, and ``OSError``) prints one line ``cdog-jax: error: <file>:
<what>`` on stderr and exits 2, as argparse's usage errors do; ``--debug`` shows its
traceback instead. Any other exception is a bug of the library and keeps its traceback.
Outputs are checked (``_paths.py``) and every file is written atomically
(``cdog_jax/io/_atomic.py``) before and while the work runs. The argument types and
checks the commands share are in ``_common.py``. Each command imports the heavy parts of
the library (JAX programs, matplotlib) only when it runs, so ``--help`` stays fast.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from .._runtime.compile_cache import disable_compilation_cache, enable_compilation_cache
from .._runtime.memory import limit_heap_arenas, map_large_blocks
from .._runtime.xla_kernels import use_xla_kernels
from .._version import __version__
from . import (
    _associate_command,
    _benchmark_command,
    _calibrate_command,
    _demo_command,
    _track_command,
)

_SUBCOMMANDS = (
    _demo_command.add_parser,
    _benchmark_command.add_parser,
    _calibrate_command.add_parser,
    _associate_command.add_parsers,
    _track_command.add_parser,
)


def build_parser() -> argparse.ArgumentParser:
    """The ``cdog-jax`` parser with every subcommand of ``_SUBCOMMANDS``."""
    parser = argparse.ArgumentParser(
        prog="cdog-jax",
        description="C-DOG multi-view multi-instance point association in JAX.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.add_argument("--debug", action="store_true", help=_DEBUG_HELP)
    parser.add_argument("--no-cache", action="store_true", help=_NO_CACHE_HELP)
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in _SUBCOMMANDS:
        add(subparsers)
    for sub in subparsers.choices.values():  # also accepted after the command's name
        sub.add_argument(
            "--debug", action="store_true", default=argparse.SUPPRESS, help=_DEBUG_HELP
        )
        sub.add_argument(
            "--no-cache", action="store_true", default=argparse.SUPPRESS, help=_NO_CACHE_HELP
        )
    return parser


_DEBUG_HELP = "on an error, show the Python traceback instead of one line"
_NO_CACHE_HELP = "neither load nor store compiled programs on disk (as CDOG_JAX_CACHE=0)"


def main(argv: Sequence[str | os.PathLike[str]] | None = None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``; paths may be
    ``os.PathLike``); returns the exit code: 0, or 2 for a user error (one line on stderr)."""
    args = build_parser().parse_args(None if argv is None else [str(a) for a in argv])
    if argv is None:  # the process's own command line: batches may use every core
        # (the benchmark's package: loaded here, by the process's own command line only)
        from ..benchmark._cpu_cores import use_cpu_cores

        limit_heap_arenas()  # the process's C heap stays compact over a long recording
        map_large_blocks()  # and its large tables go back to the system when freed
        use_xla_kernels()  # XLA's own kernels for small sums and products: faster here
        use_cpu_cores(count=_cpu_devices_from_environment())

    if args.no_cache:
        disable_compilation_cache()
    else:
        enable_compilation_cache()  # importing the package leaves JAX's settings alone
    try:
        return args.func(args)
    # A bad file, path or value, or a scene too large for memory; other exceptions are bugs.
    except (ValueError, OSError, MemoryError) as e:
        if args.debug:
            raise
        print(f"cdog-jax: error: {_one_line(e)}", file=sys.stderr, flush=True)
        return 2


def _cpu_devices_from_environment() -> int | None:
    """``CDOG_JAX_CPU_DEVICES`` (a count; 1: one device, as a library call runs), or None:
    the usable cores."""
    text = os.environ.get("CDOG_JAX_CPU_DEVICES", "").strip()
    return int(text) if text.isdigit() and int(text) > 0 else None


def _one_line(error: Exception) -> str:
    """The message of a user error on one line; an ``OSError`` as ``"<file>: <reason>"``."""
    if isinstance(error, OSError) and error.strerror:
        files = [os.fspath(f) for f in (error.filename, error.filename2) if f is not None]
        text = ": ".join([*files, error.strerror])
    else:
        text = str(error) or type(error).__name__
    return " ".join(line.strip() for line in text.splitlines() if line.strip())
