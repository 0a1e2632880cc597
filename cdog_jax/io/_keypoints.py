"""Keypoint detections as pose estimators write them: OpenPose folders and point tables.

Both readers end in :class:`cdog_jax.io.Detections` with ``classes``: each keypoint type
is a class, and association (:func:`cdog_jax.associate_classes`) never joins two classes.

**OpenPose folders** (:func:`load_openpose`): one folder per camera (views in the order of
the folders' names, natural order: ``cam2`` before ``cam10``) of one JSON file per frame,
``{"people": [{"pose_keypoints_2d": [x0, y0, c0, x1, y1, c1, …]}, …]}`` with ``J``
keypoints per person (BODY_25, BODY_25B, COCO-17 or any ``J``). The frame number of a
file is the last run of digits in its name (``cam01.0012.json``, ``video_000000000012_keypoints.json``);
frames missing in a camera are empty views there. Each person's keypoint ``j`` in a view
is a candidate of class ``j`` in slot ``person · J + j`` (the person's index in one view
is not an identity across views; association decides); ``instances`` holds that index
(``associate_classes(..., instances=, person_vote=True)``). Score 0 means not detected.

**Tables** (:func:`load_keypoint_table`): one detection per row, ``frame, view, class,
x, y`` and optional ``score`` and ``instance`` (an int ``>= -1``: the 2D skeleton of the
detection in its view, -1 unknown): a CSV with that header (``#`` lines are comments), or
an NPZ with 1-D arrays of those names (``xy (N, 2)`` may replace ``x`` and ``y``).
``view`` is the rig's view index (from 0); ``class`` an int id or a name; ``frame`` any
integer (frames are the distinct numbers, in increasing order). A row with score 0 is
not a detection. Slots of a view are its rows in file order.

Scores: any finite score ``>= 0`` is accepted and mapped to [0, 1] by
:func:`cdog_jax.io._scores.normalise_keypoint_scores` (probabilities kept, a larger scale
divided by the file's largest score; a note says so).
"""

from __future__ import annotations

import csv
import os
import re
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._expect import PATH, expect_args
from ._class_labels import check_names
from ._detections_checks import _finish, few_views_note
from ._detections_rows import _check_coordinates, _check_options
from ._detections_type import Detections
from ._errors import InputError, _Where, read_text
from ._read_files import check_keys, open_npz, read_json
from ._scores import (
    SCORE_TOLERANCE,
    clipped_scores_note,
    normalise_keypoint_scores,
    scaled_scores_note,
)

PathLike = str | os.PathLike

# Keypoint names by id of the common skeletons (OpenPose's and COCO's orders).
SKELETONS: dict[str, tuple[str, ...]] = {
    "BODY_25": (
        "Nose",
        "Neck",
        "RShoulder",
        "RElbow",
        "RWrist",
        "LShoulder",
        "LElbow",
        "LWrist",
        "MidHip",
        "RHip",
        "RKnee",
        "RAnkle",
        "LHip",
        "LKnee",
        "LAnkle",
        "REye",
        "LEye",
        "REar",
        "LEar",
        "LBigToe",
        "LSmallToe",
        "LHeel",
        "RBigToe",
        "RSmallToe",
        "RHeel",
    ),
    "BODY_25B": (
        "Nose",
        "LEye",
        "REye",
        "LEar",
        "REar",
        "LShoulder",
        "RShoulder",
        "LElbow",
        "RElbow",
        "LWrist",
        "RWrist",
        "LHip",
        "RHip",
        "LKnee",
        "RKnee",
        "LAnkle",
        "RAnkle",
        "Neck",
        "Head",
        "LBigToe",
        "LSmallToe",
        "LHeel",
        "RBigToe",
        "RSmallToe",
        "RHeel",
    ),
    "COCO_17": (
        "nose",
        "left_eye",
        "right_eye",
        "left_ear",
        "right_ear",
        "left_shoulder",
        "right_shoulder",
        "left_elbow",
        "right_elbow",
        "left_wrist",
        "right_wrist",
        "left_hip",
        "right_hip",
        "left_knee",
        "right_knee",
        "left_ankle",
        "right_ankle",
    ),
}
TABLE_COLUMNS = ("frame", "view", "class", "x", "y", "score", "instance")
_DIGITS = re.compile(r"\d+")
TABLE_INT_LIMIT = 2**31
"""Frames, views and instances of a table are integers of magnitude below this (32 bits): a
larger one is a corrupt or misread column, not a frame number."""
MAX_VIEWS = 1024
"""The most views a table may name when the number of views is not given (a rig gives it):
the views are allocated up to the largest index."""


