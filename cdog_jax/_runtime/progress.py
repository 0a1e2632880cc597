"""Progress of the long jobs (benchmark, calibrate, many-frame associate), one way for all.

Bars are tqdm's, drawn on stderr, and only when stderr is a terminal: in a log, a pipe or a
test nothing is drawn (``CDOG_JAX_PROGRESS=1`` forces them on, ``=0`` off). A job that is
compiling says so with a live line and its elapsed time, because the first call of a
jitted program can be silent for tens of seconds otherwise.
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Any


def interactive() -> bool:
    """Whether progress is shown: ``CDOG_JAX_PROGRESS`` if set (``0``/``1``), else whether
    stderr is a terminal."""
    forced = os.environ.get("CDOG_JAX_PROGRESS", "").strip()
    if forced in ("0", "1"):
        return forced == "1"
    stream = sys.stderr
    return bool(getattr(stream, "isatty", None) and stream.isatty())


def bar(total: int | None, desc: str, unit: str = "it", **options: Any) -> Any:
    """A tqdm bar on stderr, disabled (every call a no-op) when not :func:`interactive`;
    ``options`` go to ``tqdm``."""
    # tqdm loads with the first progress bar
    from tqdm import tqdm

    return tqdm(
        total=total,
        desc=desc,
        unit=unit,
        file=sys.stderr,
        disable=not interactive(),
        leave=True,
        dynamic_ncols=True,
        **options,
    )


@contextlib.contextmanager
def compiling(what: str) -> Iterator[None]:
    """A live line ``compiling <what> … 12s`` while the block runs (refreshed twice a
    second from a thread), replaced by ``compiled <what> in 12.3 s`` at its end; nothing
    when not :func:`interactive`."""
    if not interactive():
        yield
        return
    line = bar(None, f"compiling {what}", unit="s", bar_format="{desc} … {elapsed}")
    stop = threading.Event()

    def tick() -> None:
        while not stop.wait(0.5):
            line.refresh()

    thread = threading.Thread(target=tick, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()
        elapsed = line.format_dict["elapsed"]
        line.set_description_str(f"compiled {what} in {elapsed:.1f} s")
        line.bar_format = "{desc}"
        line.close()


def sweep_bar(num_scenes: int) -> tuple[Callable[[Any], None], Callable[[], None]]:
    """``(callback, close)`` for :func:`cdog_jax.benchmark.sweep`'s ``progress=``: a bar
    over the grid's scenes, advanced as each capacity bucket finishes."""
    scenes = bar(num_scenes, "sweep: buckets of scenes", unit="scene")

    def callback(p: Any) -> None:
        scenes.set_description_str(
            f"sweep: bucket {p.bucket + 1}/{p.num_buckets} (capacity {p.capacity}) done"
        )
        scenes.update(p.scenes_done - scenes.n)

    return callback, scenes.close
