"""Rig files (docs/CONVENTIONS.md §3): EasyVis/OpenMVG text folders, the project's JSON, NPZ, and the
helpers that the modules of the other formats share (anipose ``calibration.toml``, COLMAP
text models, EasyMocap ``intri.yml``/``extri.yml``, nerfstudio ``transforms.json``,
Qualisys); ``load_rig``, above them all, is in ``_load_rig.py``.

Every reader returns the convention of docs/CONVENTIONS.md §1: world→camera ``X_cam = R X_world + t``
with ``R`` a 3×3 rotation matrix (rows are the camera axes in world coordinates: x right,
y down, z forward), pixels ``x ~ K X_cam`` divided by the third homogeneous coordinate,
so a general upper-triangular ``K`` (``K[2,2] = -1`` included) is kept as it is. Pixel
coordinates are those of the rest of the library: x right, y down, pixel centres at
integer coordinates (OpenCV). ``dist`` holds OpenCV distortion ``(k1, k2, p1, p2, k3)``
(zeros when a file gives none) or a :class:`cdog_jax.geometry.Fisheye` (OpenCV's fisheye
``k1 … k4``); it is read and written, and applied only where it is passed on
(``associate(dist=…)``, ``project(dist=…)``, ``triangulate(dist=…)``).

Precision: files are parsed to float64 on the host; the :class:`Rig` gets ``dtype``
(default: JAX's default float, float32 unless x64 is enabled), as :func:`rig_from_arrays`.
Writers widen the rig to float64 (exact) and write every number with ``repr``, so a saved
rig loads back bit-identical in its own dtype (up to the conversions a format forces:
Rodrigues vectors, quaternions, COLMAP's half-pixel shift, ``K / K[2,2]``).
"""

from __future__ import annotations

import ast
import json
import os
import re
import sys
import zipfile
import zlib
from typing import Any, NamedTuple

import numpy as np

from .._expect import PATH, expect_args
from ..geometry._camera import Rig, rig_from_arrays
from ..geometry._distortion import Fisheye
from ._atomic import atomic_write
from ._errors import InputError, read_text, too_large

PathLike = str | os.PathLike  # a folder or file name

FORMATS = ("easyvis", "json", "npz", "anipose", "colmap", "easymocap", "nerfstudio", "qualisys")
_EASYVIS_FILE = re.compile(r"^([KRT])(0|[1-9][0-9]*)\.txt$")


class RigFile(NamedTuple):
    """What a rig file holds.

    Attributes:
        rig: the ``M`` cameras, ``K, R (M, 3, 3)``, ``t (M, 3)``.
        image_size: ``(width, height)`` in pixels shared by all views, or ``None`` when the
            file gives none or when its views have different sizes (see ``view_sizes``).
        dist: ``(M, 5)`` float64 OpenCV distortion ``(k1, k2, p1, p2, k3)`` (zeros when
            the file gives none), or a :class:`cdog_jax.geometry.Fisheye` of ``(M, 4)``
            float64 coefficients for fisheye lenses. Not applied by the reader.
        view_sizes: ``(M, 2)`` int64 ``(width, height)`` of every view, or ``None`` when
            the file gives no sizes.
        names: the camera names in view order, or ``None`` when the file has none.
    """

    rig: Rig
    image_size: tuple[int, int] | None
    dist: np.ndarray | Fisheye
    view_sizes: np.ndarray | None = None
    names: tuple[str, ...] | None = None

    def select(self, names: Any) -> "RigFile":
        """The views named ``names`` (a sequence of camera names), in that order.

        Match cameras by name, never by position, when two tools order them differently:
        e.g. aniposelib's ``CameraGroup.load`` orders ``[cam_10]`` before ``[cam_2]`` (string
        order) while :func:`load_rig` reads sections in numeric order.
        ``rig_file.select(camera_group.get_names())`` gives aniposelib's order.
        """
        if self.names is None:
            raise ValueError("this rig has no camera names; select views by index with rig.select(views)")
        if isinstance(names, str):
            raise TypeError(f"names must be a sequence of camera names, not the string {names!r}")
        index = {n: m for m, n in enumerate(self.names)}
        missing = [n for n in names if str(n) not in index]
        if missing:
            raise ValueError(f"camera {missing[0]!r} is not in this rig; its cameras are {list(self.names)}")
        views = np.array([index[str(n)] for n in names], dtype=np.int64)
        dist = Fisheye(self.dist.coeffs[views]) if isinstance(self.dist, Fisheye) else self.dist[views]
        sizes = None if self.view_sizes is None else self.view_sizes[views]
        image_size = None
        if sizes is not None and len(sizes) and (sizes == sizes[0]).all():
            image_size = (int(sizes[0, 0]), int(sizes[0, 1]))
        return RigFile(self.rig.select(views), image_size, dist, sizes, tuple(self.names[m] for m in views))


