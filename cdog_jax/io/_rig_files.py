"""Rig files (docs/CONVENTIONS.md §3): what one holds (:class:`RigFile`) and how the views a
format's reader returns become one. Each format has its module: the project's JSON
(``_rig_json.py``) and NPZ (``_rig_npz.py``), EasyVis/OpenMVG folders (``_rig_easyvis.py``),
anipose ``calibration.toml``, COLMAP text models, EasyMocap ``intri.yml``/``extri.yml``,
nerfstudio ``transforms.json`` and Qualisys; the values they share are checked in
``_rig_values.py``; ``load_rig``, above them all, dispatches in ``_load_rig.py``.

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

import os
import re
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..geometry._camera import (
    ROUNDING_PX_LIMIT,
    Rig,
    centres_on_host,
    rig_from_arrays,
    rounding_px,
)
from ..geometry._distortion import Fisheye
from ._errors import InputError

PathLike = str | os.PathLike  # a folder or file name

FORMATS = ("easyvis", "json", "npz", "anipose", "colmap", "easymocap", "nerfstudio", "qualisys")


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
        origin: ``(3,)`` float64, the world point that is the rig's origin (``origin=``
            of the reader): the rig and its associations' 3D points are in world
            coordinates less it; ``None``: the file's own world.
    """

    rig: Rig
    image_size: tuple[int, int] | None
    dist: np.ndarray | Fisheye
    view_sizes: np.ndarray | None = None
    names: tuple[str, ...] | None = None
    origin: np.ndarray | None = None

    def select(self, names: Any) -> RigFile:
        """The views named ``names`` (a sequence of camera names), in that order.

        Match cameras by name, never by position, when two tools order them differently:
        e.g. aniposelib's ``CameraGroup.load`` orders ``[cam_10]`` before ``[cam_2]`` (string
        order) while :func:`load_rig` reads sections in numeric order.
        ``rig_file.select(camera_group.get_names())`` gives aniposelib's order.
        """
        if self.names is None:
            raise ValueError(
                "this rig has no camera names; select views by index with rig.select(views)"
            )
        if isinstance(names, str):
            raise TypeError(f"names must be a sequence of camera names, not the string {names!r}")
        index = {n: m for m, n in enumerate(self.names)}
        missing = [n for n in names if str(n) not in index]
        if missing:
            raise ValueError(
                f"camera {missing[0]!r} is not in this rig; its cameras are {list(self.names)}"
            )
        views = np.array([index[str(n)] for n in names], dtype=np.int64)
        dist = (
            Fisheye(self.dist.coeffs[views]) if isinstance(self.dist, Fisheye) else self.dist[views]
        )
        sizes = None if self.view_sizes is None else self.view_sizes[views]
        image_size = None
        if sizes is not None and len(sizes) and (sizes == sizes[0]).all():
            image_size = (int(sizes[0, 0]), int(sizes[0, 1]))
        return RigFile(
            self.rig.select(views),
            image_size,
            dist,
            sizes,
            tuple(self.names[m] for m in views),
            self.origin,
        )


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
    if dtype is not None and np.dtype(dtype).itemsize == 8 and not jax.config.jax_enable_x64:
        raise ValueError(
            f"{function}: dtype={np.dtype(dtype).name} needs 64-bit JAX, which is off (the rig would be float32); "
            'call jax.config.update("jax_enable_x64", True) first, or leave dtype=None'
        )


def rig_file_from_views(views: _Views, dtype: Any, path: str, origin: Any = None) -> RigFile:
    """The :class:`RigFile` of a reader's views: the rig checked and in ``dtype``, zeros for
    a missing ``dist``, the common image size. ``path`` names the source in errors.
    ``origin``: ``None``, ``(3,)`` a world point, ``"cameras"`` (the cameras' mean centre),
    or ``"auto"`` (the cameras' mean centre where ``dtype`` cannot hold the rig in its own
    world, else ``None``), subtracted from the world in float64 (see
    :func:`cdog_jax.rig_from_arrays`)."""
    if isinstance(origin, str):
        if origin not in ("cameras", "auto"):
            raise ValueError(
                f"origin must be 'cameras', 'auto' or 3 numbers (x, y, z); got {origin!r}"
            )

        far = (
            rounding_px(views.K, views.R, views.t, np.dtype(dtype or jnp.asarray(0.0).dtype))
            > ROUNDING_PX_LIMIT
        )
        origin = (
            centres_on_host(views.R, views.t).mean(axis=0) if origin == "cameras" or far else None
        )
    _check_float_range(views, dtype, path)
    if views.names is not None:
        names = list(views.names)
        twice = next((n for k, n in enumerate(names) if n in names[:k]), None)
        if twice is not None:
            views_of = [m for m, n in enumerate(names) if n == twice]
            raise InputError(
                f"{path}: two cameras are named {twice!r} (views {views_of[0]} and "
                f"{views_of[1]}); selecting cameras by name could not tell them apart"
            )
    try:
        rig = rig_from_arrays(views.K, views.R, views.t, dtype=dtype, origin=origin)
    except ValueError as e:
        message = str(e).replace("as origin=", "as origin= (or origin='cameras')")
        raise ValueError(f"{path}: {_name_views(message, views.names)}") from e
    image_size = None
    if views.view_sizes is not None and (views.view_sizes == views.view_sizes[0]).all():
        image_size = (int(views.view_sizes[0, 0]), int(views.view_sizes[0, 1]))
    dist = np.zeros((views.K.shape[0], 5)) if views.dist is None else views.dist
    if origin is not None:
        origin = np.asarray(origin, np.float64)
    return RigFile(rig, image_size, dist, views.view_sizes, views.names, origin)


def _check_float_range(views: _Views, dtype: Any, path: str) -> None:
    """Refuse numbers the rig's float type cannot hold (they would turn infinite)."""
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
    return re.sub(
        r"\bview (\d+)\b",
        lambda m: f"{m.group(0)} (camera {names[int(m.group(1))]!r})",
        message,
        count=1,
    )
