"""Detections as rows ``(F, M, L, 2|3)``, from ragged lists or arrays, and the encodings of
"missing" decoded to a mask (the ``missing`` option; docs/CONVENTIONS.md §3)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ._detections_checks import _finish, _image_size
from ._detections_type import Detections
from ._errors import _Where, too_large

MISSING = ("auto", "nan", "sentinel", "confidence")
_LARGEST_FLOAT = int(np.finfo(np.float64).max)
_ENTRY = "expected [x, y] or [x, y, confidence]"


def _check_options(
    missing: str, capacity: int | None, num_views: int | None, image_size: Any
) -> None:
    if image_size is not None:
        _image_size(image_size)
    if missing not in MISSING:
        raise ValueError(f"missing must be one of {MISSING}; got {missing!r}")
    if capacity is not None and (
        isinstance(capacity, bool) or not isinstance(capacity, (int, np.integer)) or capacity < 1
    ):
        raise ValueError(f"capacity must be a positive int or None; got {capacity!r}")
    if num_views is not None and (
        isinstance(num_views, bool) or not isinstance(num_views, (int, np.integer)) or num_views < 1
    ):
        raise ValueError(f"num_views must be a positive int or None; got {num_views!r}")


def _array_from_lists(
    frames_views: list, where: _Where, num_views: int | None
) -> tuple[np.ndarray, np.ndarray]:
    """Ragged lists of every frame as NaN-padded rows ``(F, M, L, C)`` and which rows exist
    ``(F, M, L)``, with ``L`` the longest list and ``C`` 2 or 3 (the same for all entries)."""
    width = None  # entries of the whole file have 2 or 3 numbers, not a mix
    first = None
    M = None
    for f, views in enumerate(frames_views):
        if not isinstance(views, list):
            raise where.error(
                f'"views" must be a list of per-view lists; got {type(views).__name__}', f
            )
        if not views:
            raise where.error("no views (an empty list)", f)
        if M is not None and len(views) != M:
            raise where.error(f"{len(views)} views; frame 0 has {M}", f)
        M = len(views)
        if num_views is not None and M != num_views:
            raise where.error(f"{M} views; the rig has {num_views} (num_views)", f)
        for m, view in enumerate(views):
            if not isinstance(view, list):
                raise where.error(f"expected a list of detections; got {type(view).__name__}", f, m)
            for i, entry in enumerate(view):
                if not isinstance(entry, (list, tuple)):
                    raise where.error(f"{_ENTRY}; got {entry!r}", f, m, i)
                for v in entry:
                    if isinstance(v, bool) or not isinstance(v, (int, float)):
                        raise where.error(f"non-numeric entry {list(entry)!r}; {_ENTRY}", f, m, i)
                    if isinstance(v, int) and abs(v) > _LARGEST_FLOAT:
                        raise where.error(too_large(v), f, m, i)
                if len(entry) not in (2, 3):
                    raise where.error(
                        f"entry {list(entry)!r} has {len(entry)} numbers; {_ENTRY}", f, m, i
                    )
                if width is None:
                    width, first = len(entry), where.loc(f, m, i)
                elif len(entry) != width:
                    raise where.error(
                        f"entry has {len(entry)} numbers but {first} has {width}; use [x, y] or [x, y, confidence] "
                        "for every entry",
                        f,
                        m,
                        i,
                    )
    F = len(frames_views)
    L = max(len(view) for views in frames_views for view in views)
    a = np.full((F, M, L, width or 2), np.nan)
    present = np.zeros((F, M, L), bool)
    for f, views in enumerate(frames_views):
        for m, view in enumerate(views):
            if view:
                a[f, m, : len(view)] = np.asarray(view, dtype=np.float64)
                present[f, m, : len(view)] = True
    return a, present


def _numeric(a: Any, where: _Where, name: str) -> np.ndarray:
    a = np.asarray(a)
    if a.dtype == np.bool_ or not (
        np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)
    ):
        raise where.error(f"{name}: non-numeric entries (dtype {a.dtype}); expected real numbers")
    return a.astype(np.float64)


def _rows_from_array(a: Any, where: _Where, name: str) -> tuple[np.ndarray, bool]:
    """``(M, P, C)`` or ``(F, M, P, C)`` numbers as float64 ``(F, M, P, C)``, ``C`` 2 or 3."""
    a = _numeric(a, where, name)
    if a.ndim not in (3, 4) or a.shape[-1] not in (2, 3):
        raise where.error(f"{name}: expected shape (M, P, 2|3) or (F, M, P, 2|3); got {a.shape}")
    frames = a.ndim == 4
    a = a if frames else a[None]
    if a.shape[0] == 0:
        raise where.error(f"{name}: no frames (shape {a.shape})")
    if a.shape[1] == 0:
        raise where.error(f"{name}: no views (shape {a.shape})")
    return a, frames


def _check_views(M: int, where: _Where, num_views: int | None) -> None:
    if M == 0:
        raise where.error("no views")
    if num_views is not None and M != num_views:
        raise where.error(f"{M} views; the rig has {num_views} (num_views)")


def _check_coordinates(xy: np.ndarray, rows: np.ndarray, where: _Where, why: str) -> None:
    """Finite ``xy`` on ``rows``; one NaN coordinate, or an infinite one, is malformed."""
    nan = np.isnan(xy)
    half = rows & (nan[..., 0] != nan[..., 1])
    inf = rows & np.isinf(xy).any(axis=-1)
    both = rows & nan.all(axis=-1)
    for bad, text in (
        (
            half,
            "one NaN coordinate and one finite: a malformed row (a missing detection has both NaN)",
        ),
        (inf, "an infinite coordinate"),
        (both, f"NaN coordinates {why}"),
    ):
        if bad.any():
            f, m, i = (int(v) for v in np.argwhere(bad)[0])
            x, y = xy[f, m, i]
            raise where.error(f"({x}, {y}) has {text}", f, m, i)


def _from_rows(
    rows,
    present,
    frames,
    where,
    missing,
    sentinel,
    num_views,
    capacity,
    image_size,
    classes=None,
    names=None,
) -> Detections:
    """Rows ``(F, M, L, 2|3)`` of which ``present (F, M, L)`` exist, "missing" decoded."""
    _check_views(rows.shape[1], where, num_views)
    coords = rows[..., :2]
    conf = rows[..., 2] if rows.shape[-1] == 3 else None
    # Malformed rows raise whatever the encoding: only a full NaN row can mean "missing".
    nan = np.isnan(coords)
    _check_coordinates(coords, present & ~nan.all(axis=-1), where, "")
    by = {
        "nan": present & nan.all(axis=-1),
        "sentinel": present & (coords == sentinel).all(axis=-1),
        "confidence": present & (conf == 0.0) if conf is not None else np.zeros_like(present),
    }
    notes = []
    if missing == "auto":
        used = [name for name, rows_ in by.items() if rows_.any()]
        gone = np.zeros_like(present)
        for name in used:
            gone |= by[name]
        labels = {
            "nan": "NaN coordinates",
            "sentinel": f"sentinel [{sentinel:g}, {sentinel:g}]",
            "confidence": "confidence 0",
        }
        if used:
            notes.append(
                f"missing='auto': {int(gone.sum())} missing rows, encoded as "
                + " and ".join(labels[n] for n in used)
            )
    else:
        if missing == "confidence" and conf is None:
            raise where.error(
                "missing='confidence' needs a confidence column (rows [x, y, confidence])"
            )
        gone = by[missing]
    mask = present & ~gone
    _check_coordinates(coords, mask, where, f"where they do not mean missing (missing={missing!r})")
    return _finish(coords, mask, conf, frames, where, notes, capacity, image_size, classes, names)
