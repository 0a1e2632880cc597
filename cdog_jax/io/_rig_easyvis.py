"""EasyVis/OpenMVG rig folders: ``K{i}.txt``, ``R{i}.txt`` and ``T{i}.txt`` Python-literal
files, one triple per view (docs/CONVENTIONS.md §3); no image size, no distortion."""

from __future__ import annotations

import ast
import os
import re

import numpy as np

from .._expect import PATH, expect_args
from ..geometry._camera import Rig
from ._atomic import atomic_write
from ._errors import read_text
from ._rig_files import PathLike, _Views
from ._rig_values import _host_rig, _to_array

_EASYVIS_FILE = re.compile(r"^([KRT])(0|[1-9][0-9]*)\.txt$")


def easyvis_files(folder: str) -> list[tuple[str, str, int]]:
    """``(file name, letter, view index)`` of every ``K/R/T{i}.txt`` in ``folder``."""
    out = []
    for name in os.listdir(folder):
        match = _EASYVIS_FILE.match(name)
        if match and os.path.isfile(os.path.join(folder, name)):
            out.append((name, match.group(1), int(match.group(2))))
    return out


def read_easyvis(folder: str):
    if not os.path.isdir(folder):
        raise ValueError(
            f"{folder}: not a folder (the easyvis format is a folder of K/R/T{{i}}.txt files)"
        )
    files = easyvis_files(folder)
    if not files:
        raise ValueError(f"{folder}: no K{{i}}.txt, R{{i}}.txt, T{{i}}.txt files (zero views)")
    present = {(letter, i) for _, letter, i in files}
    M = max(i for _, _, i in files) + 1
    for i in range(M):  # views must be 0 … M-1, each with its three files
        for letter in "KRT":
            if (letter, i) not in present:
                found = sorted({i for _, _, i in files})
                raise ValueError(
                    f"{folder}: missing {letter}{i}.txt (views must be numbered 0…M-1 with K, R and T "
                    f"files each; found view indices {found})"
                )
    K = np.stack([_read_literal(os.path.join(folder, f"K{i}.txt"), (3, 3)) for i in range(M)])
    R = np.stack([_read_literal(os.path.join(folder, f"R{i}.txt"), (3, 3)) for i in range(M)])
    t = np.stack([_read_literal(os.path.join(folder, f"T{i}.txt"), (3,)) for i in range(M)])
    return _Views(K, R, t)


def _read_literal(file: str, shape: tuple[int, ...]) -> np.ndarray:
    """A Python-literal nested list of numbers, checked for shape and finiteness (a ``(3,)``
    vector may also be written as a ``(3, 1)`` column)."""
    text = read_text(file)
    try:
        value = ast.literal_eval(text.strip())
    except (ValueError, SyntaxError, TypeError, MemoryError, RecursionError) as e:
        raise ValueError(f"{file}: not a Python literal ({type(e).__name__}: {e})") from e
    return _to_array(value, shape, file)


def save_rig_easyvis(folder: PathLike, rig: Rig) -> None:
    """Write ``rig`` (``K, R (M, 3, 3)``, ``t (M, 3)``) as ``K{i}.txt``, ``R{i}.txt`` and
    ``T{i}.txt`` (``[[x], [y], [z]]``) Python-literal files in ``folder`` (created if needed).

    The format has no image size and no distortion. Raises ``ValueError`` if the folder
    already holds a ``K/R/T{i}.txt`` with ``i >= M``, which would be read as an extra view.
    """
    expect_args("save_rig_easyvis", folder=(folder, PATH), rig=(rig, Rig))
    K, R, t = _host_rig(rig)
    folder = os.fspath(folder)
    os.makedirs(folder, exist_ok=True)
    M = K.shape[0]
    stale = sorted(name for name, _, i in easyvis_files(folder) if i >= M)
    if stale:
        raise ValueError(
            f"{folder}: holds {stale[0]}, beyond the {M} views of the rig; remove it or use an empty folder"
        )
    for m in range(M):
        for name, a in (("K", K[m]), ("R", R[m]), ("T", t[m][:, None])):
            with atomic_write(os.path.join(folder, f"{name}{m}.txt"), "w") as f:
                f.write(_literal(a) + "\n")


def _literal(a: np.ndarray) -> str:
    """A float64 array as a Python-literal nested list, every number as its exact ``repr``."""
    if a.ndim == 1:
        return "[" + ", ".join(repr(float(x)) for x in a) + "]"
    return "[" + ", ".join(_literal(row) for row in a) + "]"
