"""Detection files (docs/CONVENTIONS.md §3): JSON lists, NPZ arrays, and the encodings of "missing".

Every reader and converter ends in the dense, padded form the pipeline takes (docs/CONVENTIONS.md §2):
``xy (F, M, P, 2)`` pixels and ``mask (F, M, P)`` bool, with a frame axis ``F`` that is 1
for a single scene. The slot of a detection is its index in its view's list (JSON) or its
row in the array (NPZ); slots are kept unless a ``capacity`` forces a view to be packed,
which is then reported in ``notes``.

"Missing" comes in four encodings in the field, all converted to ``mask = False``:

- an explicit ``mask`` array (NPZ; every other row is a detection),
- ``"nan"``: both coordinates NaN,
- ``"sentinel"``: both coordinates equal to ``sentinel`` (default ``-1``, as ``[-1, -1]``),
- ``"confidence"``: confidence exactly 0 (a third column ``[x, y, c]``, as OpenPose writes).

``"auto"`` uses whichever of the last three the data shows (all of them if several) and
says which in ``notes``. A row with exactly one NaN coordinate, or an infinite one, is
malformed rather than missing, and raises.

Everything is checked before any work, and every error names the file, the frame (for a
list of frames), the view and the detection index. Padded slots hold ``xy = 0`` and
``confidence = 0``.
"""

from __future__ import annotations

import os
from typing import Any, NamedTuple

import numpy as np

from .._expect import ARRAY, PATH, expect_args
from ._errors import InputError, too_large
from ._rig_files import open_npz, read_json
from ._class_labels import check_names, class_array, views_and_labels
from ._scores import clip_scores

PathLike = str | os.PathLike  # a file name

MISSING = ("auto", "nan", "sentinel", "confidence")
_LARGEST_FLOAT = int(np.finfo(np.float64).max)
_ENTRY = "expected [x, y] or [x, y, confidence]"


