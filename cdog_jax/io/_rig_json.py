"""The project's JSON rig: ``{"views": [{"K", "R", "t", "dist" | "fisheye", "image_size"}, …]}``
(docs/CONVENTIONS.md §3), read and written exactly (float64 ``repr``)."""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from .._expect import PATH, expect_args
from ..geometry._camera import Rig
from ..geometry._distortion import Fisheye
from ._atomic import atomic_write
from ._read_files import check_keys, read_json
from ._rig_files import PathLike, _Views
from ._rig_values import (
    _check_dist,
    _check_image_size,
    _host_rig,
    _tile_size,
    _to_array,
    stack_dists,
)

_VIEW_KEYS = ("K", "R", "t", "dist", "fisheye", "image_size")


def read_json_rig(path: str):
    data = read_json(path)
    if not isinstance(data, dict) or "views" not in data:
        raise ValueError(
            f'{path}: missing key "views" (expected {{"views": [{{"K", "R", "t"}}, …]}})'
        )
    check_keys(data, ("views",), path)
    views = data["views"]
    if not isinstance(views, list) or not views:
        raise ValueError(f'{path}: "views" must be a non-empty list of view objects')
    K, R, t, dists, sizes = [], [], [], [], []
    for m, view in enumerate(views):
        where = f"{path}: view {m}"
        if not isinstance(view, dict):
            raise ValueError(
                f"{where}: expected an object with keys K, R, t; got {type(view).__name__}"
            )  # noqa: TRY004 (bad file content, not a bad argument)
        check_keys(view, _VIEW_KEYS, where)
        for key in ("K", "R", "t"):
            if key not in view:
                raise ValueError(f'{where}: missing key "{key}"')
        K.append(_to_array(view["K"], (3, 3), f'{where}, key "K"'))
        R.append(_to_array(view["R"], (3, 3), f'{where}, key "R"'))
        t.append(_to_array(view["t"], (3,), f'{where}, key "t"'))
        if "dist" in view and "fisheye" in view:
            raise ValueError(f'{where}: both "dist" and "fisheye"; a view has one lens model')
        if "fisheye" in view:
            dists.append(("fisheye", _to_array(view["fisheye"], (4,), f'{where}, key "fisheye"')))
        else:
            dists.append(
                _to_array(view["dist"], (5,), f'{where}, key "dist"') if "dist" in view else None
            )
        sizes.append(
            _check_image_size(view["image_size"], f'{where}, key "image_size"')
            if "image_size" in view
            else None
        )
    given = {s for s in sizes if s is not None}
    if len(given) > 1:
        raise ValueError(
            f'{path}: views give different "image_size" values {sorted(given)}; expected one for all views'
        )
    image_size = given.pop() if given else None
    return _Views(
        np.stack(K),
        np.stack(R),
        np.stack(t),
        _tile_size(image_size, len(K)),
        stack_dists(dists, path),
    )


def save_rig_json(
    path: PathLike, rig: Rig, *, image_size: tuple[int, int] | None = None, dist: Any = None
) -> None:
    """Write ``rig`` (``K, R (M, 3, 3)``, ``t (M, 3)``) as the project's JSON rig.

    One object per view ``{"K": 3×3, "R": 3×3, "t": [3]}``, plus ``"image_size": [w, h]``
    and ``"dist": [5]`` (OpenCV ``k1, k2, p1, p2, k3``, ``dist (M, 5)``) or ``"fisheye":
    [4]`` (a :class:`cdog_jax.geometry.Fisheye`) when given. Numbers are written exactly
    (float64 ``repr``).
    """
    expect_args("save_rig_json", path=(path, PATH), rig=(rig, Rig))
    K, R, t = _host_rig(rig)
    size = _check_image_size(image_size, "image_size")
    dist = _check_dist(dist, K.shape[0])
    views = []
    for m in range(K.shape[0]):
        view: dict[str, Any] = {"K": K[m].tolist(), "R": R[m].tolist(), "t": t[m].tolist()}
        if isinstance(dist, Fisheye):
            view["fisheye"] = dist.coeffs[m].tolist()
        elif dist is not None:
            view["dist"] = dist[m].tolist()
        if size is not None:
            view["image_size"] = list(size)
        views.append(json.dumps(view, allow_nan=False))
    with atomic_write(path, "w") as f:
        f.write('{"views": [\n  ' + ",\n  ".join(views) + "\n]}\n")