def natural_key(name: str) -> list:
    """Sort key that orders the digit runs of ``name`` by value (``cam2`` < ``cam10``)."""
    return [int(p) if p.isdigit() else p for p in re.split(r"(\d+)", name)]


def load_openpose(
    path: PathLike | Sequence[PathLike],
    *,
    keypoints: str | Sequence[str] | None = None,
    num_views: int | None = None,
    capacity: int | None = None,
    image_size: tuple[int, int] | None = None,
) -> Detections:
    """Read OpenPose JSON folders, one per camera (module docstring), as classed detections.

    Args:
        path: a folder whose sub-folders holding ``.json`` files are the cameras (natural
            order of their names), or a list of camera folders in view order.
        keypoints: names of the ``J`` keypoint types: a skeleton of :data:`SKELETONS`
            (``"BODY_25"``, ``"BODY_25B"``, ``"COCO_17"``) or a list; ``None``: ids only.
        num_views, capacity, image_size: as in :func:`cdog_jax.io.load_detections`
            (``capacity`` counts slots ``person · J + j``).

    Returns:
        :class:`Detections` ``(F, M, P = people · J)`` with ``classes`` (``j`` per slot),
        ``instances`` (the person's index in the view), ``class_names`` and ``frame_ids`` (the files' frame numbers). Raises
        :class:`InputError` naming the file (and person, keypoint) for a file without
        ``people``, a ``pose_keypoints_2d`` whose length is not ``3 J``, a non-numeric
        value, a negative or non-finite score, a camera folder without JSON files, two
        files of one camera with the same frame number, or a view count other than
        ``num_views``.
    """
    _check_options("auto", capacity, num_views, image_size)
    files = _OpenPoseFiles(path, num_views)
    rows, classes, instances, J = files.rows(slice(None))
    names = _keypoint_names(keypoints, J, files.source)
    where = _Where(files.source, True)
    return _keypoint_detections(
        rows,
        classes,
        names,
        files.frame_ids,
        where,
        [files.note(J)],
        capacity,
        image_size,
        instances,
    )