class Detections(NamedTuple):
    """Detections of ``F`` frames (``F = 1`` for a single scene) in padded dense form.

    Attributes:
        xy: ``(F, M, P, 2)`` float64 pixels; padded slots hold 0.
        mask: ``(F, M, P)`` bool, the slot holds a detection.
        confidence: ``(F, M, P)`` float64 in [0, 1] (0 in padded slots), or ``None`` when the
            input has no confidence.
        frames: the input held a list of frames (``{"frames": …}`` or a leading array axis);
            ``False`` for one scene.
        counts: ``(F, M)`` int64 detections per view.
        notes: non-fatal findings (empty views, the encoding ``missing="auto"`` chose,
            views packed to fit ``capacity``), one sentence each.
        classes: ``(F, M, P)`` int64 class id of every detection (``-1`` where ``mask`` is
            False), or ``None`` when the input has no classes (see
            :mod:`cdog_jax.io._class_labels`); associate with :func:`cdog_jax.associate_classes`.
        class_names: the class names by id, or ``None`` when only ids are known.
        frame_ids: ``(F,)`` int64 frame numbers as the files name them (keypoint readers),
            or ``None`` when frames are numbered ``0 … F-1``.
    """

    xy: np.ndarray
    mask: np.ndarray
    confidence: np.ndarray | None
    frames: bool
    counts: np.ndarray
    notes: list[str]
    classes: np.ndarray | None = None
    class_names: tuple[str, ...] | None = None
    frame_ids: np.ndarray | None = None

    def scene(self, f: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """``(xy (M, P, 2), mask (M, P), confidence (M, P) or None)`` of frame ``f``, ready
        for :func:`cdog_jax.associate`."""
        conf = None if self.confidence is None else self.confidence[f]
        return self.xy[f], self.mask[f], conf


def load_detections(
    path: PathLike,
    *,
    num_views: int | None = None,
    capacity: int | None = None,
    image_size: tuple[int, int] | None = None,
    missing: str = "auto",
) -> Detections:
    """Read a detections file (JSON or NPZ, by suffix) and check it.

    Formats:

    - JSON, one scene: ``{"views": [[[x, y], …], …]}``, one list per view in rig order; a
      view may be empty; an entry may be ``[x, y, confidence]`` (then all entries must be).
    - JSON, many frames: ``{"frames": [{"views": …}, …]}``, the same views in every frame.
    - JSON with classes: ``"classes"`` beside ``"views"`` (one class per detection, an int
      id or a name) or ``"by_class": {name: [per-view lists]}`` instead of ``"views"``, and
      an optional top-level ``"class_names"`` (:mod:`cdog_jax.io._class_labels`).
    - NPZ: ``xy (M, P, 2)`` and ``mask (M, P)`` bool, optional ``confidence (M, P)``, or the
      same with a leading frame axis ``(F, M, P, …)``. Without ``mask``, ``xy (…, 2|3)``
      encodes missing rows as NaN, sentinel or confidence 0 (see ``missing``).

    Args:
        path: a ``.json`` or ``.npz`` file.
        num_views: the rig's ``M``; every frame must have exactly this many views.
        capacity: slots ``P`` per view. ``None``: as many as the fullest view of any frame
            (JSON) or as the array has (NPZ). A view with more detections raises; it is
            never truncated.
        image_size: ``(width, height)`` in pixels; a detection more than half the image size
            outside the image raises.
        missing: ``"auto"``, ``"nan"``, ``"sentinel"`` (``[-1, -1]``) or ``"confidence"``
            (confidence 0): how missing rows are encoded where there is no ``mask``.

    Returns:
        A :class:`Detections`. Raises ``ValueError`` naming the file, frame, view and
        detection index for non-numeric entries, a wrong entry length, NaN or inf that does
        not mean missing, an integer too large for a float, duplicate detections in a view,
        far-outside coordinates, a view count other than ``num_views``, no views, a
        confidence outside [0, 1.1] or NaN (see :mod:`cdog_jax.io._scores`: up to 1.1 is
        clipped to 1 with a note), or a view over ``capacity``; and when no group is
        possible: one scene with fewer than 2 views with detections, or a list of frames
        none of which has 2. Frames of a list with fewer than 2 views with detections (a
        subject out of view) are kept with a note: they get zero groups.
    """
    expect_args("load_detections", path=(path, PATH))
    path = os.fspath(path)
    _check_options(missing, capacity, num_views, image_size)
    suffix = os.path.splitext(path)[1].lower()
    if suffix == ".json":
        frames_views, frames, labels, names = _read_json(path)
        where = _Where(path, frames)
        a, present = _array_from_lists(frames_views, where, num_views)
        classes = None
        if any(lab is not None for lab in labels) or names is not None:
            classes, names = class_array(labels, frames_views, present.shape, names, where.error)
        return _from_rows(a, present, frames, where, missing, -1.0, num_views, capacity, image_size, classes, names)
    if suffix == ".npz":
        return _read_npz(path, num_views, capacity, image_size, missing)
    raise ValueError(f"{path}: cannot tell the detections format; expected a .json or .npz file")


def detections_from_lists(
    views: list,
    *,
    missing: str = "auto",
    sentinel: float = -1.0,
    num_views: int | None = None,
    capacity: int | None = None,
    image_size: tuple[int, int] | None = None,
) -> Detections:
    """One scene given as ragged per-view lists ``[[[x, y], …], …]`` (entries may be
    ``[x, y, confidence]``; a view may be empty) as a :class:`Detections` with ``F = 1``.

    The slot of a detection is its index in its list; a row that encodes "missing" (see
    ``missing``, as in :func:`detections_from_array`) keeps its slot with ``mask = False``.
    The other options and the checks are those of :func:`load_detections`.
    """
    expect_args("detections_from_lists", views=(views, (list, tuple)))
    _check_options(missing, capacity, num_views, image_size)
    where = _Where(None, False)
    a, present = _array_from_lists([views], where, num_views)
    return _from_rows(a, present, False, where, missing, sentinel, num_views, capacity, image_size)


def detections_from_array(
    a: Any,
    *,
    missing: str = "auto",
    sentinel: float = -1.0,
    num_views: int | None = None,
    capacity: int | None = None,
    image_size: tuple[int, int] | None = None,
) -> Detections:
    """Dense rows with "missing" encoded in the values, as a :class:`Detections`.

    Args:
        a: ``(M, P, 2|3)`` one scene or ``(F, M, P, 2|3)`` frames; rows ``[x, y]`` or
            ``[x, y, confidence]``, pixels.
        missing: ``"nan"`` (both coordinates NaN), ``"sentinel"`` (both equal ``sentinel``),
            ``"confidence"`` (confidence 0; needs the third column), or ``"auto"``: the
            encodings that the data shows, named in ``notes``.
        sentinel: the coordinate value of a missing row for ``"sentinel"`` / ``"auto"``.
        num_views, capacity, image_size: as in :func:`load_detections`.

    Returns:
        A :class:`Detections` (``frames`` is True for a 4-D ``a``). A row with one NaN
        coordinate, or an infinite one, raises ``ValueError`` naming frame, view and row.
    """
    expect_args("detections_from_array", a=(a, ARRAY))
    _check_options(missing, capacity, num_views, image_size)
    where = _Where(None, np.ndim(a) == 4)
    rows, frames = _rows_from_array(a, where, "array")
    return _from_rows(rows, np.ones(rows.shape[:3], bool), frames, where, missing, sentinel, num_views, capacity, image_size)


# Locations in messages ---------------------------------------------------------------------


class _Where(NamedTuple):
    """Formats "file: frame f, view m, detection i: text" (frame only for lists of frames)."""

    source: str | None
    frames: bool

    def loc(self, f: int | None = None, m: int | None = None, i: int | None = None) -> str:
        parts = []
        if self.frames and f is not None:
            parts.append(f"frame {f}")
        if m is not None:
            parts.append(f"view {m}")
        if i is not None:
            parts.append(f"detection {i}")
        return ", ".join(parts)

    def error(self, text: str, f: int | None = None, m: int | None = None, i: int | None = None) -> ValueError:
        head = [s for s in (self.source, self.loc(f, m, i)) if s]
        return InputError(": ".join([*head, text]))


def _check_options(missing: str, capacity: int | None, num_views: int | None, image_size: Any) -> None:
    if image_size is not None:
        _image_size(image_size)
    if missing not in MISSING:
        raise ValueError(f"missing must be one of {MISSING}; got {missing!r}")
    if capacity is not None and (isinstance(capacity, bool) or not isinstance(capacity, (int, np.integer)) or capacity < 1):
        raise ValueError(f"capacity must be a positive int or None; got {capacity!r}")
    if num_views is not None and (isinstance(num_views, bool) or not isinstance(num_views, (int, np.integer)) or num_views < 1):
        raise ValueError(f"num_views must be a positive int or None; got {num_views!r}")


# Readers -----------------------------------------------------------------------------------


def _read_json(path: str) -> tuple[list, bool, list, Any]:
    """The views of every frame, whether the file held a list of frames, the per-detection
    class labels of every frame (``None`` entries without classes) and ``class_names``."""
    data = read_json(path)
    names = data.get("class_names") if isinstance(data, dict) else None
    if isinstance(data, dict) and "frames" in data:
        frames = data["frames"]
        if not isinstance(frames, list) or not frames:
            raise ValueError(f'{path}: "frames" must be a non-empty list of {{"views": …}} objects')
        out, labels = [], []
        for f, frame in enumerate(frames):
            if not isinstance(frame, dict) or not ("views" in frame or "by_class" in frame):
                raise ValueError(f'{path}: frame {f}: expected an object {{"views": [[[x, y], …], …]}}')
            views, labs = views_and_labels(frame, f"{path}: frame {f}")
            out.append(views)
            labels.append(labs)
        return out, True, labels, names
    if isinstance(data, dict) and ("views" in data or "by_class" in data):
        views, labs = views_and_labels(data, path)
        return [views], False, [labs], names
    raise ValueError(f'{path}: expected {{"views": [[[x, y], …], …]}} or {{"frames": [{{"views": …}}, …]}}')


def _read_npz(path: str, num_views, capacity, image_size, missing) -> Detections:
    with open_npz(path) as npz:
        if "xy" not in npz.files:
            raise ValueError(f'{path}: missing array "xy" (expected xy (M, P, 2) and mask (M, P), or a frame axis first)')
        arrays = {k: npz[k] for k in ("xy", "mask", "confidence", "classes", "class_names") if k in npz.files}
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
            raise where.error(f'array "confidence": expected shape {xy.shape[:-1]} to match xy {xy.shape}; got {conf.shape}')
        rows = np.concatenate([rows, conf.reshape(lead)[..., None]], axis=-1)
    classes, names = _npz_classes(arrays, xy.shape[:-1], lead, where)
    if "mask" not in arrays:
        present = np.ones(lead, bool)
        return _from_rows(rows, present, frames, where, missing, -1.0, num_views, capacity, image_size, classes, names)
    mask = arrays["mask"]
    if mask.shape != xy.shape[:-1]:
        raise where.error(f'array "mask": expected shape {xy.shape[:-1]} to match xy {xy.shape}; got {mask.shape}')
    mask = mask.reshape(lead)
    if mask.dtype != np.bool_:
        if not (np.issubdtype(mask.dtype, np.integer) and np.isin(mask, (0, 1)).all()):
            raise where.error(f'array "mask": expected booleans (or 0/1); got dtype {mask.dtype}')
        mask = mask.astype(bool)
    _check_views(lead[1], where, num_views)
    _check_coordinates(rows[..., :2], mask, where, "where mask is True")
    conf = rows[..., 2] if rows.shape[-1] == 3 else None
    return _finish(rows[..., :2], mask, conf, frames, where, [], capacity, image_size, classes, names)


def _npz_classes(arrays: dict, shape: tuple, lead: tuple, where: _Where) -> tuple[np.ndarray | None, tuple | None]:
    """Optional ``classes`` (int ids, the shape of ``mask``) and ``class_names`` (strings)."""
    names = None
    if "class_names" in arrays:
        raw = arrays["class_names"]
        if raw.ndim != 1 or raw.dtype.kind not in "US":
            raise where.error(f'array "class_names": expected a 1-D array of strings; got dtype {raw.dtype}, shape {raw.shape}')
        names = check_names([str(n) for n in raw], where.error)
    if "classes" not in arrays:
        if names is not None:
            raise where.error('array "class_names" without an array "classes"')
        return None, None
    c = arrays["classes"]
    if c.shape != shape or not np.issubdtype(c.dtype, np.integer):
        raise where.error(f'array "classes": expected integer class ids of shape {shape}; got dtype {c.dtype}, shape {c.shape}')
    c = c.reshape(lead).astype(np.int64)
    limit = np.iinfo(np.int64).max if names is None else len(names)
    bad = (c < 0) | (c >= limit)
    if bad.any():
        f, m, i = (int(v) for v in np.argwhere(bad)[0])
        raise where.error(f"class id {c[f, m, i]} must be >= 0" + ("" if names is None else f" and < {len(names)} (class_names)"), f, m, i)
    return c, names


# Lists and arrays to rows ------------------------------------------------------------------


def _array_from_lists(frames_views: list, where: _Where, num_views: int | None) -> tuple[np.ndarray, np.ndarray]:
    """Ragged lists of every frame as NaN-padded rows ``(F, M, L, C)`` and which rows exist
    ``(F, M, L)``, with ``L`` the longest list and ``C`` 2 or 3 (the same for all entries)."""
    width = None  # entries of the whole file have 2 or 3 numbers, not a mix
    first = None
    M = None
    for f, views in enumerate(frames_views):
        if not isinstance(views, list):
            raise where.error(f'"views" must be a list of per-view lists; got {type(views).__name__}', f)
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
                    raise where.error(f"entry {list(entry)!r} has {len(entry)} numbers; {_ENTRY}", f, m, i)
                if width is None:
                    width, first = len(entry), where.loc(f, m, i)
                elif len(entry) != width:
                    raise where.error(
                        f"entry has {len(entry)} numbers but {first} has {width}; use [x, y] or [x, y, confidence] "
                        "for every entry",
                        f, m, i,
                    )  # fmt: skip
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
    if a.dtype == np.bool_ or not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
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
        (half, "one NaN coordinate and one finite: a malformed row (a missing detection has both NaN)"),
        (inf, "an infinite coordinate"),
        (both, f"NaN coordinates {why}"),
    ):
        if bad.any():
            f, m, i = (int(v) for v in np.argwhere(bad)[0])
            x, y = xy[f, m, i]
            raise where.error(f"({x}, {y}) has {text}", f, m, i)


