"""What is wrong with a file, a path or a value the user gave: :class:`InputError`, where in
a file of detections it is (:class:`_Where`), and reading text files so that a bad byte is
reported with its file and offset."""

from __future__ import annotations

import os
import stat
from typing import NamedTuple


class InputError(ValueError):
    """A problem with the user's input (a file's content, a path, a command-line value),
    not with the library. The message starts with where: ``"<file>: <what>"``, with the
    frame, view, detection, key or line after the file when they are known. The command
    line prints it as one line, ``cdog-jax: error: <message>``."""


class _Where(NamedTuple):
    """Formats "file: frame f, view m, detection i: text" (frame only for lists of frames)."""

    source: str | None
    frames: bool
    first_frame: int = 0  # a part of a recording: its frame 0 is this frame of the whole

    def loc(self, f: int | None = None, m: int | None = None, i: int | None = None) -> str:
        parts = []
        if self.frames and f is not None:
            parts.append(f"frame {f + self.first_frame}")
        if m is not None:
            parts.append(f"view {m}")
        if i is not None:
            parts.append(f"detection {i}")
        return ", ".join(parts)

    def error(
        self, text: str, f: int | None = None, m: int | None = None, i: int | None = None
    ) -> ValueError:
        head = [s for s in (self.source, self.loc(f, m, i)) if s]
        return InputError(": ".join([*head, text]))


MAX_INPUT_BYTES = 2**31
"""The largest file a reader reads whole (2 GiB): a rig, a detections file, a table."""


def check_regular_file(path: str | os.PathLike) -> None:
    """Refuse, before reading, a ``path`` that is not a regular file (a FIFO would block
    forever, a device such as ``/dev/zero`` read until memory runs out) or that is larger
    than :data:`MAX_INPUT_BYTES`. A missing file or a folder is left to ``open``."""
    try:
        info = os.stat(path)
    except OSError:
        return
    if stat.S_ISDIR(info.st_mode):
        return
    if not stat.S_ISREG(info.st_mode):
        raise InputError(
            f"{os.fspath(path)}: not a regular file (a pipe, a device or a socket); "
            "files are read whole, so they must be regular files"
        )
    if info.st_size > MAX_INPUT_BYTES:
        raise InputError(
            f"{os.fspath(path)}: {info.st_size:,} bytes; a file read whole may hold at most "
            f"{MAX_INPUT_BYTES:,} bytes"
        )


def read_text(path: str | os.PathLike) -> str:
    """The UTF-8 text of ``path``, without the byte-order mark that spreadsheets and some
    Windows editors put first; a byte that is not UTF-8 raises :class:`InputError` with the
    file and the byte's offset (from 0)."""
    check_regular_file(path)
    with open(path, "rb") as f:
        data = f.read()
    try:
        text = data.decode("utf-8")
        return text[1:] if text.startswith("\ufeff") else text
    except UnicodeDecodeError as e:
        raise InputError(
            f"{os.fspath(path)}: not UTF-8 text: byte {e.start} (0x{data[e.start]:02x}) cannot be decoded ({e.reason}); "
            "save the file as UTF-8"
        ) from None


def too_large(value: int) -> str:
    """How to say that the integer ``value`` does not fit a float64."""
    digits = len(str(abs(value)))
    return (
        f"the integer {str(value)[:12]}… ({digits} digits) is too large for a floating-point number"
    )
