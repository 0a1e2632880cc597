"""COLMAP text models (``cameras.txt`` + ``images.txt``) as rigs (docs/CONVENTIONS.md §3).

``cameras.txt``: ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]`` per line. ``images.txt``: two
lines per image, ``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`` then the image's
``POINTS2D`` (``X Y POINT3D_ID`` triples), a line that is empty for an image without
points. ``#`` starts a comment line.

Convention: ``(QW, QX, QY, QZ)`` is a Hamilton unit quaternion (``w`` first) of the
world→camera rotation and ``X_cam = R X_world + T``; camera axes x right, y down, z
forward, as OpenCV. COLMAP puts the centre of the top-left pixel at ``(0.5, 0.5)``, OpenCV
(and this library) at ``(0, 0)``: the principal point is read as ``(cx - 0.5, cy - 0.5)``
and written back as ``(cx + 0.5, cy + 0.5)``. Distortion maps to OpenCV's
``(k1, k2, p1, p2, k3)`` as: SIMPLE_RADIAL ``k`` → ``(k, 0, 0, 0, 0)``, RADIAL ``k1, k2``
→ ``(k1, k2, 0, 0, 0)``, OPENCV ``k1, k2, p1, p2`` → ``(k1, k2, p1, p2, 0)`` (COLMAP's
OPENCV model is OpenCV's, same ``p1, p2`` order), FULL_OPENCV ``k1, k2, p1, p2, k3, k4,
k5, k6`` → ``(k1, k2, p1, p2, k3)`` when ``k4 = k5 = k6 = 0`` (then it is OpenCV's
5-coefficient model; otherwise the rational model, refused), OPENCV_FISHEYE ``k1 … k4`` →
:class:`cdog_jax.geometry.Fisheye` (OpenCV's fisheye model).
"""

from __future__ import annotations

import io
import os
from typing import Any

import numpy as np

from .._expect import PATH, expect_args
from ..geometry._camera import Rig
from ..geometry._distortion import Fisheye
from ._atomic import atomic_write
from ._errors import read_text
from ._rig_files import PathLike, _Views
from ._rig_values import (
    _check_dist,
    _check_names,
    _check_view_sizes,
    _host_rig,
    _K_over_K22,
    stack_dists,
)
from ._rotations import quaternion_from_rotation, rotation_from_quaternion

# model → parameter names; f, fx, fy, cx, cy, then the distortion coefficients.
_MODELS = {
    "SIMPLE_PINHOLE": ("f", "cx", "cy"),
    "PINHOLE": ("fx", "fy", "cx", "cy"),
    "SIMPLE_RADIAL": ("f", "cx", "cy", "k"),
    "RADIAL": ("f", "cx", "cy", "k1", "k2"),
    "OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"),
    "FULL_OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
    "OPENCV_FISHEYE": ("fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"),
}
_QUATERNION_NORM_TOL = 1e-3


def read_colmap(path: str) -> _Views:
    """Read a COLMAP text model: a folder holding ``cameras.txt`` and ``images.txt``, or the
    path of one of them (the module docstring has the convention).

    Views are the images in ascending ``IMAGE_ID`` (ids may be non-contiguous, several
    images may share one camera); names are the image ``NAME``; sizes come from each
    image's camera. ``dist`` is ``None`` when every camera is SIMPLE_PINHOLE or PINHOLE.
    The quaternion is normalised; one whose norm is off 1 by more than 1e-3 is an error.
    """
    folder = os.path.dirname(path) if os.path.isfile(path) else path
    cameras_file = os.path.join(folder, "cameras.txt")
    images_file = os.path.join(folder, "images.txt")
    for file in (cameras_file, images_file):
        if not os.path.isfile(file):
            raise ValueError(
                f"{path}: missing {file} (a COLMAP text model is cameras.txt + images.txt)"
            )
    cameras = _read_cameras(cameras_file)
    images = _read_images(images_file)
    if not images:
        raise ValueError(f"{images_file}: no images (zero views)")
    K, R, t, sizes, dists, names = [], [], [], [], [], []
    for m, (image_id, (q, T, camera_id, name, lineno)) in enumerate(sorted(images.items())):
        where = f"{images_file}, line {lineno}: view {m} (image {image_id} {name!r})"
        if camera_id not in cameras:
            raise ValueError(
                f"{where}: CAMERA_ID {camera_id} is not in {cameras_file} (ids: {sorted(cameras)})"
            )
        norm = float(np.sqrt(q @ q))
        if abs(norm - 1.0) > _QUATERNION_NORM_TOL:
            raise ValueError(
                f"{where}: quaternion (QW, QX, QY, QZ) = {q.tolist()} has norm {norm:.6g}; expected 1"
            )
        Kc, size, dist = cameras[camera_id]
        K.append(Kc)
        R.append(rotation_from_quaternion(q / norm))
        t.append(T)
        sizes.append(size)
        dists.append(dist)
        names.append(name)
    dist = stack_dists(dists, images_file)
    return _Views(
        np.stack(K), np.stack(R), np.stack(t), np.array(sizes, dtype=np.int64), dist, tuple(names)
    )


def _data_lines(file: str):
    """``(line number, text)`` of every line of ``file``, newline stripped."""
    for lineno, line in enumerate(io.StringIO(read_text(file), newline=None), start=1):
        yield lineno, line.rstrip("\r\n")


def _numbers(fields: list[str], where: str, what: str) -> np.ndarray:
    try:
        a = np.array([float(x) for x in fields], dtype=np.float64)
    except ValueError:
        raise ValueError(
            f"{where}: expected numbers for {what}; got {' '.join(fields)!r}"
        ) from None
    if not np.isfinite(a).all():
        raise ValueError(f"{where}: non-finite {what}: {' '.join(fields)!r}")
    return a


def _int(field: str, where: str, what: str, minimum: int) -> int:
    try:
        value = int(field)
    except ValueError:
        raise ValueError(f"{where}: expected an integer {what}; got {field!r}") from None
    if value < minimum:
        raise ValueError(f"{where}: expected {what} >= {minimum}; got {value}")
    return value


def _read_cameras(file: str) -> dict[int, tuple[np.ndarray, tuple[int, int], Any]]:
    """``CAMERA_ID → (K (3, 3) in OpenCV pixels, (width, height), lens)``, the lens as
    :func:`camera_from_params` gives it."""
    cameras: dict[int, Any] = {}
    for lineno, line in _data_lines(file):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        where = f"{file}, line {lineno}"
        if len(fields) < 4:
            raise ValueError(
                f"{where}: expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]; got {line.strip()!r}"
            )
        camera_id = _int(fields[0], where, "CAMERA_ID", 0)
        where = f"{file}, line {lineno}, camera {camera_id}"
        model = fields[1]
        if model not in _MODELS:
            camera_from_params(model, np.zeros(0), where)  # raises: unsupported model
        if camera_id in cameras:
            raise ValueError(f"{where}: CAMERA_ID {camera_id} defined twice")
        size = (_int(fields[2], where, "WIDTH", 1), _int(fields[3], where, "HEIGHT", 1))
        names = _MODELS[model]
        if len(fields) - 4 != len(names):
            raise ValueError(
                f"{where}: model {model} takes {len(names)} parameters ({', '.join(names)}); got {len(fields) - 4}"
            )
        K, dist = camera_from_params(
            model, _numbers(fields[4:], where, f"{model} parameters"), where
        )
        cameras[camera_id] = (K, size, dist)
    return cameras


