"""``save_rig``: a rig written in any format that :func:`load_rig` reads (but Qualisys), its
format told from the path as the reader tells it.

Above every format's module, as ``_load_rig.py`` is: each format's writer lives beside its
reader, and this module picks one of them and checks the options it is given.
"""

from __future__ import annotations

import inspect
import os
from typing import Any

from .._expect import PATH, expect_args
from ..geometry._camera import Rig
from ._anipose import save_rig_anipose
from ._colmap import save_rig_colmap
from ._easymocap import save_rig_easymocap
from ._nerfstudio import save_rig_nerfstudio
from ._rig_easyvis import save_rig_easyvis
from ._rig_files import PathLike
from ._rig_json import save_rig_json
from ._rig_npz import save_rig_npz

_WRITERS = {
    "easyvis": save_rig_easyvis,
    "json": save_rig_json,
    "npz": save_rig_npz,
    "anipose": save_rig_anipose,
    "colmap": save_rig_colmap,
    "easymocap": save_rig_easymocap,
    "nerfstudio": save_rig_nerfstudio,
}
WRITTEN_FORMATS = tuple(_WRITERS)
"""The formats :func:`save_rig` writes: every one :func:`load_rig` reads but Qualisys."""


def save_rig(
    path: PathLike,
    rig: Rig,
    *,
    format: str = "auto",
    image_size: Any = None,
    dist: Any = None,
    names: Any = None,
) -> None:
    """Write ``rig`` (``K, R (M, 3, 3)``, ``t (M, 3)``) as a rig file that :func:`load_rig`
    reads back: the same cameras (to float round-off), sizes, distortion and names.

    Formats (docs/CONVENTIONS.md §3; each file written whole or not at all):

    - ``"json"``, ``"npz"``: a file; ``image_size`` and ``dist`` (OpenCV's five
      coefficients ``(M, 5)`` or a :class:`cdog_jax.geometry.Fisheye`) optional.
    - ``"anipose"``: an aniposelib ``calibration.toml``; ``image_size`` needed (aniposelib
      cannot load a camera without one), ``dist`` and ``names`` optional.
    - ``"colmap"``: a folder with a COLMAP text model (``cameras.txt``, ``images.txt``,
      ``points3D.txt``); ``image_size`` needed, ``dist`` and ``names`` optional.
    - ``"easymocap"``: a folder with ``intri.yml`` and ``extri.yml``; ``image_size``,
      ``dist``, ``names`` optional.
    - ``"nerfstudio"``: a ``transforms.json``; ``image_size`` needed.
    - ``"easyvis"``: a folder of ``K{i}.txt``, ``R{i}.txt``, ``T{i}.txt``; cameras only.
    - ``"auto"``: a file named ``transforms.json`` is nerfstudio; ``.json``, ``.npz`` and
      ``.toml`` (anipose) by suffix; a folder's format must be given.

    Args:
        path: the file or folder to write (a folder is made when missing).
        rig: the cameras.
        format: ``"auto"`` or one of ``WRITTEN_FORMATS``.
        image_size: ``(width, height)`` in pixels, shared by all views (``(M, 2)`` per view
            where the format holds one size per camera: anipose, colmap, easymocap,
            nerfstudio).
        dist: ``(M, 5)`` OpenCV distortion or a :class:`~cdog_jax.geometry.Fisheye`.
        names: ``M`` camera names (anipose, colmap, easymocap, nerfstudio).

    Raises ``ValueError`` for an unknown format, a format that cannot be told from the path,
    an option the format cannot hold (nothing given is silently left out) or a needed one
    missing, and whatever the format's writer refuses (naming the file).
    """
    expect_args("save_rig", path=(path, PATH), rig=(rig, Rig))
    path = os.fspath(path)
    fmt = _written_format(path, format)
    writer = _WRITERS[fmt]
    options = inspect.signature(writer).parameters
    given = {
        name: value
        for name, value in (("image_size", image_size), ("dist", dist), ("names", names))
        if value is not None
    }
    held = [name for name in given if name not in options]
    if held:
        raise ValueError(
            f"{path}: the {fmt} format holds no {' or '.join(held)}; leave it out or choose a "
            f"format that holds it"
        )
    needed = [
        name
        for name, p in options.items()
        if p.kind == p.KEYWORD_ONLY and p.default is p.empty and name not in given
    ]
    if needed:
        raise ValueError(f"{path}: the {fmt} format needs {' and '.join(needed)}=")
    writer(path, rig, **given)


def _written_format(path: str, format: str) -> str:
    if format in _WRITERS:
        return format
    if format != "auto":
        raise ValueError(
            f"{path}: cannot write the rig format {format!r}; expected 'auto' or one of "
            f"{WRITTEN_FORMATS}"
        )
    base = os.path.basename(os.path.normpath(path))
    if base == "transforms.json":
        return "nerfstudio"
    suffix = os.path.splitext(base)[1].lower()
    if suffix in (".json", ".npz") and not os.path.isdir(path):
        return suffix[1:]
    if suffix == ".toml" and not os.path.isdir(path):
        return "anipose"
    raise ValueError(
        f"{path}: cannot tell the rig format from the path (a .json, .npz or .toml file, or "
        f"transforms.json); pass format= one of {WRITTEN_FORMATS}"
    )