def _from_rows(rows, present, frames, where, missing, sentinel, num_views, capacity, image_size, classes=None, names=None) -> Detections:
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
        labels = {"nan": "NaN coordinates", "sentinel": f"sentinel [{sentinel:g}, {sentinel:g}]", "confidence": "confidence 0"}
        if used:
            notes.append(f"missing='auto': {int(gone.sum())} missing rows, encoded as " + " and ".join(labels[n] for n in used))
    else:
        if missing == "confidence" and conf is None:
            raise where.error("missing='confidence' needs a confidence column (rows [x, y, confidence])")
        gone = by[missing]
    mask = present & ~gone
    _check_coordinates(coords, mask, where, f"where they do not mean missing (missing={missing!r})")
    return _finish(coords, mask, conf, frames, where, notes, capacity, image_size, classes, names)


# Checks on the decoded detections, and the capacity ----------------------------------------


def _finish(xy, mask, conf, frames, where, notes, capacity, image_size, classes=None, names=None, frame_ids=None) -> Detections:
    xy = np.where(mask[..., None], xy, 0.0)
    if conf is not None:
        conf, note = clip_scores(conf, mask, where.error)
        notes += [note] if note else []
    if classes is not None:
        classes = np.where(mask, classes, -1)
    counts = mask.sum(axis=-1).astype(np.int64)
    if capacity is not None:
        xy, mask, conf, classes = _fit_capacity(xy, mask, conf, counts, capacity, where, notes, classes)
    _check_duplicates(xy, mask, where, classes)
    if image_size is not None:
        _check_in_image(xy, mask, image_size, where)
    _check_groups_possible(counts, frames, where, notes)
    for f, m in np.argwhere(counts == 0):
        notes.append(f"{where.loc(int(f), int(m))}: empty view")
    return Detections(xy, mask, conf, bool(frames), counts, notes, classes, names, frame_ids)