class _Views(NamedTuple):
    """What a reader returns: float64 ``K, R (M, 3, 3)``, ``t (M, 3)``, and optional int
    ``view_sizes (M, 2)``, ``dist (M, 5)`` (or a :class:`Fisheye` of float64 ``(M, 4)``)
    and names."""

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    view_sizes: np.ndarray | None = None
    dist: np.ndarray | Fisheye | None = None
    names: tuple[str, ...] | None = None


def check_rig_dtype(dtype: Any, function: str) -> None:
    """Refuse ``float64`` while JAX is 32-bit: it would quietly give a float32 rig."""
    import jax

    if dtype is not None and np.dtype(dtype).itemsize == 8 and not jax.config.jax_enable_x64:
        raise ValueError(
            f"{function}: dtype={np.dtype(dtype).name} needs 64-bit JAX, which is off (the rig would be float32); "
            'call jax.config.update("jax_enable_x64", True) first, or leave dtype=None'
        )


def rig_file_from_views(views: _Views, dtype: Any, path: str) -> RigFile:
    """The :class:`RigFile` of a reader's views: the rig checked and in ``dtype``, zeros for
    a missing ``dist``, the common image size. ``path`` names the source in errors."""
    _check_float_range(views, dtype, path)
    try:
        rig = rig_from_arrays(views.K, views.R, views.t, dtype=dtype)
    except ValueError as e:
        raise ValueError(f"{path}: {_name_views(str(e), views.names)}") from e
    image_size = None
    if views.view_sizes is not None and (views.view_sizes == views.view_sizes[0]).all():
        image_size = (int(views.view_sizes[0, 0]), int(views.view_sizes[0, 1]))
    dist = np.zeros((views.K.shape[0], 5)) if views.dist is None else views.dist
    return RigFile(rig, image_size, dist, views.view_sizes, views.names)


def _check_float_range(views: _Views, dtype: Any, path: str) -> None:
    """Refuse numbers the rig's float type cannot hold (they would turn infinite)."""
    import jax.numpy as jnp

    dtype = np.dtype(dtype or jnp.asarray(0.0).dtype)
    largest = float(np.finfo(dtype).max)
    for key, a in (("K", views.K), ("R", views.R), ("t", views.t)):
        bad = (np.abs(a) > largest).reshape(a.shape[0], -1).any(axis=1)
        if bad.any():
            m = int(np.argmax(bad))
            raise InputError(
                f"{path}: {_name_views(f'view {m}', views.names)}: {key} has entries out of {dtype.name} range "
                f"(largest {largest:.4g}): {a[m].ravel()[np.abs(a[m].ravel()) > largest][0]:g}"
            )


def _name_views(message: str, names: tuple[str, ...] | None) -> str:
    """``"… view 3 …"`` → ``"… view 3 (camera 'c3') …"`` when the file names its cameras."""
    if names is None:
        return message
    return re.sub(r"\bview (\d+)\b", lambda m: f"{m.group(0)} (camera {names[int(m.group(1))]!r})", message, count=1)


def save_rig_json(path: PathLike, rig: Rig, *, image_size: tuple[int, int] | None = None, dist: Any = None) -> None:
    """Write ``rig`` (``K, R (M, 3, 3)``, ``t (M, 3)``) as the project's JSON rig.

    One object per view ``{"K": 3×3, "R": 3×3, "t": [3]}``, plus ``"image_size": [w, h]``
    and ``"dist": [5]`` (OpenCV ``k1, k2, p1, p2, k3``, ``dist (M, 5)``) or ``"fisheye":
    [4]`` (a :class:`cdog_jax.geometry.Fisheye`) when given. Numbers are written exactly
    (float64 ``repr``).
    """
    expect_args("save_rig_json", path=(path, PATH), rig=(rig, Rig))
    K, R, t = _host_rig(rig)
    size = _check_image_size(image_size, "image_size")
    dist = _check_dist(dist, K.shape[0])
    views = []
    for m in range(K.shape[0]):
        view: dict[str, Any] = {"K": K[m].tolist(), "R": R[m].tolist(), "t": t[m].tolist()}
        if isinstance(dist, Fisheye):
            view["fisheye"] = dist.coeffs[m].tolist()
        elif dist is not None:
            view["dist"] = dist[m].tolist()
        if size is not None:
            view["image_size"] = list(size)
        views.append(json.dumps(view, allow_nan=False))
    with atomic_write(path, "w") as f:
        f.write('{"views": [\n  ' + ",\n  ".join(views) + "\n]}\n")


def save_rig_npz(path: PathLike, rig: Rig, *, image_size: tuple[int, int] | None = None, dist: Any = None) -> None:
    """Write ``rig`` as NPZ: float64 ``K (M, 3, 3)``, ``R (M, 3, 3)``, ``t (M, 3)``, and
    ``dist (M, 5)`` (or ``fisheye (M, 4)`` for a :class:`cdog_jax.geometry.Fisheye`) and
    int ``image_size (2,)`` (width, height) when given."""
    expect_args("save_rig_npz", path=(path, PATH), rig=(rig, Rig))
    K, R, t = _host_rig(rig)
    arrays = {"K": K, "R": R, "t": t}
    size = _check_image_size(image_size, "image_size")
    dist = _check_dist(dist, K.shape[0])
    if size is not None:
        arrays["image_size"] = np.asarray(size, dtype=np.int64)
    if isinstance(dist, Fisheye):
        arrays["fisheye"] = dist.coeffs
    elif dist is not None:
        arrays["dist"] = dist
    with atomic_write(path, "wb") as f:  # a file object: np.savez would append ".npz" to a str path
        np.savez(f, **arrays)


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
        raise ValueError(f"{folder}: holds {stale[0]}, beyond the {M} views of the rig; remove it or use an empty folder")
    for m in range(M):
        for name, a in (("K", K[m]), ("R", R[m]), ("T", t[m][:, None])):
            with atomic_write(os.path.join(folder, f"{name}{m}.txt"), "w") as f:
                f.write(_literal(a) + "\n")


# Readers ---------------------------------------------------------------------------------


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
        raise ValueError(f"{folder}: not a folder (the easyvis format is a folder of K/R/T{{i}}.txt files)")
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


def read_json(path: str) -> Any:
    """The parsed JSON file. Raises :class:`InputError` naming the file for invalid JSON, a
    byte that is not UTF-8 (with its offset), nesting deeper than Python's recursion limit,
    and an integer with more digits than Python reads (4300); a missing file stays
    ``FileNotFoundError``."""
    text = read_text(path)
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise InputError(f"{path}: not valid JSON ({e})") from None
    except RecursionError:
        raise InputError(f"{path}: not readable JSON: brackets nested too deeply (deeper than Python's recursion limit)") from None
    except ValueError as e:  # an integer beyond sys.get_int_max_str_digits()
        found = re.search(r"value has (\d+) digits", str(e))
        digits = f"an integer has {found.group(1)} digits" if found else "an integer has too many digits"
        raise InputError(f"{path}: not readable JSON: {digits}; at most {sys.get_int_max_str_digits()} are read") from None


def read_json_rig(path: str):
    data = read_json(path)
    if not isinstance(data, dict) or "views" not in data:
        raise ValueError(f'{path}: missing key "views" (expected {{"views": [{{"K", "R", "t"}}, …]}})')
    views = data["views"]
    if not isinstance(views, list) or not views:
        raise ValueError(f'{path}: "views" must be a non-empty list of view objects')
    K, R, t, dists, sizes = [], [], [], [], []
    for m, view in enumerate(views):
        where = f"{path}: view {m}"
        if not isinstance(view, dict):
            raise ValueError(f"{where}: expected an object with keys K, R, t; got {type(view).__name__}")  # noqa: TRY004 (bad file content, not a bad argument)
        for key in ("K", "R", "t"):
            if key not in view:
                raise ValueError(f'{where}: missing key "{key}"')
        K.append(_to_array(view["K"], (3, 3), f'{where}, key "K"'))
        R.append(_to_array(view["R"], (3, 3), f'{where}, key "R"'))
        t.append(_to_array(view["t"], (3,), f'{where}, key "t"'))
        if "dist" in view and "fisheye" in view:
            raise ValueError(f'{where}: both "dist" and "fisheye"; a view has one lens model')
        if "fisheye" in view:
            dists.append(("fisheye", _to_array(view["fisheye"], (4,), f'{where}, key "fisheye"')))
        else:
            dists.append(_to_array(view["dist"], (5,), f'{where}, key "dist"') if "dist" in view else None)
        sizes.append(_check_image_size(view["image_size"], f'{where}, key "image_size"') if "image_size" in view else None)
    given = {s for s in sizes if s is not None}
    if len(given) > 1:
        raise ValueError(f'{path}: views give different "image_size" values {sorted(given)}; expected one for all views')
    image_size = given.pop() if given else None
    return _Views(np.stack(K), np.stack(R), np.stack(t), _tile_size(image_size, len(K)), stack_dists(dists, path))


def open_npz(path: str) -> _NpzFile:
    """``np.load`` of an ``.npz`` without pickles. An unreadable file, or an array that is
    unreadable or holds Python objects, raises :class:`InputError` naming the file (and the
    array); a missing file stays ``FileNotFoundError``, a folder ``IsADirectoryError``."""
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
            raise InputError(f'{self._path}: array "{key}" is unreadable ({type(e).__name__}: {e})') from None

    def __enter__(self) -> _NpzFile:
        return self

    def __exit__(self, *exc: object) -> None:
        self._npz.close()


def read_npz(path: str):
    with open_npz(path) as npz:
        for key in ("K", "R", "t"):
            if key not in npz.files:
                raise ValueError(f'{path}: missing array "{key}" (expected K (M, 3, 3), R (M, 3, 3), t (M, 3))')
        K = _npz_array(npz, "K", path)
        M = K.shape[0] if K.ndim == 3 else -1
        if K.ndim != 3 or K.shape[1:] != (3, 3) or M == 0:
            raise ValueError(f'{path}: array "K": expected shape (M, 3, 3) with M >= 1; got {K.shape}')
        R = _npz_array(npz, "R", path)
        t = _npz_array(npz, "t", path)
        if t.shape == (M, 3, 1):
            t = t[..., 0]
        for key, a, shape in (("R", R, (M, 3, 3)), ("t", t, (M, 3))):
            if a.shape != shape:
                raise ValueError(f'{path}: array "{key}": expected shape {shape} (M={M} from K); got {a.shape}')
        dist = None
        if "dist" in npz.files and "fisheye" in npz.files:
            raise ValueError(f'{path}: both arrays "dist" and "fisheye"; a rig has one lens model')
        for key, n in (("dist", 5), ("fisheye", 4)):
            if key in npz.files:
                dist = _npz_array(npz, key, path)
                if dist.shape != (M, n):
                    raise ValueError(f'{path}: array "{key}": expected shape {(M, n)} (M={M} from K); got {dist.shape}')
        fisheye = "fisheye" in npz.files
        image_size = None
        if "image_size" in npz.files:
            image_size = _check_image_size(npz["image_size"].tolist(), f'{path}: array "image_size"')
    for key, a in (("K", K), ("R", R), ("t", t), ("dist", dist)):
        if a is not None:
            bad = ~np.isfinite(a).reshape(M, -1).all(axis=1)
            if bad.any():
                raise ValueError(f'{path}: array "{"fisheye" if key == "dist" and fisheye else key}", view {int(np.argmax(bad))}: non-finite entries')
    return _Views(K, R, t, _tile_size(image_size, M), Fisheye(dist) if fisheye else dist)