def camera_from_params(model: str, params: np.ndarray, where: str) -> tuple[np.ndarray, Any]:
    """``K (3, 3)`` in OpenCV pixels and the lens (``None``, ``(5,)`` OpenCV coefficients or
    ``("fisheye", (4,))``) of a COLMAP camera ``model`` with its ``params``."""
    if model not in _MODELS:
        raise ValueError(
            f"{where}: unsupported camera model {model!r}; expected one of {', '.join(_MODELS)} "
            "(undistort the model with `colmap image_undistorter` or convert it to OPENCV)"
        )
    values = np.asarray(params, dtype=np.float64).reshape(-1)
    if values.size != len(_MODELS[model]):
        raise ValueError(
            f"{where}: model {model} takes {len(_MODELS[model])} parameters ({', '.join(_MODELS[model])}); got {values.size}"
        )
    p = dict(zip(_MODELS[model], values.tolist()))
    fx, fy = (p["f"], p["f"]) if "f" in p else (p["fx"], p["fy"])
    # COLMAP's pixel centres are at +0.5: shift the principal point to OpenCV's convention.
    K = np.array([[fx, 0.0, p["cx"] - 0.5], [0.0, fy, p["cy"] - 0.5], [0.0, 0.0, 1.0]])
    dist: Any = None
    if model == "SIMPLE_RADIAL":
        dist = np.array([p["k"], 0.0, 0.0, 0.0, 0.0])
    elif model == "RADIAL":
        dist = np.array([p["k1"], p["k2"], 0.0, 0.0, 0.0])
    elif model == "OPENCV":
        dist = np.array([p["k1"], p["k2"], p["p1"], p["p2"], 0.0])
    elif model == "FULL_OPENCV":
        rational = [p["k4"], p["k5"], p["k6"]]
        if any(rational):
            raise ValueError(
                f"{where}: FULL_OPENCV with k4, k5, k6 = {rational} (the rational model) is not supported; "
                "only k4 = k5 = k6 = 0, OpenCV's 5-coefficient model"
            )
        dist = np.array([p["k1"], p["k2"], p["p1"], p["p2"], p["k3"]])
    elif model == "OPENCV_FISHEYE":
        dist = ("fisheye", np.array([p["k1"], p["k2"], p["k3"], p["k4"]]))
    return K, dist


def _read_images(file: str) -> dict[int, tuple[np.ndarray, np.ndarray, int, str, int]]:
    """``IMAGE_ID → (q (4,), T (3,), CAMERA_ID, NAME, line number)``.

    Comment and blank lines are skipped only while looking for an image line: the line
    after an image line is its POINTS2D line, even when empty.
    """
    images: dict[int, Any] = {}
    lines = _data_lines(file)
    for lineno, line in lines:
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        where = f"{file}, line {lineno}"
        fields = line.split(maxsplit=9)
        if len(fields) < 10:
            raise ValueError(
                f"{where}: expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME; got {len(fields)} fields {line.strip()!r}"
            )
        image_id = _int(fields[0], where, "IMAGE_ID", 0)
        name = fields[9].strip()
        where = f"{where}, image {image_id} {name!r}"
        if image_id in images:
            raise ValueError(
                f"{where}: IMAGE_ID {image_id} defined twice (also on line {images[image_id][4]})"
            )
        pose = _numbers(fields[1:8], where, "QW QX QY QZ TX TY TZ")
        camera_id = _int(fields[8], where, "CAMERA_ID", 0)
        points = next(lines, None)
        if points is not None and len(points[1].split()) % 3 != 0:
            raise ValueError(
                f"{file}, line {points[0]}: expected the POINTS2D line of image {image_id} {name!r} "
                f"(X Y POINT3D_ID triples, or an empty line); got {len(points[1].split())} fields. "
                "Was the empty POINTS2D line of an image removed?"
            )
        images[image_id] = (pose[:4], pose[4:], camera_id, name, lineno)
    return images


