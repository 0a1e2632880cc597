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
from typing import Any

import numpy as np

from .._expect import ARRAY, PATH, expect_args
from ._class_labels import class_array
from ._detections_files import _read_json, _read_npz
from ._detections_rows import _array_from_lists, _check_options, _from_rows, _rows_from_array
from ._detections_type import Detections as Detections
from ._errors import _Where

PathLike = str | os.PathLike  # a file name


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
        return _from_rows(
            a,
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
    return _from_rows(
        rows,
        np.ones(rows.shape[:3], bool),
        frames,
        where,
        missing,
        sentinel,
        num_views,
        capacity,
        image_size,
    )
