"""Qualisys ``.qca.txt`` calibrations (QTM's XML export), as Pose2Sim reads them.

Layout: ``<calibration><cameras><camera serial=… model=…>`` with ``<fov_video left top
right bottom>`` (pixels, inclusive), ``<transform x y z r11 … r33>`` (camera position in
mm and a rotation) and ``<intrinsic focalLengthU focalLengthV centerPointU centerPointV
radialDistortion1..3 tangentalDistortion1..2>``, the intrinsics in sub-pixel units (×64).

Convention (Pose2Sim 0.7.2 ``calibration.read_qca`` + ``calib_qca_fun``, binning 1):

- ``K = [[fu, 0, cu], [0, fv, cv], [0, 0, 1]]`` with ``fu = focalLengthU / 64``,
  ``fv = focalLengthV / 64``, ``cu = centerPointU / 64 − left``, ``cv = centerPointV / 64 − top``;
- ``dist = (k1, k2, p1, p2, k3)`` = ``(radialDistortion1, radialDistortion2,
  tangentalDistortion1, tangentalDistortion2, radialDistortion3) / 64`` (OpenCV order;
  Pose2Sim also divides these by 64, and leaves out ``k3``, 0 in its files);
- with ``Q`` the matrix of ``r11 … r33`` in row-major order of their names and ``C =
  (x, y, z) / 1000`` (metres), Pose2Sim takes ``Q`` as world→Qualisys-camera and turns
  the camera by π about its x axis (Qualisys cameras look along −z, y up):
  ``R = diag(1, −1, −1) · Q``, ``t = −R · C``; so ``X_cam = R X_world + t`` (OpenCV
  axes and pixels), scene units metres;
- image size ``(right − left + 1, bottom − top + 1)`` of ``fov_video``;
- the video cameras (``model`` ``"Miqus Video"``, ``"Miqus Video UnderWater"`` or
  ``"none"``) in the natural order of their ``serial`` (``cam_2`` before ``cam_10``).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET

import numpy as np

from ._errors import InputError, read_text
from ._keypoints import natural_key
from ._rig_files import _Views

SUBPIXEL = 64.0  # QTM stores intrinsics in 1/64 pixel
VIDEO_MODELS = ("Miqus Video", "Miqus Video UnderWater", "none")
_FLIP = np.diag([1.0, -1.0, -1.0])  # Qualisys camera axes (y up, looking along -z) to OpenCV's


def read_qualisys(path: str) -> _Views:
    """Read a ``.qca.txt`` file (module docstring has the convention). Raises
    :class:`InputError` naming the file and camera for malformed XML, a missing element or
    attribute, or a non-numeric value."""
    try:
        root = ET.fromstring(read_text(path))
    except ET.ParseError as e:
        raise InputError(f"{path}: not a Qualisys calibration: invalid XML ({e})") from None
    cameras = root.findall("cameras/camera")
    if not cameras:
        raise InputError(
            f"{path}: no <cameras><camera …> elements (not a Qualisys .qca.txt calibration?)"
        )
    video = [c for c in cameras if c.get("model") in VIDEO_MODELS]
    chosen = sorted(video, key=lambda c: natural_key(c.get("serial") or ""))
    if len(chosen) < 2:
        raise InputError(
            f"{path}: {len(chosen)} video camera(s) (model one of {VIDEO_MODELS}); a rig needs at least 2"
        )
    K, R, t, dist, sizes, names = [], [], [], [], [], []
    for k, cam in enumerate(chosen):
        name = cam.get("serial") or f"camera {k}"
        where = f"{path}: camera {name!r}"
        fov, tr, intr = (
            _element(cam, tag, where) for tag in ("fov_video", "transform", "intrinsic")
        )
        left, top, right, bottom = (
            _number(fov, a, where) for a in ("left", "top", "right", "bottom")
        )
        fu, fv, cu, cv = (
            _number(intr, a, where) / SUBPIXEL
            for a in ("focalLengthU", "focalLengthV", "centerPointU", "centerPointV")
        )
        K.append([[fu, 0.0, cu - left], [0.0, fv, cv - top], [0.0, 0.0, 1.0]])
        coeffs = (
            "radialDistortion1",
            "radialDistortion2",
            "tangentalDistortion1",
            "tangentalDistortion2",
            "radialDistortion3",
        )
        dist.append([_number(intr, a, where, default=0.0) / SUBPIXEL for a in coeffs])
        Q = np.array([[_number(tr, f"r{i}{j}", where) for j in (1, 2, 3)] for i in (1, 2, 3)])
        C = np.array([_number(tr, a, where) for a in ("x", "y", "z")]) / 1000.0
        R.append(_FLIP @ Q)
        t.append(-(_FLIP @ Q) @ C)
        sizes.append([int(right - left + 1), int(bottom - top + 1)])
        names.append(name)
    if len(set(names)) != len(names):
        raise InputError(f"{path}: camera serials are not distinct: {names}")
    return _Views(
        np.array(K),
        np.array(R),
        np.array(t),
        view_sizes=np.array(sizes, np.int64),
        dist=np.array(dist),
        names=tuple(names),
    )


def _element(cam: ET.Element, tag: str, where: str) -> ET.Element:
    found = cam.find(tag)
    if found is None:
        raise InputError(f"{where}: no <{tag}> element")
    return found


def _number(element: ET.Element, name: str, where: str, default: float | None = None) -> float:
    text = element.get(name)
    if text is None:
        if default is not None:
            return default
        raise InputError(f"{where}: <{element.tag}> has no attribute {name!r}")
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{where}: <{element.tag} {name}={text!r}> is not a number") from None
    if not np.isfinite(value):
        raise InputError(f"{where}: <{element.tag} {name}={text!r}> is not finite")
    return value


def is_qualisys(path: str) -> bool:
    """``path`` names a Qualisys calibration (``.qca.txt`` or ``.qca``)."""
    return os.path.basename(path).lower().endswith((".qca.txt", ".qca"))