class _OpenPoseFiles:
    """The camera folders of an OpenPose recording and each camera's file of every frame
    (listed, not read): ``frame_ids`` the frame numbers in order."""

    def __init__(self, path: Any, num_views: int | None):
        self.cameras = _camera_folders(path)
        self.source = (
            os.fspath(path) if isinstance(path, (str, os.PathLike)) else os.fspath(self.cameras[0])
        )
        if num_views is not None and len(self.cameras) != num_views:
            raise InputError(
                f"{self.source}: {len(self.cameras)} camera folders; the rig has {num_views} views (num_views)"
            )
        self.files = [_frame_files(folder) for folder in self.cameras]  # {frame number: file}
        self.frame_ids = np.array(sorted(set().union(*(f.keys() for f in self.files))), np.int64)
        self._J: int | None = None
        self._first: str | None = None

    def note(self, J: int) -> str:
        names = ", ".join(os.path.basename(os.path.normpath(c)) for c in self.cameras)
        return f"{len(self.cameras)} cameras {names}; {J} keypoint types"

    def rows(self, frames: slice, most: int | None = None, need_people: bool = True):
        """The files of ``frames`` (a slice of ``frame_ids``) read: rows ``(F, M, most · J, 3)``
        ``[x, y, score]`` (``most``: people per view, default the most in these files), each
        slot's class and instance, and ``J`` (every file's keypoint count, checked against
        the first file read with a person); ``J`` is None when no file read has a person and
        not ``need_people``."""
        ids = self.frame_ids[frames]
        row_of = {int(n): k for k, n in enumerate(ids)}
        people: dict[tuple[int, int], list[np.ndarray]] = {}
        for m, per_frame in enumerate(self.files):
            for number in ids.tolist():
                file = per_frame.get(number)
                if file is None:
                    continue
                persons = _read_people(file)
                for p, flat in enumerate(persons):
                    if flat.size == 0:
                        continue
                    if flat.size % 3:
                        raise InputError(
                            f"{file}: person {p}: pose_keypoints_2d has {flat.size} numbers; expected [x, y, score] × J"
                        )
                    if self._J is None:
                        self._J, self._first = flat.size // 3, file
                    elif flat.size != 3 * self._J:
                        raise InputError(
                            f"{file}: person {p}: {flat.size // 3} keypoints; {self._first} has {self._J}"
                        )
                people[row_of[number], m] = persons
        J = self._J
        if J is None:
            if need_people:
                raise InputError(f"{self.source}: no person with keypoints in any file")
            return None, None, None, None
        found = max((sum(1 for a in persons if a.size) for persons in people.values()), default=0)
        most = max(1, found) if most is None else most
        F, M = len(ids), len(self.cameras)
        rows = np.zeros((F, M, most * J, 3))
        for (f, m), persons in people.items():
            kept = [a for a in persons if a.size]
            if kept:
                rows[f, m, : len(kept) * J] = np.concatenate(kept).reshape(-1, 3)
        classes = np.broadcast_to(np.arange(most * J) % J, (F, M, most * J)).copy()
        instances = np.broadcast_to(np.arange(most * J) // J, (F, M, most * J)).copy()
        return rows, classes, instances, J


class OpenPoseParts:
    """An OpenPose recording read a part at a time (a long recording in the memory of one
    part), each part what :func:`load_openpose` gives for those frames of the whole: the
    same checks, messages and notes with frames counted over the whole recording, scores
    scaled by the whole's largest, every part ``most people · J`` slots wide (or
    ``capacity``).

    Every file is read twice: all of them, part by part, when the object is made (so that
    a bad file is refused before any work, and the recording's people and scores are
    known), then each part again by :meth:`read`. ``inspect(frames, detections)``, when
    given, is called on every part in the first reading (its scores as yet scaled by the
    part's own largest). ``parts``: the parts' frame slices; ``notes``: the whole
    recording's notes; ``frame_ids``: every frame's number; ``J``: the keypoint types."""

    def __init__(
        self,
        path: Any,
        *,
        part_frames: int,
        keypoints: Any = None,
        num_views: int | None = None,
        capacity: int | None = None,
        image_size: tuple[int, int] | None = None,
        inspect: Any = None,
    ):
        _check_options("auto", capacity, num_views, image_size)
        self._files = files = _OpenPoseFiles(path, num_views)
        self.frame_ids = files.frame_ids
        F = len(files.frame_ids)
        self.parts = [slice(s, min(F, s + part_frames)) for s in range(0, F, part_frames)]
        self._image_size = image_size
        self.class_names = None  # known once every file is read (the keypoint count)
        most, largest, paired, notes = 1, 0.0, False, []
        clipped, clipped_top = 0, 0.0  # scores in (1, SCORE_TOLERANCE]
        hopeless = [np.zeros(0, np.int64)]  # frames without detections in 2 views
        for part in self.parts:
            rows, classes, instances, J = files.rows(part, need_people=False)
            if rows is None:
                continue
            score = rows[..., 2]
            mask = score != 0.0
            most = max(most, rows.shape[2] // J)  # the part's most people in one file
            own = float(score[mask].max()) if mask.any() else 0.0
            largest = max(largest, own)
            above = mask & (score > 1.0) & (score <= SCORE_TOLERANCE)
            clipped += int(above.sum())
            clipped_top = max(clipped_top, float(score[above].max()) if above.any() else 0.0)
            det = self._detections(part, rows, classes, instances, J, capacity, own, notes)
            if inspect is not None:  # the caller's own checks and tallies of every part
                inspect(part, det)
            few = np.flatnonzero((det.counts > 0).sum(axis=1) < 2)
            hopeless.append(few + part.start)
            paired |= len(few) < len(det.counts)
        if files._J is None:
            raise InputError(f"{files.source}: no person with keypoints in any file")
        if not paired:
            raise InputError(
                f"{files.source}: no frame has detections in 2 views (of {F} frames); association needs at least 2"
            )
        self.J = files._J
        self.class_names = _keypoint_names(keypoints, self.J, files.source)
        self.capacity = capacity
        self._largest = largest if largest > SCORE_TOLERANCE else None
        if self._largest is not None:
            scaled = [scaled_scores_note(largest)]
        else:
            scaled = [clipped_scores_note(clipped, clipped_top)] if clipped else []
        numbering = _numbering_note(files.frame_ids)
        hopeless = np.concatenate(hopeless)
        few = [few_views_note(hopeless, F)] if hopeless.size else []
        self.notes = [
            files.note(self.J),
            *scaled,
            *([numbering] if numbering else []),
            *notes,
            *few,
        ]
        self._most = most

    def _detections(self, part, rows, classes, instances, J, capacity, largest, notes):
        where = _Where(self._files.source, True, part.start)
        return _keypoint_detections(
            rows,
            classes,
            self.class_names,
            self.frame_ids[part],
            where,
            notes,
            capacity,
            self._image_size,
            instances,
            largest=largest,
            part=True,
        )

    def read(self, k: int) -> Detections:
        """Part ``k``: :class:`Detections` of its frames (``frame_ids`` their numbers)."""
        part = self.parts[k]
        rows, classes, instances, _ = self._files.rows(part, most=self._most)
        det = self._detections(
            part, rows, classes, instances, self.J, self.capacity, self._largest, []
        )
        return det._replace(notes=[])


def load_keypoint_table(
    path: PathLike,
    *,
    num_views: int | None = None,
    capacity: int | None = None,
    image_size: tuple[int, int] | None = None,
) -> Detections:
    """Read a table of detections ``frame, view, class, x, y[, score]`` (CSV or NPZ by
    suffix; module docstring) as classed detections ``(F, M, P)``.

    ``M`` is ``num_views`` when given (a larger view index raises), else the largest view
    index + 1. Raises :class:`InputError` naming the file and the row (CSV: its line) for
    a missing column, a non-integer frame or view, a negative view, a bad class, a
    non-numeric or non-finite coordinate, or a bad score.
    """
    expect_args("load_keypoint_table", path=(path, PATH))
    _check_options("auto", capacity, num_views, image_size)
    path = os.fspath(path)
    suffix = os.path.splitext(path)[1].lower()
    if suffix == ".csv":
        columns, row_names = _read_csv_table(path)
    elif suffix == ".npz":
        columns, row_names = _read_npz_table(path)
    else:
        raise InputError(f"{path}: cannot tell the table format; expected a .csv or .npz file")
    return _from_table(path, columns, row_names, num_views, capacity, image_size)


# OpenPose ----------------------------------------------------------------------------------


def _camera_folders(path: Any) -> list[str]:
    if isinstance(path, (str, os.PathLike)):
        path = os.fspath(path)
        if not os.path.isdir(path):
            raise InputError(
                f"{path}: not a folder (expected a folder of camera folders of OpenPose JSON files)"
            )
        subs = [
            os.path.join(path, d) for d in os.listdir(path) if os.path.isdir(os.path.join(path, d))
        ]
        cameras = sorted(
            (d for d in subs if _json_names(d)), key=lambda d: natural_key(os.path.basename(d))
        )
        if len(cameras) < 2:
            raise InputError(
                f"{path}: {len(cameras)} sub-folder(s) with .json files; expected one folder per camera (at least 2)"
            )
        return cameras
    if not isinstance(path, (list, tuple)) or not all(
        isinstance(p, (str, os.PathLike)) for p in path
    ):
        raise TypeError(
            f"load_openpose: path must be a folder or a list of camera folders; got {type(path).__name__}"
        )
    cameras = [os.fspath(p) for p in path]
    for c in cameras:
        if not os.path.isdir(c):
            raise InputError(f"{c}: not a folder (expected a camera folder of OpenPose JSON files)")
    if len(cameras) < 2:
        raise InputError(f"{len(cameras)} camera folder(s); association needs at least 2")
    return cameras


def _json_names(folder: str) -> list[str]:
    return [n for n in os.listdir(folder) if n.lower().endswith(".json")]


def _frame_files(folder: str) -> dict[int, str]:
    names = _json_names(folder)
    if not names:
        raise InputError(f"{folder}: no .json files (expected one OpenPose file per frame)")
    out: dict[int, str] = {}
    for name in sorted(names, key=natural_key):
        digits = _DIGITS.findall(os.path.splitext(name)[0])
        file = os.path.join(folder, name)
        if not digits:
            raise InputError(
                f"{file}: no frame number in the file name (expected digits, as in cam01.0012.json)"
            )
        number = int(digits[-1])
        if number in out:
            raise InputError(f"{file}: frame number {number} again (also {out[number]})")
        out[number] = file
    return out


def _read_people(file: str) -> list[np.ndarray]:
    data = read_json(file)
    if not isinstance(data, dict) or not isinstance(data.get("people"), list):
        raise InputError(
            f'{file}: expected an OpenPose object {{"people": [{{"pose_keypoints_2d": […]}}, …]}}'
        )
    out = []
    for p, person in enumerate(data["people"]):
        flat = person.get("pose_keypoints_2d") if isinstance(person, dict) else None
        if not isinstance(flat, list):
            raise InputError(f'{file}: person {p}: no list "pose_keypoints_2d"')
        for k, v in enumerate(flat):
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise InputError(
                    f"{file}: person {p}: pose_keypoints_2d[{k}] = {v!r} is not a number"
                )
        out.append(np.asarray(flat, np.float64))
    return out


def _keypoint_names(keypoints: Any, J: int, source: str) -> tuple[str, ...] | None:
    if keypoints is None:
        return None
    if isinstance(keypoints, str):
        if keypoints not in SKELETONS:
            raise ValueError(
                f"keypoints must be one of {tuple(SKELETONS)} or a list of names; got {keypoints!r}"
            )
        names = SKELETONS[keypoints]
    else:
        names = check_names(list(keypoints), lambda text, *_: ValueError(f"keypoints: {text}"))
    if len(names) != J:
        raise InputError(
            f"{source}: the files have {J} keypoints per person; keypoints={keypoints!r} names {len(names)}"
        )
    return tuple(names)


def _keypoint_detections(
    rows,
    classes,
    names,
    frame_ids,
    where,
    notes,
    capacity,
    image_size,
    instances=None,
    largest: float | None = None,
    part: bool = False,
) -> Detections:
    """Rows ``(F, M, P, 3)`` ``[x, y, score]`` (score 0: none) as :class:`Detections`
    (``largest``, ``part``: a part of a longer recording, as :class:`OpenPoseParts` reads it)."""
    score = rows[..., 2]
    mask = score != 0.0
    conf, note = normalise_keypoint_scores(score, mask, where.error, largest)
    notes += [note] if note and not part else []  # a part's: said once for the whole
    _check_coordinates(rows[..., :2], mask, where, "where the score is not 0")
    numbering = None if part else _numbering_note(frame_ids)
    notes += [numbering] if numbering else []
    return _finish(
        rows[..., :2],
        mask,
        conf,
        True,
        where,
        notes,
        capacity,
        image_size,
        classes,
        names,
        frame_ids,
        instances,
        part,
    )


def _numbering_note(frame_ids: np.ndarray) -> str | None:
    """The note of frames numbered otherwise than 0, 1, … in the files."""
    if np.array_equal(frame_ids, np.arange(len(frame_ids))):
        return None
    return f"frames numbered {_ranges(frame_ids)} in the files are frames 0…{len(frame_ids) - 1} here (frame_ids)"


def _ranges(ids: np.ndarray) -> str:
    return f"{ids[0]}…{ids[-1]}" + (
        "" if ids[-1] - ids[0] + 1 == len(ids) else f" ({len(ids)} of them, with gaps)"
    )


# Tables ------------------------------------------------------------------------------------


def _read_csv_table(path: str) -> tuple[dict[str, list], list[str]]:
    lines = [
        (k + 1, line)
        for k, line in enumerate(read_text(path).splitlines())
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not lines:
        raise InputError(
            f"{path}: empty table (expected a header {', '.join(TABLE_COLUMNS)} and rows)"
        )
    rows = list(csv.reader([line for _, line in lines]))
    header = [h.strip().lower() for h in rows[0]]
    twice = next((c for k, c in enumerate(header) if c in header[:k]), None)
    if twice is not None:
        raise InputError(f'{path}: line {lines[0][0]}: the column "{twice}" appears twice')
    check_keys(dict.fromkeys(header), TABLE_COLUMNS, f"{path}: line {lines[0][0]}", "column")
    missing = [c for c in TABLE_COLUMNS[:5] if c not in header]
    if missing:
        raise InputError(
            f"{path}: line {lines[0][0]}: header {rows[0]} lacks column(s) {', '.join(missing)} "
            f"(expected {', '.join(TABLE_COLUMNS)}, score and instance optional)"
        )
    index = {c: header.index(c) for c in TABLE_COLUMNS if c in header}
    columns: dict[str, list] = {c: [] for c in index}
    for (line, _), row in zip(lines[1:], rows[1:]):
        if len(row) != len(header):
            raise InputError(
                f"{path}: line {line}: {len(row)} fields; the header has {len(header)}"
            )
        for c, k in index.items():
            columns[c].append(row[k].strip())
    return columns, [f"line {line}" for line, _ in lines[1:]]


def _read_npz_table(path: str) -> tuple[dict[str, list], list[str]]:
    with open_npz(path) as npz:
        arrays = {k: npz[k] for k in npz.files}
    if "xy" in arrays and "x" not in arrays:
        xy = arrays.pop("xy")
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise InputError(f'{path}: array "xy": expected shape (N, 2); got {xy.shape}')
        arrays["x"], arrays["y"] = xy[:, 0], xy[:, 1]
    check_keys(arrays, TABLE_COLUMNS, path, "array")
    missing = [c for c in TABLE_COLUMNS[:5] if c not in arrays]
    if missing:
        raise InputError(
            f"{path}: no array(s) {', '.join(missing)} (expected 1-D arrays {', '.join(TABLE_COLUMNS)}, score and instance optional)"
        )
    N = len(arrays["frame"])
    for c in TABLE_COLUMNS:
        if c in arrays and (arrays[c].ndim != 1 or len(arrays[c]) != N):
            raise InputError(
                f'{path}: array "{c}": expected shape ({N},) like "frame"; got {arrays[c].shape}'
            )
    return {c: arrays[c].tolist() for c in TABLE_COLUMNS if c in arrays}, [
        f"row {k}" for k in range(N)
    ]


def _from_table(path, columns, row_names, num_views, capacity, image_size) -> Detections:
    N = len(row_names)
    if N == 0:
        raise InputError(f"{path}: no rows")

    def numbers(name: str, integer: bool) -> np.ndarray:
        out = np.empty(N, np.int64 if integer else np.float64)
        for k, v in enumerate(columns[name]):
            try:
                x = float(v) if not isinstance(v, (int, np.integer)) else v
            except (TypeError, ValueError):
                x = None
            if (
                x is None
                or isinstance(v, bool)
                or (integer and (not np.isfinite(x) or x != int(x)))
            ):
                raise InputError(
                    f"{path}: {row_names[k]}: {name} {v!r} is not {'an integer' if integer else 'a number'}"
                )
            if integer and not -TABLE_INT_LIMIT < x < TABLE_INT_LIMIT:
                raise InputError(
                    f"{path}: {row_names[k]}: {name} {v!r} is out of range (a 32-bit integer)"
                )
            out[k] = int(x) if integer else x
        return out

    frame, view = numbers("frame", True), numbers("view", True)
    x, y = numbers("x", False), numbers("y", False)
    score = numbers("score", False) if "score" in columns else np.ones(N)
    instance = numbers("instance", True) if "instance" in columns else None
    if instance is not None and (instance < -1).any():
        k = int(np.flatnonzero(instance < -1)[0])
        raise InputError(
            f"{path}: {row_names[k]}: instance {instance[k]} must be >= -1 (-1: unknown)"
        )
    bad = (view < 0) | (view >= (MAX_VIEWS if num_views is None else num_views))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        rule = (
            f"in 0…{MAX_VIEWS - 1} (without num_views, the most views a table may name)"
            if num_views is None
            else f"in 0…{num_views - 1} (the rig has {num_views} views)"
        )
        raise InputError(f"{path}: {row_names[k]}: view {view[k]} must be {rule}")
    cls, names = _table_classes(columns["class"], row_names, path)
    frame_ids, f_of = np.unique(frame, return_inverse=True)
    M = num_views if num_views is not None else int(view.max()) + 1
    F = len(frame_ids)
    order = np.lexsort((np.arange(N), view, f_of))  # rows of one (frame, view) in file order
    start = np.r_[0, np.flatnonzero(np.diff(f_of[order] * M + view[order])) + 1]
    rank = np.arange(N) - np.repeat(start, np.diff(np.r_[start, N]))
    slot = np.empty(N, np.int64)
    slot[order] = rank
    P = int(slot.max()) + 1
    rows = np.zeros((F, M, P, 3))
    classes = np.full((F, M, P), -1, np.int64)
    rows[f_of, view, slot] = np.stack([x, y, score], axis=-1)
    classes[f_of, view, slot] = cls
    instances = None
    if instance is not None:
        instances = np.full((F, M, P), -1, np.int64)
        instances[f_of, view, slot] = instance
    bad = ~np.isfinite(x) | ~np.isfinite(y)
    bad &= score != 0.0
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise InputError(
            f"{path}: {row_names[k]}: ({x[k]}, {y[k]}) is not finite (a row that is no detection has score 0)"
        )
    rows[..., :2] = np.where(np.isfinite(rows[..., :2]), rows[..., :2], 0.0)
    where = _Where(path, True)
    return _keypoint_detections(
        rows, classes, names, frame_ids.astype(np.int64), where, [], capacity, image_size, instances
    )


def _table_classes(
    values: list, row_names: list[str], path: str
) -> tuple[np.ndarray, tuple[str, ...] | None]:
    """Class ids of the rows: all integers ``>= 0`` (ids), else names (ids by first appearance)."""
    ids = []
    for v in values:
        try:
            ids.append(int(v) if not isinstance(v, float) or v == int(v) else None)
        except (TypeError, ValueError):
            ids.append(None)
    if all(i is not None and i >= 0 for i in ids):
        return np.asarray(ids, np.int64), None
    if all(isinstance(v, str) for v in values):
        numeric = [k for k, i in enumerate(ids) if i is not None]
        if numeric and len(numeric) < len(ids):
            k = numeric[0]
            raise InputError(
                f"{path}: {row_names[k]}: class {values[k]!r}: the table mixes class ids and class names; use one kind"
            )
        empty = [k for k, v in enumerate(values) if not v]
        if empty:
            raise InputError(f"{path}: {row_names[empty[0]]}: empty class")
        names = tuple(dict.fromkeys(values))
        index = {n: k for k, n in enumerate(names)}
        return np.asarray([index[v] for v in values], np.int64), names
    k = next(k for k, i in enumerate(ids) if i is None or i < 0)
    raise InputError(
        f"{path}: {row_names[k]}: class {values[k]!r} is neither an int >= 0 nor a name"
    )
