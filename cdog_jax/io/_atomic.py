"""Files replaced whole or not at all.

Every writer of the library writes through :func:`atomic_write`: the content goes to a
temporary file in the target's folder, is flushed to disk, and then renamed over the target
(``os.replace``, atomic on POSIX and Windows). A write that fails mid-way (a full disk, an
exception in the serialiser, an interrupt) removes the temporary file and leaves the
previous file, if any, as it was. The new file gets the previous file's permissions, or the
usual ``0o666 & ~umask`` for a new one; a symbolic link is written through (its target is
replaced, the link kept).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from typing import IO, Any

PathLike = str | os.PathLike  # a file name


@contextlib.contextmanager
def atomic_write(
    path: PathLike, mode: str = "w", *, encoding: str | None = None, newline: str | None = None
) -> Iterator[IO[Any]]:
    """Open a temporary file for writing that replaces ``path`` when the block ends without
    an exception; ``mode`` is ``"w"`` (text, ``encoding`` default UTF-8) or ``"wb"``."""
    if mode not in ("w", "wb"):
        raise ValueError(f"mode must be 'w' or 'wb'; got {mode!r}")
    target = os.path.realpath(os.fspath(path))  # through symbolic links, as open() writes
    folder, name = os.path.split(target)
    fd, temporary = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=folder)
    try:
        text = {} if mode == "wb" else {"encoding": encoding or "utf-8", "newline": newline}
        with os.fdopen(fd, mode, **text) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.chmod(temporary, _mode_for(target))
        os.replace(temporary, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
        raise


def atomic_savefig(fig: Any, path: PathLike, **kwargs: Any) -> None:
    """``fig.savefig(path, **kwargs)`` through :func:`atomic_write`; the format is the
    extension of ``path`` (``.png`` when it has none)."""
    ext = os.path.splitext(os.fspath(path))[1].lower().lstrip(".")
    kwargs.setdefault("format", ext or "png")
    with atomic_write(path, "wb") as f:
        fig.savefig(f, **kwargs)


def _mode_for(target: str) -> int:
    """The permission bits the written file should have."""
    try:
        return os.stat(target).st_mode & 0o7777
    except FileNotFoundError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask
