"""The NPZ rig: float64 ``K (M, 3, 3)``, ``R (M, 3, 3)``, ``t (M, 3)``, optional ``dist (M, 5)``
or ``fisheye (M, 4)`` and ``image_size (2,)`` (docs/CONVENTIONS.md §3)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._expect import PATH, expect_args
from ..geometry._camera import Rig
from ..geometry._distortion import Fisheye
from ._atomic import atomic_write
from ._read_files import open_npz
from ._rig_files import PathLike, _Views
from ._rig_values import _check_dist, _check_image_size, _host_rig, _tile_size


def read_npz(path: str):
    with open_npz(path) as npz:
        for key in ("K", "R", "t"):
            if key not in npz.files:
                raise ValueError(
                    f'{path}: missing array "{key}" (expected K (M, 3, 3), R (M, 3, 3), t (M, 3))'
                )
        K = _npz_array(npz, "K", path)
        M = K.shape[0] if K.ndim == 3 else -1
        if K.ndim != 3 or K.shape[1:] != (3, 3) or M == 0:
            raise ValueError(
                f'{path}: array "K": expected shape (M, 3, 3) with M >= 1; got {K.shape}'
            )
        R = _npz_array(npz, "R", path)
        t = _npz_array(npz, "t", path)
        if t.shape == (M, 3, 1):
            t = t[..., 0]
        for key, a, shape in (("R", R, (M, 3, 3)), ("t", t, (M, 3))):
            if a.shape != shape:
                raise ValueError(
                    f'{path}: array "{key}": expected shape {shape} (M={M} from K); got {a.shape}'
                )
        dist = None
        if "dist" in npz.files and "fisheye" in npz.files:
            raise ValueError(f'{path}: both arrays "dist" and "fisheye"; a rig has one lens model')
        for key, n in (("dist", 5), ("fisheye", 4)):
            if key in npz.files:
                dist = _npz_array(npz, key, path)
                if dist.shape != (M, n):
                    raise ValueError(
                        f'{path}: array "{key}": expected shape {(M, n)} (M={M} from K); got {dist.shape}'
                    )
        fisheye = "fisheye" in npz.files
        image_size = None
        if "image_size" in npz.files:
            image_size = _check_image_size(
                npz["image_size"].tolist(), f'{path}: array "image_size"'
            )
    for key, a in (("K", K), ("R", R), ("t", t), ("dist", dist)):
        if a is not None:
            bad = ~np.isfinite(a).reshape(M, -1).all(axis=1)
            if bad.any():
                raise ValueError(
                    f'{path}: array "{"fisheye" if key == "dist" and fisheye else key}", view {int(np.argmax(bad))}: non-finite entries'
                )
    return _Views(K, R, t, _tile_size(image_size, M), Fisheye(dist) if fisheye else dist)


def _npz_array(npz, key: str, path: str) -> np.ndarray:
    a = npz[key]
    if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
        raise ValueError(f'{path}: array "{key}": expected real numbers; got dtype {a.dtype}')
    if np.issubdtype(a.dtype, np.floating) and np.finfo(a.dtype).bits < 32:
        raise ValueError(
            f'{path}: array "{key}" has dtype {a.dtype}, too coarse for a camera (about 3 '
            "significant digits); save it as float32 or float64"
        )
    return a.astype(np.float64)


def save_rig_npz(
    path: PathLike, rig: Rig, *, image_size: tuple[int, int] | None = None, dist: Any = None
) -> None:
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
