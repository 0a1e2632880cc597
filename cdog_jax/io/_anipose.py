"""anipose / aniposelib ``calibration.toml`` rigs (docs/CONVENTIONS.md §3).

One section per camera, ``[cam_0]``, ``[cam_1]``, …::

    [cam_0]
    name = "A"
    size = [1920, 1080]
    matrix = [[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]
    distortions = [k1, k2, p1, p2, k3]
    rotation = [rx, ry, rz]
    translation = [tx, ty, tz]

Convention (aniposelib's ``Camera``, which projects with ``cv2.projectPoints``): ``rotation``
is a Rodrigues vector (axis × angle in radians, as ``cv2.Rodrigues``) of the world→camera
rotation, ``X_cam = R X_world + translation``; OpenCV camera axes (x right, y down, z
forward) and pixels (centre of the top-left pixel at ``(0, 0)``); ``distortions`` are
OpenCV's ``(k1, k2, p1, p2[, k3])``, or, with ``fisheye = true`` (aniposelib's
``FisheyeCamera``), OpenCV's fisheye ``(k1, k2, k3, k4)``.

Camera order: aniposelib's ``CameraGroup.load`` sorts the section names as strings
(``cam_10`` before ``cam_2``); :func:`read_anipose` sorts them by number. Match cameras by
their ``name`` (``RigFile.select(camera_group.get_names())``), never by position. The
writer zero-pads the numbers (``cam_00`` … ``cam_10``) so that both orders agree.
"""

from __future__ import annotations

import itertools
import re
import sys
from typing import Any

import numpy as np

from .._expect import PATH, expect_args
from ..geometry._camera import Rig
from ..geometry._distortion import Fisheye
from ._atomic import atomic_write
from ._errors import InputError, read_text
from ._rig_files import PathLike, _Views
from ._rig_values import (
    _check_dist,
    _check_image_size,
    _check_names,
    _check_view_sizes,
    _host_rig,
    _K_over_K22,
    _opencv_dist,
    _to_array,
    stack_dists,
)
from ._rotations import rodrigues_from_rotation, rotation_from_rodrigues

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover (Python 3.10)
    import tomli as tomllib

_SECTION = re.compile(r"cam_([0-9]+)")


