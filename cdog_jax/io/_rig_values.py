"""The values of rig files, checked and converted the same way by every format: nested lists
as arrays, image sizes, lens models, camera names, ``K / K[2,2]``, and a rig as float64
host arrays for the writers (docs/CONVENTIONS.md §1)."""

from __future__ import annotations

import re
from typing import Any

import numpy as np

from ..geometry._camera import Rig
from ..geometry._distortion import Fisheye
from ._errors import InputError, too_large


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
        raise ValueError(
            f"{where}: expected a nested list of numbers of shape {shape}; got ragged lists"
        ) from e
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
        not isinstance(v, bool)
        and isinstance(v, (int, float, np.integer, np.floating))
        and float(v).is_integer()
        and v >= 1
        for v in values
    )
    if not ok:
        raise ValueError(f"{where}: expected (width, height), two positive integers; got {size!r}")
    return int(values[0]), int(values[1])


def _tile_size(size: tuple[int, int] | None, M: int) -> np.ndarray | None:
    """One ``(width, height)`` for all views as ``view_sizes (M, 2)``."""
    return None if size is None else np.tile(np.asarray(size, dtype=np.int64), (M, 1))


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
            raise ValueError(
                "image_size is required by this format: (width, height) or (M, 2) per view"
            )
        return None
    a = np.asarray(image_size)
    if a.shape == (2,):
        return np.tile(
            np.asarray(_check_image_size(a.tolist(), "image_size"), dtype=np.int64), (M, 1)
        )
    if a.shape != (M, 2):
        raise ValueError(
            f"image_size must be (width, height) or have shape (M, 2) = {(M, 2)}; got shape {a.shape}"
        )
    return np.array(
        [_check_image_size(row.tolist(), f"image_size[{m}]") for m, row in enumerate(a)],
        dtype=np.int64,
    )


def _check_names(
    names: Any, M: int, default: str, pattern: str | None = None, rule: str = ""
) -> tuple[str, ...]:
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
        raise ValueError(
            f"K of view {int(np.argmax(zero))} has K[2,2] = 0; cannot write it in this format"
        )
    return K / K[:, 2:3, 2:3]


def _host_rig(rig: Rig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rig as float64 host arrays (exact widening), checked to be one finite rig."""
    K, R, t = (np.asarray(a, dtype=np.float64) for a in (rig.K, rig.R, rig.t))
    if K.ndim != 3:
        raise ValueError(
            f"expected one rig with K of shape (M, 3, 3); got {K.shape} (a batch of rigs?)"
        )
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
            raise ValueError(
                f"Fisheye coefficients must have shape (M, 4) = {(M, 4)}; got {coeffs.shape}"
            )
        if not np.isfinite(coeffs).all():
            raise ValueError("Fisheye coefficients have non-finite entries; cannot write them")
        return Fisheye(coeffs)
    dist = np.asarray(dist, dtype=np.float64)
    if dist.shape != (M, 5):
        raise ValueError(f"dist must have shape (M, 5) = {(M, 5)}; got {dist.shape}")
    if not np.isfinite(dist).all():
        raise ValueError("dist has non-finite entries; cannot write it")
    return dist
