"""Rigs from and to an aniposelib ``CameraGroup``, in memory (aniposelib is optional:
imported only by :func:`aniposelib_from_rig`).

Convention (aniposelib's ``Camera``, which projects with ``cv2.projectPoints``):
``get_rotation()`` is the Rodrigues vector of the world→camera rotation, ``X_cam = R X +
get_translation()``; OpenCV axes and pixels; ``get_distortions()`` are OpenCV's ``(k1, k2,
p1, p2[, k3])``, or ``(k1, k2, k3, k4)`` for a ``FisheyeCamera``; ``get_size()`` is
``(width, height)``. Views keep the group's camera order; names are ``get_name()``.
"""

from __future__ import annotations

from typing import Any

from ..geometry._camera import Rig
from ._opencv_arrays import opencv_from_rig, rig_from_opencv
from ._rig_files import RigFile
from ._rig_values import _check_names


def rig_from_aniposelib(camera_group: Any, *, dtype: Any = None) -> RigFile:
    """A :class:`RigFile` from an aniposelib ``CameraGroup`` (anything with ``.cameras``
    whose items have aniposelib's ``Camera`` getters), in the group's camera order: the rig
    ``K, R (M, 3, 3)``, ``t (M, 3)``, ``dist (M, 5)`` (or a Fisheye), ``view_sizes (M, 2)``.

    A group mixing ``FisheyeCamera`` and ``Camera`` raises (a rig has one lens model); so
    does one where only some cameras have a size.
    """
    cameras = list(getattr(camera_group, "cameras", None) or [])
    if not cameras:
        raise ValueError(
            f"camera_group: expected an aniposelib CameraGroup with cameras; got {type(camera_group).__name__}"
        )
    fisheye = [type(c).__name__ == "FisheyeCamera" for c in cameras]
    if any(fisheye) and not all(fisheye):
        raise ValueError(
            f"camera_group: cameras {[m for m, f in enumerate(fisheye) if f]} are FisheyeCamera and the others are not; a rig has one lens model"
        )
    sizes = [c.get_size() for c in cameras]
    if any(s is None for s in sizes) and not all(s is None for s in sizes):
        m = next(m for m, s in enumerate(sizes) if s is None)
        raise ValueError(
            f"camera_group: camera {m} ({cameras[m].get_name()!r}) has no size and others have one"
        )
    names = [c.get_name() for c in cameras]
    return rig_from_opencv(
        [c.get_camera_matrix() for c in cameras],
        [c.get_distortions() for c in cameras],
        [c.get_rotation() for c in cameras],
        [c.get_translation() for c in cameras],
        image_size=None if sizes[0] is None else [list(s) for s in sizes],
        fisheye=all(fisheye),
        names=None if any(n is None for n in names) else [str(n) for n in names],
        dtype=dtype,
    )


def aniposelib_from_rig(rig: Rig, *, image_size: Any, dist: Any = None, names: Any = None) -> Any:
    """``rig`` as an aniposelib ``CameraGroup`` (needs ``pip install aniposelib``).

    ``image_size``: ``(w, h)`` or ``(M, 2)``, required (aniposelib cannot save or load a
    camera without it). ``dist``: ``(M, 5)``, a :class:`cdog_jax.geometry.Fisheye`
    (``FisheyeCamera``), or ``None`` (zeros). ``names``: default ``"cam_{m}"``. ``matrix`` is
    ``K / K[2,2]``.
    """
    try:
        # an optional library (the `interop` extra), loaded by this converter alone
        from aniposelib.cameras import Camera, CameraGroup, FisheyeCamera
    except ImportError as e:
        raise ImportError("aniposelib_from_rig needs aniposelib: pip install aniposelib") from e
    if image_size is None:
        raise ValueError(
            "aniposelib_from_rig: image_size is required (aniposelib cannot save or load a camera without a size)"
        )
    cams = opencv_from_rig(rig, dist=dist, image_size=image_size)
    M = cams.K.shape[0]
    if names is None:
        names = [f"cam_{m}" for m in range(M)]
    names = _check_names(names, M, "cam_{}")
    kind = FisheyeCamera if cams.fisheye else Camera
    cameras = [
        kind(
            matrix=cams.K[m],
            dist=cams.dist[m],
            size=[int(v) for v in cams.image_size[m]],
            rvec=cams.rvec[m],
            tvec=cams.tvec[m],
            name=names[m],
        )
        for m in range(M)
    ]
    return CameraGroup(cameras)