def read_anipose(path: str) -> _Views:
    """Read an aniposelib ``calibration.toml`` (the module docstring has the convention).

    Views are the ``[cam_N]`` sections in numeric order of ``N`` (``cam_2`` before ``cam_10``;
    aniposelib itself sorts the names as strings); other sections (``[metadata]``) are
    ignored. ``name`` (default: the section name) and ``size`` are optional; 4
    ``distortions`` get ``k3 = 0``; 8 (the rational model) are read when ``k4 = k5 = k6 =
    0``. ``fisheye = true`` reads 4 ``distortions`` as a :class:`Fisheye` (every camera of
    the rig must then be fisheye).
    """
    text = read_text(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{path}: not valid TOML ({e})") from None
    except RecursionError:
        raise InputError(f"{path}: not readable TOML: arrays nested too deeply") from None
    sections = []
    for key, section in data.items():
        match = _SECTION.fullmatch(key)
        if match:
            sections.append((int(match.group(1)), key, section))
    if not sections:
        raise ValueError(
            f"{path}: no [cam_N] sections (zero cameras); found sections {sorted(data)}"
        )
    sections.sort(key=lambda s: s[0])
    for (n0, key0, _), (n1, key1, _) in itertools.pairwise(sections):
        if n0 == n1:
            raise ValueError(
                f"{path}: sections [{key0}] and [{key1}] have the same camera number {n0}"
            )
    Ks, Rs, ts, dists, sizes, names = [], [], [], [], [], []
    for m, (_, key, section) in enumerate(sections):
        if not isinstance(section, dict):
            raise ValueError(
                f"{path}: view {m}, [{key}]: expected a table; got {type(section).__name__}"
            )  # noqa: TRY004
        name = section.get("name", key)
        if isinstance(name, bool) or not isinstance(name, (str, int)):
            raise ValueError(
                f'{path}: view {m}, [{key}], key "name": expected a string; got {name!r}'
            )  # noqa: TRY004
        name = str(name)
        where = f"{path}: view {m} (camera {name!r}, section [{key}])"
        fisheye = section.get("fisheye", False)
        if not isinstance(fisheye, bool):
            raise ValueError(f'{where}, key "fisheye": expected true or false; got {fisheye!r}')  # noqa: TRY004
        for k in ("matrix", "distortions", "rotation", "translation"):
            if k not in section:
                raise ValueError(
                    f'{where}: missing key "{k}" (expected matrix, distortions, rotation, translation)'
                )
        Ks.append(_to_array(section["matrix"], (3, 3), f'{where}, key "matrix"'))
        dist = section["distortions"]
        length = len(dist) if isinstance(dist, list) else 1
        if fisheye:
            dists.append(
                (
                    "fisheye",
                    _to_array(dist, (4,), f'{where}, key "distortions" (fisheye: k1, k2, k3, k4)'),
                )
            )
        else:
            dists.append(
                _opencv_dist(
                    _to_array(dist, (length,), f'{where}, key "distortions"'),
                    f'{where}, key "distortions"',
                )
            )
        Rs.append(
            rotation_from_rodrigues(
                _to_array(section["rotation"], (3,), f'{where}, key "rotation"')
            )
        )
        ts.append(_to_array(section["translation"], (3,), f'{where}, key "translation"'))
        sizes.append(
            _check_image_size(section["size"], f'{where}, key "size"')
            if "size" in section
            else None
        )
        names.append(name)
    view_sizes = None
    if any(s is not None for s in sizes):
        missing = [m for m, s in enumerate(sizes) if s is None]
        if missing:
            raise ValueError(
                f'{path}: view {missing[0]} (camera {names[missing[0]]!r}): missing key "size" (other cameras give one)'
            )
        view_sizes = np.array(sizes, dtype=np.int64)
    return _Views(
        np.stack(Ks), np.stack(Rs), np.stack(ts), view_sizes, stack_dists(dists, path), tuple(names)
    )


def save_rig_anipose(
    path: PathLike, rig: Rig, *, image_size: Any = None, dist: Any = None, names: Any = None
) -> None:
    """Write ``rig`` (``K, R (M, 3, 3)``, ``t (M, 3)``) as an aniposelib ``calibration.toml``.

    Sections ``[cam_0]`` … ``[cam_{M-1}]`` (zero-padded to one width, ``[cam_00]`` …, when
    ``M > 10``, so that aniposelib's string order is the view order) with ``name``
    (``names``, default ``"cam_{m}"``), ``size`` (``image_size``, one ``(w, h)`` or
    ``(M, 2)``: required, aniposelib cannot load a camera without it), ``matrix = K /
    K[2,2]`` (same projection; OpenCV assumes ``K[2,2] = 1`` and ignores the skew
    ``K[0,1]``, which is written all the same), ``distortions`` (``dist (M, 5)``, zeros
    when ``None``; a :class:`cdog_jax.geometry.Fisheye` writes its 4 coefficients and
    ``fisheye = true``), ``rotation`` (Rodrigues vector of ``R``) and ``translation``.
    Numbers are written with float64 ``repr``.
    """
    expect_args("save_rig_anipose", path=(path, PATH), rig=(rig, Rig))
    K, R, t = _host_rig(rig)
    M = K.shape[0]
    K = _K_over_K22(K)
    if image_size is None:
        raise ValueError(
            "save_rig: an anipose rig needs image_size: aniposelib cannot load a calibration.toml camera "
            "without size = [width, height]; pass image_size=(w, h) or one per view (M, 2)"
        )
    sizes = _check_view_sizes(image_size, M)
    dist = _check_dist(dist, M)
    fisheye = isinstance(dist, Fisheye)
    coeffs = dist.coeffs if fisheye else (np.zeros((M, 5)) if dist is None else dist)
    names = _check_names(names, M, "cam_{}")
    width = len(str(M - 1)) if M > 10 else 1
    blocks = []
    for m in range(M):
        lines = [f"[cam_{m:0{width}d}]", f"name = {_toml_string(names[m])}"]
        lines.append(f"size = [{int(sizes[m, 0])}, {int(sizes[m, 1])}]")
        lines += [
            f"matrix = [{', '.join(_toml_floats(row) for row in K[m])}]",
            f"distortions = {_toml_floats(coeffs[m])}",
            f"rotation = {_toml_floats(rodrigues_from_rotation(R[m]))}",
            f"translation = {_toml_floats(t[m])}",
        ]
        if fisheye:
            lines.append("fisheye = true")
        blocks.append("\n".join(lines) + "\n")
    with atomic_write(path, "w") as f:
        f.write("\n".join(blocks))


def _toml_floats(a: np.ndarray) -> str:
    # repr of a finite float ("0.1", "-0.0", "1e-05", "1e+16") is a valid TOML float.
    return "[" + ", ".join(repr(float(x)) for x in a) + "]"


def _toml_string(s: str) -> str:
    """A TOML basic string: quote, backslash and control characters escaped."""
    escapes = {
        '"': '\\"',
        "\\": "\\\\",
        "\b": "\\b",
        "\t": "\\t",
        "\n": "\\n",
        "\f": "\\f",
        "\r": "\\r",
    }
    out = []
    for c in s:
        if c in escapes:
            out.append(escapes[c])
        elif ord(c) < 0x20 or ord(c) == 0x7F:
            out.append(f"\\u{ord(c):04x}")
        else:
            out.append(c)
    return '"' + "".join(out) + '"'
