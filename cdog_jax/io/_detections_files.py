"""Reading detection files: the JSON forms (one scene, frames, classes) and NPZ arrays
(docs/CONVENTIONS.md §3), as rows for :mod:`._detections_rows`."""

from __future__ import annotations

from typing import Any

import numpy as np

from ._class_labels import check_names, views_and_labels
from ._detections_checks import _finish
from ._detections_rows import (
    _check_coordinates,
    _check_views,
    _from_rows,
    _numeric,
    _rows_from_array,
)
from ._detections_type import Detections
from ._errors import _Where
from ._read_files import check_keys, open_npz, read_json


def _read_json(path: str) -> tuple[list, bool, list, Any]:
    """The views of every frame, whether the file held a list of frames, the per-detection
    class labels of every frame (``None`` entries without classes) and ``class_names``."""
    data = read_json(path)
    names = data.get("class_names") if isinstance(data, dict) else None
    known = ("views", "by_class", "classes", "class_names", "frames")
    if isinstance(data, dict) and "frames" in data:
        beside = [k for k in ("views", "by_class", "classes") if k in data]
        if beside:
            raise ValueError(
                f'{path}: "{beside[0]}" beside "frames": a file holds one scene ({{"views": …}}) or '
                'frames ({"frames": [{"views": …}, …]}), not both'
            )
        check_keys(data, known, path)
        frames = data["frames"]
        if not isinstance(frames, list) or not frames:
            raise ValueError(f'{path}: "frames" must be a non-empty list of {{"views": …}} objects')
        out, labels = [], []
        for f, frame in enumerate(frames):
            if not isinstance(frame, dict) or not ("views" in frame or "by_class" in frame):
                raise ValueError(
                    f'{path}: frame {f}: expected an object {{"views": [[[x, y], …], …]}}'
                )
            check_keys(frame, ("views", "by_class", "classes"), f"{path}: frame {f}")
            views, labs = views_and_labels(frame, f"{path}: frame {f}")
            out.append(views)
            labels.append(labs)
        return out, True, labels, names
    if isinstance(data, dict) and ("views" in data or "by_class" in data):
        check_keys(data, known, path)
        views, labs = views_and_labels(data, path)
        return [views], False, [labs], names
    raise ValueError(
        f'{path}: expected {{"views": [[[x, y], …], …]}} or {{"frames": [{{"views": …}}, …]}}'
    )


def _read_npz(path: str, num_views, capacity, image_size, missing) -> Detections:
    with open_npz(path) as npz:
        if "xy" not in npz.files:
            raise ValueError(
                f'{path}: missing array "xy" (expected xy (M, P, 2) and mask (M, P), or a frame axis first)'
            )
        arrays = {
            k: npz[k]
            for k in ("xy", "mask", "confidence", "classes", "class_names")
            if k in npz.files
        }
    xy = arrays["xy"]
    frames = xy.ndim == 4
    where = _Where(path, frames)
    rows, _ = _rows_from_array(xy, where, 'array "xy"')
    lead = rows.shape[:3]
    conf = None
    if "confidence" in arrays:
        if rows.shape[-1] == 3:
            raise where.error('both a third column in "xy" and an array "confidence"; give one')
        conf = _numeric(arrays["confidence"], where, 'array "confidence"')
        if conf.shape != xy.shape[:-1]:
            raise where.error(
                f'array "confidence": expected shape {xy.shape[:-1]} to match xy {xy.shape}; got {conf.shape}'
            )
        rows = np.concatenate([rows, conf.reshape(lead)[..., None]], axis=-1)
    classes, names = _npz_classes(arrays, xy.shape[:-1], lead, where)
    if "mask" not in arrays:
        present = np.ones(lead, bool)
        return _from_rows(
            rows,
            present,
            frames,
            where,
            missing,
            -1.0,
            num_views,
            capacity,
            image_size,
            classes,
            names,
        )
    mask = arrays["mask"]
    if mask.shape != xy.shape[:-1]:
        raise where.error(
            f'array "mask": expected shape {xy.shape[:-1]} to match xy {xy.shape}; got {mask.shape}'
        )
    mask = mask.reshape(lead)
    if mask.dtype != np.bool_:
        if not (np.issubdtype(mask.dtype, np.integer) and np.isin(mask, (0, 1)).all()):
            raise where.error(f'array "mask": expected booleans (or 0/1); got dtype {mask.dtype}')
        mask = mask.astype(bool)
    _check_views(lead[1], where, num_views)
    _check_coordinates(rows[..., :2], mask, where, "where mask is True")
    conf = rows[..., 2] if rows.shape[-1] == 3 else None
    return _finish(
        rows[..., :2], mask, conf, frames, where, [], capacity, image_size, classes, names
    )


def _npz_classes(
    arrays: dict, shape: tuple, lead: tuple, where: _Where
) -> tuple[np.ndarray | None, tuple | None]:
    """Optional ``classes`` (int ids, the shape of ``mask``) and ``class_names`` (strings)."""
    names = None
    if "class_names" in arrays:
        raw = arrays["class_names"]
        if raw.ndim != 1 or raw.dtype.kind not in "US":
            raise where.error(
                f'array "class_names": expected a 1-D array of strings; got dtype {raw.dtype}, shape {raw.shape}'
            )
        names = check_names([str(n) for n in raw], where.error)
    if "classes" not in arrays:
        if names is not None:
            raise where.error('array "class_names" without an array "classes"')
        return None, None
    c = arrays["classes"]
    if c.shape != shape or not np.issubdtype(c.dtype, np.integer):
        raise where.error(
            f'array "classes": expected integer class ids of shape {shape}; got dtype {c.dtype}, shape {c.shape}'
        )
    c = c.reshape(lead).astype(np.int64)
    limit = np.iinfo(np.int64).max if names is None else len(names)
    bad = (c < 0) | (c >= limit)
    if bad.any():
        f, m, i = (int(v) for v in np.argwhere(bad)[0])
        raise where.error(
            f"class id {c[f, m, i]} must be >= 0"
            + ("" if names is None else f" and < {len(names)} (class_names)"),
            f,
            m,
            i,
        )
    return c, names