def _tile_size(size: tuple[int, int] | None, M: int) -> np.ndarray | None:
    """One ``(width, height)`` for all views as ``view_sizes (M, 2)``."""
    return None if size is None else np.tile(np.asarray(size, dtype=np.int64), (M, 1))


def _npz_array(npz, key: str, path: str) -> np.ndarray:
    a = npz[key]
    if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
        raise ValueError(f'{path}: array "{key}": expected real numbers; got dtype {a.dtype}')
    return a.astype(np.float64)


def _to_array(value: Any, shape: tuple[int, ...], where: str) -> np.ndarray:
    """Nested lists of real numbers (no strings, no booleans) as a float64 array of ``shape``;
    a ``(3,)`` vector may come as a ``(3, 1)`` column."""

    def check(v):
        if isinstance(v, (list, tuple)):
            return [check(x) for x in v]
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ValueError(f"{where}: expected a nested list of numbers; found {v!r}")  # noqa: TRY004
        try:
            return float(v)
        except OverflowError:
            raise InputError(f"{where}: {too_large(v)}") from None

    try:
        a = np.array(check(value), dtype=np.float64)
    except RecursionError:
        raise InputError(f"{where}: lists nested too deeply; expected shape {shape}") from None
    except ValueError as e:
        if str(e).startswith(where):
            raise
        raise ValueError(f"{where}: expected a nested list of numbers of shape {shape}; got ragged lists") from e
    if shape == (3,) and a.shape == (3, 1):
        a = a[:, 0]
    if a.shape != shape:
        expected = f"{shape}" + (" or (3, 1)" if shape == (3,) else "")
        raise ValueError(f"{where}: expected shape {expected}; got {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{where}: non-finite entries")
    return a


def _check_image_size(size: Any, where: str) -> tuple[int, int] | None:
    if size is None:
        return None
    values = list(size) if isinstance(size, (list, tuple, np.ndarray)) else [size]
    ok = len(values) == 2 and all(
        not isinstance(v, bool) and isinstance(v, (int, float, np.integer, np.floating)) and float(v).is_integer() and v >= 1
        for v in values
    )
    if not ok:
        raise ValueError(f"{where}: expected (width, height), two positive integers; got {size!r}")
    return int(values[0]), int(values[1])


# Writers ---------------------------------------------------------------------------------


