"""nerfstudio ``transforms.json`` rigs.

::

    {"camera_model": "OPENCV",            # or "PINHOLE", "OPENCV_FISHEYE"
     "fl_x": …, "fl_y": …, "cx": …, "cy": …, "w": …, "h": …,
     "k1": …, "k2": …, "k3": …, "k4": …, "p1": …, "p2": …,
     "frames": [{"file_path": "images/a.png", "transform_matrix": 4×4, …}, …]}

Intrinsics and distortion may be given at the top level (shared) or in each frame (which
wins). One frame is one view; its name is ``file_path``.

Convention (nerfstudio's): ``transform_matrix`` is camera→world, ``X_world = M [X_cam; 1]``,
with OpenGL camera axes (x right, y up, z backwards); this library's OpenCV axes (y down, z
forward) are ``diag(1, -1, -1)`` of them, so ``R = (M₃ₓ₃ diag(1, -1, -1))ᵀ`` and ``t = -R
M[:3, 3]``. The world frame is the file's as written. nerfstudio puts the centre of the
top-left pixel at ``(0.5, 0.5)`` (rays through ``pixel + 0.5``), OpenCV at ``(0, 0)``: the
principal point is read as ``(cx - 0.5, cy - 0.5)`` and written back with ``+ 0.5``.
Distortion: ``OPENCV`` ``k1, k2, p1, p2, k3`` → OpenCV's ``(k1, k2, p1, p2, k3)`` (``k4``,
an ``r⁸`` term in nerfstudio, must be 0); ``OPENCV_FISHEYE`` ``k1 … k4`` →
:class:`cdog_jax.geometry.Fisheye`.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from .._expect import PATH, expect_args
from ..geometry._camera import Rig
from ..geometry._distortion import Fisheye
from ._atomic import atomic_write
from ._read_files import read_json
from ._rig_files import PathLike, _Views
from ._rig_values import (
    _check_dist,
    _check_image_size,
    _check_names,
    _check_view_sizes,
    _host_rig,
    _K_over_K22,
    _to_array,
    stack_dists,
)

_OPENGL_FROM_OPENCV = np.diag([1.0, -1.0, -1.0])
_MODELS = ("PINHOLE", "OPENCV", "OPENCV_FISHEYE")
_INTRINSICS = ("fl_x", "fl_y", "cx", "cy", "w", "h")


def read_nerfstudio(path: str) -> _Views:
    """Read a nerfstudio ``transforms.json`` (the module docstring has the convention).

    Views are the ``frames`` in file order, named by ``file_path``. Camera models other than
    PINHOLE, OPENCV and OPENCV_FISHEYE raise ``ValueError``, as does a rotation block of
    ``transform_matrix`` that is not a rotation (a scaled world).
    """
    data = read_json(path)
    if not isinstance(data, dict) or not isinstance(data.get("frames"), list) or not data["frames"]:
        raise ValueError(
            f'{path}: expected an object with a non-empty list "frames" (nerfstudio transforms.json)'
        )
    Ks, Rs, ts, dists, sizes, names = [], [], [], [], [], []
    for m, frame in enumerate(data["frames"]):
        where = f"{path}: frame {m}"
        if not isinstance(frame, dict):
            raise ValueError(f"{where}: expected an object; got {type(frame).__name__}")  # noqa: TRY004
        get = {
            **{k: v for k, v in data.items() if k != "frames"},
            **frame,
        }  # a frame's own values win
        model = get.get("camera_model", "OPENCV")
        if model not in _MODELS:
            raise ValueError(
                f"{where}: camera_model {model!r} is not supported; expected one of {', '.join(_MODELS)}"
            )
        for key in (*_INTRINSICS, "transform_matrix"):
            if key not in get:
                raise ValueError(f'{where}: missing key "{key}" (in the frame or at the top level)')
        fx, fy, cx, cy = (
            float(_to_array([get[k]], (1,), f'{where}, key "{k}"')[0]) for k in _INTRINSICS[:4]
        )
        Ks.append(np.array([[fx, 0.0, cx - 0.5], [0.0, fy, cy - 0.5], [0.0, 0.0, 1.0]]))
        sizes.append(_check_image_size([get["w"], get["h"]], f'{where}, keys "w", "h"'))
        coeff = {
            k: float(_to_array([get.get(k, 0.0)], (1,), f'{where}, key "{k}"')[0])
            for k in ("k1", "k2", "k3", "k4", "p1", "p2")
        }
        if model == "OPENCV_FISHEYE":
            dists.append(
                ("fisheye", np.array([coeff["k1"], coeff["k2"], coeff["k3"], coeff["k4"]]))
            )
        elif model == "OPENCV":
            if coeff["k4"] != 0:
                raise ValueError(
                    f"{where}: OPENCV with k4 = {coeff['k4']!r} (an r⁸ term OpenCV's model lacks) is not supported"
                )
            dists.append(
                np.array([coeff["k1"], coeff["k2"], coeff["p1"], coeff["p2"], coeff["k3"]])
            )
        else:
            dists.append(None)
        c2w = _to_array(get["transform_matrix"], (4, 4), f'{where}, key "transform_matrix"')
        if not np.allclose(c2w[3], (0.0, 0.0, 0.0, 1.0), rtol=0.0, atol=1e-6):
            raise ValueError(
                f'{where}, key "transform_matrix": the last row must be [0, 0, 0, 1] (a rigid '
                f"transform, camera to world); got {c2w[3].tolist()}"
            )
        R_c2w = c2w[:3, :3] @ _OPENGL_FROM_OPENCV
        Rs.append(R_c2w.T)  # not a rotation (a scaled world): rig_from_arrays names the view
        ts.append(-R_c2w.T @ c2w[:3, 3])
        name = frame.get("file_path", f"frame_{m}")
        names.append(str(name))
    if len(set(names)) != len(names):
        raise ValueError(f'{path}: frames repeat a "file_path": {names}')
    return _Views(
        np.stack(Ks),
        np.stack(Rs),
        np.stack(ts),
        np.array(sizes, dtype=np.int64),
        stack_dists(dists, path),
        tuple(names),
    )


def save_rig_nerfstudio(
    path: PathLike, rig: Rig, *, image_size: Any, dist: Any = None, names: Any = None
) -> None:
    """Write ``rig`` (``K, R (M, 3, 3)``, ``t (M, 3)``) as a nerfstudio ``transforms.json``.

    One frame per view with its own ``fl_x, fl_y, cx, cy`` (principal point + 0.5), ``w, h``
    (``image_size``: ``(w, h)`` or ``(M, 2)``, required), the distortion coefficients, and
    ``transform_matrix`` (camera→world, OpenGL axes); ``file_path`` is ``names`` (default
    ``"view_{m}"``). ``camera_model``: PINHOLE without ``dist``, OPENCV with ``dist (M, 5)``,
    OPENCV_FISHEYE with a :class:`cdog_jax.geometry.Fisheye`. ``K / K[2,2]`` is written; a
    nonzero skew ``K[0,1]`` raises ``ValueError`` (nerfstudio has none).
    """
    expect_args("save_rig_nerfstudio", path=(path, PATH), rig=(rig, Rig))
    K, R, t = _host_rig(rig)
    M = K.shape[0]
    K = _K_over_K22(K)
    sizes = _check_view_sizes(image_size, M, required=True)
    dist = _check_dist(dist, M)
    names = _check_names(names, M, "view_{}")
    model = (
        "OPENCV_FISHEYE" if isinstance(dist, Fisheye) else ("PINHOLE" if dist is None else "OPENCV")
    )
    frames = []
    for m in range(M):
        if abs(K[m, 0, 1]) > 1e-12 * np.abs(K[m]).max():
            raise ValueError(
                f"view {m}: K has skew K[0,1] = {float(K[m, 0, 1])!r} (after K / K[2,2]); nerfstudio cannot hold it"
            )
        frame: dict[str, Any] = {"file_path": names[m]}
        frame.update(fl_x=K[m, 0, 0], fl_y=K[m, 1, 1], cx=K[m, 0, 2] + 0.5, cy=K[m, 1, 2] + 0.5)
        frame.update(w=int(sizes[m, 0]), h=int(sizes[m, 1]))
        if isinstance(dist, Fisheye):
            frame.update(zip(("k1", "k2", "k3", "k4"), dist.coeffs[m]))
        elif dist is not None:
            frame.update(zip(("k1", "k2", "p1", "p2", "k3"), dist[m]))
        c2w = np.eye(4)
        c2w[:3, :3] = R[m].T @ _OPENGL_FROM_OPENCV
        c2w[:3, 3] = -R[m].T @ t[m]
        frame["transform_matrix"] = c2w.tolist()
        frames.append(
            {k: (float(v) if isinstance(v, np.floating) else v) for k, v in frame.items()}
        )
    with atomic_write(path, "w") as f:
        f.write(
            json.dumps({"camera_model": model, "frames": frames}, indent=1, allow_nan=False) + "\n"
        )
