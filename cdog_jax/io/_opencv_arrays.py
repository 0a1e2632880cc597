"""Rigs from and to plain OpenCV arrays, one set per camera: ``K, dist, rvec, tvec,
image_size`` (what ``cv2.calibrateCamera`` / ``cv2.stereoCalibrate`` / ``cv2.solvePnP``
give and ``cv2.projectPoints`` takes).

Convention (OpenCV's): ``rvec`` is the Rodrigues vector (axis × angle, radians) of the
world→camera rotation, ``X_cam = R X_world + tvec``; camera axes x right, y down, z
forward; pixel centres at integer coordinates; ``dist`` is ``(k1, k2, p1, p2[, k3])`` or,
for ``cv2.fisheye``, ``(k1, k2, k3, k4)`` with ``fisheye=True``; ``image_size`` is
``(width, height)``.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from ..geometry._camera import Rig
from ..geometry._distortion import Fisheye
from ._rig_files import RigFile, _Views, check_rig_dtype, rig_file_from_views
from ._rig_values import _check_dist, _check_names, _check_view_sizes, _host_rig, _opencv_dist
from ._rotations import rodrigues_from_rotation, rotation_from_rodrigues


class OpenCVCameras(NamedTuple):
    """A rig as OpenCV arrays (float64; ``M`` cameras).

    Attributes:
        K: ``(M, 3, 3)`` camera matrices (``K[2,2] = 1``).
        dist: ``(M, 5)`` ``(k1, k2, p1, p2, k3)``, or ``(M, 4)`` fisheye ``(k1, k2, k3, k4)``.
        rvec: ``(M, 3)`` Rodrigues vectors of the world→camera rotations.
        tvec: ``(M, 3)`` world→camera translations.
        image_size: ``(M, 2)`` int64 ``(width, height)``, or ``None``.
        fisheye: whether ``dist`` is ``cv2.fisheye``'s model.
    """

    K: np.ndarray
    dist: np.ndarray
    rvec: np.ndarray
    tvec: np.ndarray
    image_size: np.ndarray | None
    fisheye: bool


def rig_from_opencv(
    K: Any,
    dist: Any,
    rvec: Any,
    tvec: Any,
    *,
    image_size: Any = None,
    fisheye: bool = False,
    names: Any = None,
    dtype: Any = None,
    origin: Any = None,
) -> RigFile:
    """A :class:`RigFile` from OpenCV arrays, one entry per camera (sequences or stacked).

    Args:
        K: ``M`` camera matrices ``(3, 3)``.
        dist: ``M`` coefficient vectors: 4, 5 or 8 (``k4 = k5 = k6 = 0``) OpenCV
            coefficients, or 4 fisheye ones with ``fisheye=True``; ``None``: no distortion.
        rvec, tvec: ``M`` Rodrigues vectors and translations (``(3,)`` or ``(3, 1)``).
        image_size: ``(width, height)`` for all, ``M`` of them, or ``None``.
        fisheye: ``dist`` is ``cv2.fisheye``'s ``(k1, k2, k3, k4)``.
        names: ``M`` camera names, or ``None``.
        dtype: float dtype of the rig (default: JAX's default float).
        origin: a world point, or ``"cameras"``, that becomes the rig's origin (see
            :func:`cdog_jax.io.load_rig`).

    Returns:
        The rig ``X_cam = Rodrigues(rvec) X + tvec`` with ``dist (M, 5)`` or a
        :class:`cdog_jax.geometry.Fisheye`; ``ValueError`` names the camera of a bad entry.
    """
    check_rig_dtype(dtype, "rig_from_opencv")
    K = _per_camera(K, (3, 3), "K")
    M = K.shape[0]
    rvec = _per_camera(rvec, (3,), "rvec", M)
    tvec = _per_camera(tvec, (3,), "tvec", M)
    R = np.stack([rotation_from_rodrigues(r) for r in rvec])
    lens: Any = None
    if dist is not None:
        rows = [np.asarray(d, dtype=np.float64).reshape(-1) for d in dist]
        if len(rows) != M:
            raise ValueError(
                f"dist: expected {M} coefficient vectors (one per camera, M={M} from K); got {len(rows)}"
            )
        if fisheye:
            bad = [m for m, d in enumerate(rows) if d.size != 4]
            if bad:
                raise ValueError(
                    f"dist[{bad[0]}]: fisheye=True takes 4 coefficients (k1, k2, k3, k4); got {rows[bad[0]].size}"
                )
            lens = Fisheye(np.stack(rows))
        else:
            lens = np.stack([_opencv_dist(d, f"dist[{m}]") for m, d in enumerate(rows)])
        coeffs = lens.coeffs if fisheye else lens
        if not np.isfinite(coeffs).all():
            raise ValueError(
                f"dist[{int(np.argwhere(~np.isfinite(coeffs))[0, 0])}]: non-finite coefficients"
            )
    sizes = _check_view_sizes(image_size, M)
    names = None if names is None else _check_names(names, M, "")
    return rig_file_from_views(
        _Views(K, R, tvec, sizes, lens, names), dtype, "rig_from_opencv", origin
    )


def opencv_from_rig(rig: Rig, *, dist: Any = None, image_size: Any = None) -> OpenCVCameras:
    """``rig`` as OpenCV arrays (:class:`OpenCVCameras`), ready for ``cv2.projectPoints(X,
    rvec[m], tvec[m], K[m], dist[m])`` (or ``cv2.fisheye.projectPoints``).

    ``K`` is ``K / K[2,2]`` (same projection; OpenCV assumes ``K[2,2] = 1``). ``dist``:
    ``(M, 5)``, a :class:`cdog_jax.geometry.Fisheye`, or ``None`` (zeros).
    """
    K, R, t = _host_rig(rig)
    M = K.shape[0]
    lens = _check_dist(dist, M)
    fisheye = isinstance(lens, Fisheye)
    coeffs = lens.coeffs if fisheye else (np.zeros((M, 5)) if lens is None else lens)
    rvec = np.stack([rodrigues_from_rotation(r) for r in R])
    return OpenCVCameras(
        K / K[:, 2:3, 2:3], coeffs, rvec, t, _check_view_sizes(image_size, M), fisheye
    )


def _per_camera(values: Any, shape: tuple[int, ...], name: str, M: int | None = None) -> np.ndarray:
    """``M`` arrays of ``shape`` (a ``(3,)`` vector may be ``(3, 1)``) as one float64 array."""
    try:
        rows = [np.asarray(v, dtype=np.float64) for v in values]
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name}: expected one array of numbers per camera ({e})") from None
    if M is not None and len(rows) != M:
        raise ValueError(
            f"{name}: expected {M} entries (one per camera, M={M} from K); got {len(rows)}"
        )
    if not rows:
        raise ValueError(f"{name}: no cameras")
    for m, a in enumerate(rows):
        if shape == (3,) and a.shape in ((3, 1), (1, 3)):
            rows[m] = a = a.reshape(3)
        if a.shape != shape:
            raise ValueError(f"{name}[{m}]: expected shape {shape}; got {a.shape}")
        if not np.isfinite(a).all():
            raise ValueError(f"{name}[{m}]: non-finite entries")
    return np.stack(rows)
