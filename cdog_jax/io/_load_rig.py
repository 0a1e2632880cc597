"""``load_rig``: a rig file of any format (docs/CONVENTIONS.md §3), its format told from the path.

Above every format's module: the readers share the helpers of ``_rig_files.py`` and this
module picks one of them.
"""

from __future__ import annotations

import os
from typing import Any

from .._expect import PATH, expect_args
from ._anipose import read_anipose
from ._colmap import read_colmap
from ._easymocap import read_easymocap
from ._errors import InputError
from ._nerfstudio import read_nerfstudio
from ._qualisys import read_qualisys
from ._rig_easyvis import easyvis_files, read_easyvis
from ._rig_files import FORMATS, PathLike, RigFile, check_rig_dtype, rig_file_from_views
from ._rig_json import read_json_rig
from ._rig_npz import read_npz


def load_rig(
    path: PathLike, *, format: str = "auto", dtype: Any = None, origin: Any = None
) -> RigFile:
    """Read a rig file: ``K, R (M, 3, 3)``, ``t (M, 3)`` and optional sizes, distortion, names.

    Formats (all read into world→camera ``X_cam = R X + t``, ``K`` general, OpenCV pixels):

    - ``"easyvis"``: a folder of ``K{i}.txt``, ``R{i}.txt`` (3×3 Python-literal nested
      lists) and ``T{i}.txt`` (``[[x], [y], [z]]`` or ``[x, y, z]``), ``i = 0 … M-1``;
      other files are ignored. Parsed with ``ast.literal_eval``. No image size, no ``dist``.
    - ``"json"``: ``{"views": [{"K", "R", "t", "dist" (optional, 5) or "fisheye"
      (optional, 4: OpenCV's fisheye k1…k4), "image_size" (optional, [w, h])}, …]}``;
      views without ``dist`` get zeros.
    - ``"npz"``: ``K (M, 3, 3)``, ``R (M, 3, 3)``, ``t (M, 3)``, optional ``dist (M, 5)``
      or ``fisheye (M, 4)``, and ``image_size (2,)``.
    - ``"anipose"``: an aniposelib ``calibration.toml`` (see :func:`read_anipose`).
    - ``"colmap"``: a COLMAP text model, ``cameras.txt`` + ``images.txt`` (see
      :func:`read_colmap`); COLMAP's half-pixel principal point is shifted to OpenCV's.
    - ``"easymocap"``: EasyMocap ``intri.yml`` + ``extri.yml`` (see :func:`read_easymocap`).
    - ``"nerfstudio"``: a nerfstudio ``transforms.json`` (see :func:`read_nerfstudio`).
    - ``"qualisys"``: a Qualisys ``.qca.txt`` calibration, as Pose2Sim reads it (see
      :func:`read_qualisys`); scene units metres.
    - ``"auto"``: ``.qca.txt`` is qualisys; a file named ``transforms.json`` is nerfstudio; ``.json``, ``.npz``,
      ``.toml`` (anipose) by suffix; ``cameras.txt`` or
      ``images.txt`` (COLMAP) and ``intri.yml`` or ``extri.yml`` (EasyMocap) by name, their
      folder being read; a folder holding ``cameras.txt`` and ``images.txt`` is COLMAP, one
      holding ``intri.yml`` and ``extri.yml`` is EasyMocap, any other folder is EasyVis.

    Args:
        path: the folder or file.
        format: ``"auto"`` or one of :data:`FORMATS`.
        dtype: float dtype of the rig (default: JAX's default float). ``float64`` needs
            64-bit JAX (``jax.config.update("jax_enable_x64", True)``), else it raises.
        origin: a world point ``(x, y, z)``, or ``"cameras"`` for the cameras' mean centre,
            that becomes the rig's origin (:attr:`RigFile.origin`): subtracted in float64
            before the rig is rounded to ``dtype``, for a rig far from its world origin
            (UTM-like coordinates), which float32 cannot hold; add it to 3D points.
            ``"auto"``: the cameras' mean centre only where ``dtype`` cannot hold the rig.

    Returns:
        A :class:`RigFile`; ``image_size`` is the common size when all views agree, else
        ``None`` (``view_sizes`` has every view's); ``dist`` is zeros when the file gives
        none. Raises ``ValueError`` naming the file
        (and view, camera, line or key) for an unreadable file, a missing view or key, a
        wrong shape, a non-finite number, a singular ``K``, a ``R`` that is not a rotation,
        or cameras too far from the origin for ``dtype`` (it names the ``origin`` to give).
    """
    expect_args("load_rig", path=(path, PATH))
    check_rig_dtype(dtype, "load_rig")
    path = os.fspath(path)
    fmt = _resolve_format(path, format)
    readers = {
        "easyvis": read_easyvis,
        "json": read_json_rig,
        "npz": read_npz,
        "anipose": read_anipose,
        "colmap": read_colmap,
        "easymocap": read_easymocap,
        "nerfstudio": read_nerfstudio,
        "qualisys": read_qualisys,
    }
    views = readers[fmt](path)
    return rig_file_from_views(views, dtype, path, origin)


def _resolve_format(path: str, format: str) -> str:
    if format in FORMATS:
        return format
    if format != "auto":
        raise ValueError(
            f"{path}: unknown rig format {format!r}; expected 'auto' or one of {FORMATS}"
        )
    if os.path.isdir(path):
        entries = set(os.listdir(path))
        if {"cameras.txt", "images.txt"} <= entries:
            return "colmap"
        if {"intri.yml", "extri.yml"} <= entries:
            return "easymocap"
        if {"cameras.bin", "images.bin"} <= entries:
            raise ValueError(
                f"{path}: a binary COLMAP model (cameras.bin, images.bin); only text models are read: "
                "convert it with `colmap model_converter --output_type TXT`"
            )
        suffix = os.path.splitext(os.path.normpath(path))[1].lower()
        if suffix in (".json", ".npz", ".toml") and not easyvis_files(path):
            raise InputError(f"{path}: is a folder; a {suffix} rig is a file")
        return "easyvis"
    base = os.path.basename(path)
    if base.lower().endswith((".qca.txt", ".qca")):
        return "qualisys"
    if base == "transforms.json":
        return "nerfstudio"
    if base in ("cameras.txt", "images.txt"):
        return "colmap"
    if base in ("intri.yml", "extri.yml"):
        return "easymocap"
    suffix = os.path.splitext(path)[1].lower()
    if suffix in (".json", ".npz"):
        return suffix[1:]
    if suffix == ".toml":
        return "anipose"
    raise ValueError(
        f"{path}: cannot tell the rig format; expected a folder (easyvis, or colmap with cameras.txt and "
        "images.txt, or easymocap with intri.yml and extri.yml), a .json, .npz or .toml (anipose) file, transforms.json (nerfstudio), a .qca.txt (qualisys) "
        f"(or pass format= one of {FORMATS})"
    )
