"""Checks of the command line's paths before any work: inputs exist and have the right kind,
outputs can be written and are never one of the inputs.

An output is refused when its extension is not one the command writes, when it is a folder,
when its folder does not exist or is not writable, when it is an existing read-only file, or
when it is the same file as any input (compared by ``os.path.samefile``, so also through
other spellings, symbolic and hard links), including every file of a rig folder; two
outputs of one command must differ. Every refusal is an :class:`~cdog_jax.io.InputError`
``"<path>: <flag> …"``.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Mapping

from ..io._errors import InputError

# Files a rig path stands for: the rig formats that read a whole folder when given one file.
_FOLDER_FILES = ("cameras.txt", "images.txt", "intri.yml", "extri.yml")


def check_input(path: str, flag: str, *, kind: str = "file") -> None:
    """``path`` exists, is readable and is a file (``kind="file"``), a folder
    (``"folder"``) or either (``"any"``)."""
    if not os.path.exists(path):
        raise InputError(f"{path}: {flag}: does not exist")
    if kind == "file" and os.path.isdir(path):
        raise InputError(f"{path}: {flag}: is a folder; expected a file")
    if kind == "folder" and not os.path.isdir(path):
        raise InputError(f"{path}: {flag}: not a folder")
    if not os.access(path, os.R_OK):
        raise InputError(f"{path}: {flag}: not readable (permissions)")


def input_files(path: str) -> list[str]:
    """The files that reading ``path`` may read: the file itself, or every file of the
    folder (a rig folder, or the folder of ``cameras.txt``/``intri.yml`` …)."""
    folder = path if os.path.isdir(path) else None
    if folder is None and os.path.basename(path) in _FOLDER_FILES:
        folder = os.path.dirname(path) or "."
    if folder is None:
        return [path]
    return [os.path.join(folder, name) for name in sorted(os.listdir(folder))]


def check_output(
    path: str, flag: str, extensions: Iterable[str], inputs: Mapping[str, Iterable[str]]
) -> None:
    """``path`` can be written as ``flag`` (one of ``extensions``, lower case with the dot)
    and is none of the files of ``inputs`` (flag → files)."""
    extensions = tuple(extensions)
    ext = os.path.splitext(path)[1].lower()
    if ext not in extensions:
        raise InputError(
            f"{path}: {flag}: the extension must be one of {', '.join(extensions)}; got {ext or 'none'!r}"
        )
    if os.path.isdir(path):
        raise InputError(f"{path}: {flag}: is a folder; expected a file name")
    _check_not_dangling(path, flag)
    _check_folder_writable(path, flag, os.path.dirname(os.path.abspath(path)))
    _check_not_read_only(path, flag)
    for in_flag, files in inputs.items():
        for file in files:
            if _same_file(path, file):
                same = "" if os.path.abspath(file) == os.path.abspath(path) else f" ({file})"
                raise InputError(
                    f"{path}: {flag} is the same file as the input {in_flag}{same}; refusing to overwrite an input"
                )


def _check_not_dangling(path: str, flag: str) -> None:
    """``path`` is not a symbolic link to nothing (writing through it would fail at the end,
    after all the work)."""
    if os.path.islink(path) and not os.path.exists(path):
        raise InputError(
            f"{path}: {flag}: a symbolic link to {os.readlink(path)!r}, which does not exist"
        )


def _check_not_read_only(path: str, flag: str) -> None:
    """An existing ``path`` may be replaced: writable for this user and not read-only by its
    mode bits (root may write anything, but a file no one may write was meant to be kept)."""
    if os.path.exists(path) and (not os.access(path, os.W_OK) or not os.stat(path).st_mode & 0o222):
        raise InputError(
            f"{path}: {flag}: the file exists and is read-only; it is kept (choose another name)"
        )


def check_output_folder(
    folder: str,
    flag: str,
    names: Iterable[str],
    inputs: Mapping[str, Iterable[str]],
    *,
    replace: bool = True,
) -> None:
    """``folder`` is a folder that exists and is writable, or can be created in a writable
    folder; none of the files ``names`` it will get is an input or read-only, and with
    ``replace=False`` none exists yet."""
    _check_not_dangling(folder, flag)
    if os.path.exists(folder):
        if not os.path.isdir(folder):
            raise InputError(f"{folder}: {flag}: not a folder (the results are a folder of files)")
        if not os.access(folder, os.W_OK | os.X_OK):
            raise InputError(f"{folder}: {flag}: the folder is not writable")
    else:
        _check_folder_writable(folder, flag, os.path.dirname(os.path.abspath(folder)))
    for name in names:
        path = os.path.join(folder, name)
        _check_not_dangling(path, flag)
        if not replace and os.path.lexists(path):
            raise InputError(
                f"{path}: {flag} would replace {name}, which is already there; choose another "
                "folder or pass --force"
            )
        _check_not_read_only(path, flag)
        for in_flag, files in inputs.items():
            if any(_same_file(path, file) for file in files):
                raise InputError(
                    f"{path}: {flag} would overwrite {name}, the input {in_flag}; choose another folder"
                )


def check_distinct(outputs: Mapping[str, str | None]) -> None:
    """No two of ``outputs`` (flag → path or ``None``) are the same file."""
    given = [(flag, path) for flag, path in outputs.items() if path is not None]
    for k, (flag, path) in enumerate(given):
        for other_flag, other in given[k + 1 :]:
            if _same_file(path, other):
                raise InputError(
                    f"{path}: {flag} and {other_flag} are the same file; give two names"
                )


def write_output(path: str, flag: str, write: Callable[[], object]) -> None:
    """Run ``write()``, which writes the output ``path`` (atomically); an ``OSError`` (a
    full disk) becomes an :class:`InputError` naming the file and saying the previous one
    is unchanged."""
    try:
        write()
    except OSError as e:
        raise InputError(
            f"{path}: {flag}: could not write it ({e.strerror or e}); any previous file is unchanged"
        ) from e


def _check_folder_writable(path: str, flag: str, folder: str) -> None:
    if not os.path.exists(folder):
        raise InputError(f"{path}: {flag}: the folder {folder} does not exist")
    if not os.path.isdir(folder):
        raise InputError(f"{path}: {flag}: {folder} is not a folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"{path}: {flag}: the folder {folder} is not writable")


def _same_file(a: str, b: str) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet)
        return os.path.realpath(a) == os.path.realpath(b)