def _check_groups_possible(counts: np.ndarray, frames: bool, where: _Where, notes: list[str]) -> None:
    """A group needs detections in 2 views. One scene without that is refused (nothing to
    associate: most likely the wrong file); so is a list of frames none of which has it.
    Frames without it among others (a subject out of view) are kept, with a note: they
    get zero groups."""
    views_seen = (counts > 0).sum(axis=1)  # (F,)
    hopeless = np.flatnonzero(views_seen < 2)
    if not frames and hopeless.size:
        seen = np.flatnonzero(counts[0] > 0)
        which = f" (view {int(seen[0])})" if len(seen) else ""
        raise where.error(f"{len(seen)} view(s) with detections{which}; association needs at least 2")
    if hopeless.size == counts.shape[0]:
        raise where.error(f"no frame has detections in 2 views (of {counts.shape[0]} frames); association needs at least 2")
    if hopeless.size:
        shown = ", ".join(str(int(f)) for f in hopeless[:10]) + (", …" if hopeless.size > 10 else "")
        notes.append(
            f"frame{'s' if hopeless.size > 1 else ''} {shown} ({hopeless.size} of {counts.shape[0]}): fewer than 2 views "
            "with detections; they get zero groups"
        )


def check_float_range(det: Detections, dtype: Any, source: str | None = None) -> None:
    """Refuse detections whose coordinates the float type ``dtype`` (e.g. float32) cannot
    hold: they would turn infinite when converted. ``source`` (the file) starts the message,
    which names the frame, view and detection."""
    largest = float(np.finfo(dtype).max)
    bad = det.mask & (np.abs(det.xy) > largest).any(axis=-1)
    if bad.any():
        f, m, i = (int(v) for v in np.argwhere(bad)[0])
        x, y = det.xy[f, m, i]
        raise _Where(source, det.frames).error(
            f"({x:g}, {y:g}) is out of {np.dtype(dtype).name} range (largest {largest:.4g}); these cannot be pixels",
            f, m, i,
        )  # fmt: skip