def _host_rig(rig: Rig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rig as float64 host arrays (exact widening), checked to be one finite rig."""
    K, R, t = (np.asarray(a, dtype=np.float64) for a in (rig.K, rig.R, rig.t))
    if K.ndim != 3:
        raise ValueError(f"expected one rig with K of shape (M, 3, 3); got {K.shape} (a batch of rigs?)")
    for name, a in (("K", K), ("R", R), ("t", t)):
        if not np.isfinite(a).all():
            raise ValueError(f"{name} has non-finite entries; cannot write it")
    return K, R, t


def _check_dist(dist: Any, M: int) -> np.ndarray | Fisheye | None:
    """``dist (M, 5)`` or a :class:`Fisheye` of ``(M, 4)``, as float64 host arrays."""
    if dist is None:
        return None
    if isinstance(dist, Fisheye):
        coeffs = np.asarray(dist.coeffs, dtype=np.float64)
        if coeffs.shape != (M, 4):
            raise ValueError(f"Fisheye coefficients must have shape (M, 4) = {(M, 4)}; got {coeffs.shape}")
        if not np.isfinite(coeffs).all():
            raise ValueError("Fisheye coefficients have non-finite entries; cannot write them")
        return Fisheye(coeffs)
    dist = np.asarray(dist, dtype=np.float64)
    if dist.shape != (M, 5):
        raise ValueError(f"dist must have shape (M, 5) = {(M, 5)}; got {dist.shape}")
    if not np.isfinite(dist).all():
        raise ValueError("dist has non-finite entries; cannot write it")
    return dist


def _literal(a: np.ndarray) -> str:
    """A float64 array as a Python-literal nested list, every number as its exact ``repr``."""
    if a.ndim == 1:
        return "[" + ", ".join(repr(float(x)) for x in a) + "]"
    return "[" + ", ".join(_literal(row) for row in a) + "]"


# Helpers shared by the format modules ----------------------------------------------------


def stack_dists(dists: list, where: str) -> np.ndarray | Fisheye | None:
    """Per-view lens models as one: ``None`` (no view gives one), ``(M, 5)`` OpenCV
    coefficients (zeros for a view without), or a :class:`Fisheye` when every view is
    ``("fisheye", (4,))``. Mixing the two models in one rig raises."""
    if all(d is None for d in dists):
        return None
    fisheye = [isinstance(d, tuple) for d in dists]
    if any(fisheye):
        if not all(fisheye):
            m = fisheye.index(not fisheye[0])
            raise ValueError(
                f"{where}: view 0 is {'a fisheye' if fisheye[0] else 'an OpenCV (k1, k2, p1, p2, k3)'} lens and view {m} "
                "is not; one rig has one lens model"
            )
        return Fisheye(np.stack([d[1] for d in dists]))
    return np.stack([np.zeros(5) if d is None else d for d in dists])


def _opencv_dist(a: np.ndarray, where: str) -> np.ndarray:
    """4 or 5 OpenCV coefficients (a vector, or a 1×N / N×1 matrix) as ``(k1, k2, p1, p2, k3)``,
    ``k3 = 0`` when only four are given."""
    a = np.asarray(a, dtype=np.float64).reshape(-1)
    if a.size in (4, 5):
        return np.concatenate([a, np.zeros(5 - a.size)])
    if a.size == 8 and not np.any(a[5:]):
        return a[:5]  # the rational model with k4 = k5 = k6 = 0 is the 5-coefficient one
    extra = " (rational, thin-prism and tilted models are not supported)" if a.size > 5 else ""
    raise ValueError(
        f"{where}: expected 4 or 5 OpenCV distortion coefficients (k1, k2, p1, p2[, k3]); got {a.size}{extra}"
    )


def _check_view_sizes(image_size: Any, M: int, *, required: bool = False) -> np.ndarray | None:
    """``image_size`` as ``(M, 2)`` int64 ``(width, height)``: one ``(w, h)`` for all views, or
    one per view."""
    if image_size is None:
        if required:
            raise ValueError("image_size is required by this format: (width, height) or (M, 2) per view")
        return None
    a = np.asarray(image_size)
    if a.shape == (2,):
        return np.tile(np.asarray(_check_image_size(a.tolist(), "image_size"), dtype=np.int64), (M, 1))
    if a.shape != (M, 2):
        raise ValueError(f"image_size must be (width, height) or have shape (M, 2) = {(M, 2)}; got shape {a.shape}")
    return np.array([_check_image_size(row.tolist(), f"image_size[{m}]") for m, row in enumerate(a)], dtype=np.int64)


def _check_names(names: Any, M: int, default: str, pattern: str | None = None, rule: str = "") -> tuple[str, ...]:
    """``M`` distinct camera names (``default.format(m)`` when ``None``), each matching
    ``pattern`` (a regular expression, described by ``rule``) when given."""
    if names is None:
        return tuple(default.format(m) for m in range(M))
    if isinstance(names, str) or len(names) != M or not all(isinstance(n, str) for n in names):
        raise ValueError(f"names must be {M} strings, one per view; got {names!r}")
    for m, name in enumerate(names):
        if pattern is not None and not re.fullmatch(pattern, name):
            raise ValueError(f"names[{m}] = {name!r}: {rule}")
    if len(set(names)) != M:
        raise ValueError(f"names must be distinct; got {list(names)}")
    return tuple(names)


def _K_over_K22(K: np.ndarray) -> np.ndarray:
    """``K / K[2,2]`` per view (same projection; the tools these formats serve assume
    ``K[2,2] = 1``)."""
    zero = K[:, 2, 2] == 0
    if zero.any():
        raise ValueError(f"K of view {int(np.argmax(zero))} has K[2,2] = 0; cannot write it in this format")
    return K / K[:, 2:3, 2:3]