def save_rig_colmap(
    folder: PathLike, rig: Rig, *, image_size: Any, dist: Any = None, names: Any = None
) -> None:
    """Write ``rig`` (``K, R (M, 3, 3)``, ``t (M, 3)``) as a COLMAP text model in ``folder``.

    One camera and one image per view (``CAMERA_ID = IMAGE_ID = m + 1``), ``images.txt``
    with empty POINTS2D lines, and an empty ``points3D.txt``. ``K / K[2,2]`` is written
    (same projection; ``K[2,2] = -1`` allowed), the principal point shifted by +0.5 to
    COLMAP's pixel centres; PINHOLE, OPENCV for a view whose ``dist`` (``(M, 5)``) has a
    nonzero ``k1, k2, p1, p2``, FULL_OPENCV (``k4 = k5 = k6 = 0``) for one with a nonzero
    ``k3``, OPENCV_FISHEYE for every view of a :class:`cdog_jax.geometry.Fisheye`. A
    nonzero skew ``K[0,1]`` raises ``ValueError`` (no COLMAP model holds it).
    ``image_size``: ``(w, h)`` or ``(M, 2)``, required.
    ``names`` (default ``"view_{m}"``) must have no whitespace.
    """
    expect_args("save_rig_colmap", folder=(folder, PATH), rig=(rig, Rig))
    K, R, t = _host_rig(rig)
    M = K.shape[0]
    K = _K_over_K22(K)
    sizes = _check_view_sizes(image_size, M, required=True)
    dist = _check_dist(dist, M)
    names = _check_names(names, M, "view_{}", r"\S+", "COLMAP image names cannot hold whitespace")
    for m in range(M):
        scale = np.abs(K[m]).max()
        if abs(K[m, 0, 1]) > 1e-12 * scale:
            raise ValueError(
                f"view {m}: K has skew K[0,1] = {float(K[m, 0, 1])!r} (after K / K[2,2]); COLMAP's camera models cannot hold it"
            )
        if np.abs(K[m][np.tril_indices(3, -1)]).max() > 0:
            raise ValueError(
                f"view {m}: K is not upper triangular; COLMAP's camera models cannot hold it"
            )
    camera_lines, image_lines = [], []
    for m in range(M):
        fx, fy, cx, cy = K[m, 0, 0], K[m, 1, 1], K[m, 0, 2] + 0.5, K[m, 1, 2] + 0.5
        params = [fx, fy, cx, cy]
        model = "PINHOLE"
        if isinstance(dist, Fisheye):
            model = "OPENCV_FISHEYE"
            params += list(dist.coeffs[m])
        elif dist is not None and dist[m, 4] != 0:
            model = "FULL_OPENCV"
            params += list(dist[m]) + [0.0, 0.0, 0.0]
        elif dist is not None and np.any(dist[m, :4] != 0):
            model = "OPENCV"
            params += list(dist[m, :4])
        w, h = sizes[m]
        camera_lines.append(
            f"{m + 1} {model} {int(w)} {int(h)} " + " ".join(repr(float(x)) for x in params)
        )
        pose = list(quaternion_from_rotation(R[m])) + list(t[m])
        image_lines.append(
            f"{m + 1} " + " ".join(repr(float(x)) for x in pose) + f" {m + 1} {names[m]}"
        )
        image_lines.append("")  # no POINTS2D
    folder = os.fspath(folder)
    os.makedirs(folder, exist_ok=True)
    header = "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
    with atomic_write(os.path.join(folder, "cameras.txt"), "w") as f:
        f.write(header + f"# Number of cameras: {M}\n" + "\n".join(camera_lines) + "\n")
    header = (
        "# Image list with two lines of data per image:\n"
        "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
        "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
    )
    with atomic_write(os.path.join(folder, "images.txt"), "w") as f:
        f.write(
            header
            + f"# Number of images: {M}, mean observations per image: 0\n"
            + "\n".join(image_lines)
            + "\n"
        )
    with atomic_write(os.path.join(folder, "points3D.txt"), "w") as f:
        f.write(
            "# 3D point list with one line of data per point:\n#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[]\n"
        )
        f.write("# Number of points: 0, mean track length: 0\n")