def _fit_capacity(xy, mask, conf, counts, capacity, where, notes, classes=None):
    """Pad to ``capacity`` slots, or shrink to it when every view fits, packing views whose
    detections sit beyond it (slots change; said in ``notes``)."""
    over = counts > capacity
    if over.any():
        f, m = (int(v) for v in np.argwhere(over)[0])
        raise where.error(
            f"{counts[f, m]} detections exceed the capacity of {capacity} slots per view "
            "(pass a larger capacity, or None to fit the fullest view)",
            f, m,
        )  # fmt: skip
    P = mask.shape[-1]
    if P <= capacity:
        pad = ((0, 0), (0, 0), (0, capacity - P))
        conf = None if conf is None else np.pad(conf, pad)
        classes = None if classes is None else np.pad(classes, pad, constant_values=-1)
        return np.pad(xy, (*pad, (0, 0))), np.pad(mask, pad), conf, classes
    for f, m in np.argwhere(mask[..., capacity:].any(axis=-1)):
        order = np.argsort(~mask[f, m], kind="stable")  # detections first, in slot order
        xy[f, m], mask[f, m] = xy[f, m, order], mask[f, m, order]
        if conf is not None:
            conf[f, m] = conf[f, m, order]
        if classes is not None:
            classes[f, m] = classes[f, m, order]
        notes.append(f"{where.loc(int(f), int(m))}: detections moved to slots 0…{counts[f, m] - 1} to fit capacity {capacity}")
    conf = None if conf is None else conf[..., :capacity]
    classes = None if classes is None else classes[..., :capacity]
    return xy[..., :capacity, :], mask[..., :capacity], conf, classes


