"""Reading the JSON and NPZ files of every reader (rigs, detections, keypoints, results):
errors that name the file (and the array), never a pickle."""

from __future__ import annotations

import difflib
import json
import re
import sys
import zipfile
import zlib
from collections.abc import Iterable
from typing import Any

import numpy as np

from ._errors import InputError, check_regular_file, read_text


class DuplicateKeyError(ValueError):
    """A JSON object names one key twice (``args[0]``: the key)."""


def unique_keys(pairs: list[tuple[str, Any]]) -> dict:
    """An object's members as a dict; a key given twice is refused (JSON readers would keep
    the last one silently)."""
    out = dict(pairs)
    if len(out) != len(pairs):
        seen = set()
        raise DuplicateKeyError(next(k for k, _ in pairs if k in seen or seen.add(k)))
    return out


def check_keys(obj: dict, known: Iterable[str], where: str, what: str = "key") -> None:
    """Every key of the JSON object ``obj`` (or column of a table, ``what="column"``) is one
    of ``known``: an unknown one (a misspelt ``"distortion"`` for ``"dist"``) raises
    :class:`InputError` naming the nearest known one, rather than being dropped with what it
    held."""
    known = tuple(known)
    for key in obj:
        if key not in known:
            near = difflib.get_close_matches(str(key), known, n=1, cutoff=0.5)
            hint = f' (did you mean "{near[0]}"?)' if near else ""
            raise InputError(
                f'{where}: unknown {what} "{key}"{hint}; the {what}s read here are '
                + ", ".join(f'"{k}"' for k in known)
            )


def read_json(path: str) -> Any:
    """The parsed JSON file. Raises :class:`InputError` naming the file for invalid JSON, a
    key given twice in one object, a byte that is not UTF-8 (with its offset), nesting
    deeper than Python's recursion limit, and an integer with more digits than Python reads
    (4300); a missing file stays ``FileNotFoundError``."""
    text = read_text(path)
    try:
        return json.loads(text, object_pairs_hook=unique_keys)
    except DuplicateKeyError as e:
        raise InputError(
            f'{path}: the key "{e.args[0]}" appears twice in one object; which one is meant?'
        ) from None
    except json.JSONDecodeError as e:
        raise InputError(f"{path}: not valid JSON ({e})") from None
    except RecursionError:
        raise InputError(
            f"{path}: not readable JSON: brackets nested too deeply (deeper than Python's recursion limit)"
        ) from None
    except ValueError as e:  # an integer beyond sys.get_int_max_str_digits()
        found = re.search(r"value has (\d+) digits", str(e))
        digits = (
            f"an integer has {found.group(1)} digits" if found else "an integer has too many digits"
        )
        raise InputError(
            f"{path}: not readable JSON: {digits}; at most {sys.get_int_max_str_digits()} are read"
        ) from None


def open_npz(path: str) -> _NpzFile:
    """``np.load`` of an ``.npz`` without pickles. An unreadable file, or an array that is
    unreadable or holds Python objects, raises :class:`InputError` naming the file (and the
    array); a missing file stays ``FileNotFoundError``, a folder ``IsADirectoryError``."""
    check_regular_file(path)
    try:
        return _NpzFile(np.load(path, allow_pickle=False), path)
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as e:
        if isinstance(e, (FileNotFoundError, IsADirectoryError)):
            raise
        raise InputError(f"{path}: not a readable .npz file ({e})") from None


class _NpzFile:
    """An open ``.npz`` whose arrays are read with errors that name the file and array."""

    def __init__(self, npz: Any, path: str):
        if not hasattr(npz, "files"):  # np.load of a single .npy array
            raise InputError(f"{path}: a single .npy array, not an .npz archive of named arrays")
        self._npz, self._path = npz, path
        self.files = npz.files

    def __getitem__(self, key: str) -> np.ndarray:
        try:
            return self._npz[key]
        except ValueError as e:
            if "allow_pickle" in str(e):
                raise InputError(
                    f'{self._path}: array "{key}" holds Python objects (an object array, readable only by unpickling, '
                    "which is not done); save it as an array of numbers"
                ) from None
            raise InputError(f'{self._path}: array "{key}" is unreadable ({e})') from None
        except (OSError, EOFError, zipfile.BadZipFile, zlib.error) as e:
            raise InputError(
                f'{self._path}: array "{key}" is unreadable ({type(e).__name__}: {e})'
            ) from None

    def __enter__(self) -> _NpzFile:
        return self

    def __exit__(self, *exc: object) -> None:
        self._npz.close()
