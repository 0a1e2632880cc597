"""Rigs from and to a pycolmap ``Reconstruction``, in memory (pycolmap is optional:
imported only by :func:`pycolmap_from_rig`).

Convention (COLMAP's): ``image.cam_from_world`` maps world to camera, ``X_cam = R X + t``
(its ``matrix()`` is ``[R | t]``); OpenCV camera axes; COLMAP puts the centre of the
top-left pixel at ``(0.5, 0.5)``, so the principal point is read as ``(cx - 0.5, cy - 0.5)``
and written with ``+ 0.5``; camera models map to distortion as for COLMAP text models
(:mod:`cdog_jax.io._colmap`: PINHOLE, SIMPLE_PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV,
FULL_OPENCV with ``k4 = k5 = k6 = 0``, OPENCV_FISHEYE). Views are the images with a pose in
ascending ``image_id``, named by ``image.name``.
"""

from __future__ import annotations

import os
import tempfile
from typing import Any

import numpy as np

from ..geometry._camera import Rig
from ._colmap import camera_from_params, save_rig_colmap
from ._rig_files import RigFile, _Views, check_rig_dtype, rig_file_from_views
from ._rig_values import stack_dists


def rig_from_pycolmap(reconstruction: Any, *, dtype: Any = None, origin: Any = None) -> RigFile:
    """A :class:`RigFile` from a pycolmap ``Reconstruction`` (anything with ``images`` and
    ``cameras`` mappings whose items have pycolmap's attributes: ``image.camera_id``,
    ``image.name``, ``image.cam_from_world`` (a ``Rigid3d`` or a method returning one, with
    ``matrix()``), ``camera.model`` (or ``model_name``), ``camera.params``, ``camera.width``,
    ``camera.height``). Images without a pose (``has_pose`` False) are skipped. ``origin``:
    a world point, or ``"cameras"``, that becomes the rig's origin (see
    :func:`cdog_jax.io.load_rig`).
    """
    check_rig_dtype(dtype, "rig_from_pycolmap")
    K, R, t, sizes, dists, names = [], [], [], [], [], []
    for image_id, image in sorted(dict(reconstruction.images).items()):
        if hasattr(image, "has_pose") and not (
            image.has_pose() if callable(image.has_pose) else image.has_pose
        ):
            continue
        where = f"reconstruction: image {image_id} ({image.name!r})"
        camera = reconstruction.cameras[image.camera_id]
        model = getattr(camera, "model_name", None) or getattr(camera.model, "name", camera.model)
        Kc, dist = camera_from_params(
            str(model),
            np.asarray(camera.params, dtype=np.float64),
            f"{where}, camera {image.camera_id}",
        )
        pose = image.cam_from_world() if callable(image.cam_from_world) else image.cam_from_world
        Rt = np.asarray(pose.matrix(), dtype=np.float64)
        K.append(Kc)
        R.append(Rt[:, :3])
        t.append(Rt[:, 3])
        sizes.append((int(camera.width), int(camera.height)))
        dists.append(dist)
        names.append(str(image.name))
    if not K:
        raise ValueError("reconstruction: no images with a pose (zero views)")
    views = _Views(
        np.stack(K),
        np.stack(R),
        np.stack(t),
        np.array(sizes, dtype=np.int64),
        stack_dists(dists, "reconstruction"),
        tuple(names),
    )
    return rig_file_from_views(views, dtype, "reconstruction", origin)


def pycolmap_from_rig(rig: Rig, *, image_size: Any, dist: Any = None, names: Any = None) -> Any:
    """``rig`` (``K, R (M, 3, 3)``, ``t (M, 3)``) as a pycolmap ``Reconstruction`` (needs
    ``pip install pycolmap``): one camera and one posed image per view, no points, with
    the camera models of :func:`save_rig_colmap`, which writes the model that pycolmap then
    reads (so every pycolmap version builds it the same way). ``image_size``: ``(w, h)`` or
    ``(M, 2)``, required; ``dist``: ``(M, 5)`` or a :class:`cdog_jax.geometry.Fisheye`."""
    try:
        # an optional library (the `interop` extra), loaded by this converter alone
        import pycolmap
    except ImportError as e:
        raise ImportError("pycolmap_from_rig needs pycolmap: pip install pycolmap") from e
    with tempfile.TemporaryDirectory() as folder:
        save_rig_colmap(folder, rig, image_size=image_size, dist=dist, names=names)
        reconstruction = pycolmap.Reconstruction()
        reconstruction.read_text(os.fspath(folder))
    return reconstruction