def _check_duplicates(xy, mask, where, classes=None) -> None:
    """Two detections of one view (and one class, when classes are given: keypoints of
    different types may coincide) at the same pixel are refused."""
    f, m, i = np.nonzero(mask)
    if len(f) < 2:
        return
    x, y = xy[f, m, i, 0], xy[f, m, i, 1]
    c = np.zeros_like(f) if classes is None else classes[f, m, i]
    order = np.lexsort((i, y, x, c, m, f))
    f, m, i, x, y, c = f[order], m[order], i[order], x[order], y[order], c[order]
    same = (f[1:] == f[:-1]) & (m[1:] == m[:-1]) & (c[1:] == c[:-1]) & (x[1:] == x[:-1]) & (y[1:] == y[:-1])
    if same.any():
        # Report the pair earliest in (frame, view, first index) order.
        k = min(np.flatnonzero(same), key=lambda k: (f[k], m[k], i[k]))
        raise where.error(f"detections {i[k]} and {i[k + 1]} are duplicates (both at ({x[k]}, {y[k]}))", int(f[k]), int(m[k]))


def _check_in_image(xy, mask, image_size, where) -> None:
    w, h = _image_size(image_size)
    x, y = xy[..., 0], xy[..., 1]
    beyond_x = np.maximum(np.maximum(-x, x - w), 0.0)  # px beyond the left or right edge
    beyond_y = np.maximum(np.maximum(-y, y - h), 0.0)
    bad = mask & ((beyond_x > w / 2) | (beyond_y > h / 2))
    if bad.any():
        f, m, i = (int(v) for v in np.argwhere(bad)[0])
        xf, yf = float(x[f, m, i]), float(y[f, m, i])
        how = []
        if beyond_x[f, m, i] > 0:
            how.append(f"{beyond_x[f, m, i]:g} px {'left' if xf < 0 else 'right'} of")
        if beyond_y[f, m, i] > 0:
            how.append(f"{beyond_y[f, m, i]:g} px {'above' if yf < 0 else 'below'}")
        raise where.error(
            f"({xf:g}, {yf:g}) lies {' and '.join(how)} the {w:g}×{h:g} image, beyond the margin of half the "
            f"image size ({w / 2:g} px in x, {h / 2:g} px in y)",
            f, m, i,
        )  # fmt: skip


def _image_size(image_size: Any) -> tuple[float, float]:
    ok = (
        isinstance(image_size, (list, tuple))
        and len(image_size) == 2
        and all(not isinstance(v, bool) and isinstance(v, (int, float, np.integer, np.floating)) and v > 0 for v in image_size)
    )
    if not ok:
        raise ValueError(f"image_size must be (width, height), two positive numbers; got {image_size!r}")
    return float(image_size[0]), float(image_size[1])
