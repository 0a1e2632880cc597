"""Marker trajectories as ``.trc`` files, the text format OpenSim and Pose2Sim read.

Layout (tab-separated): ``PathFileType 4 (X/Y/Z) <file name>``; the header keys
``DataRate CameraRate NumFrames NumMarkers Units OrigDataRate OrigDataStartFrame
OrigNumFrames`` and their values; ``Frame# Time`` and the marker names (each followed by two
empty columns); ``X1 Y1 Z1 X2 …``; an empty line; then one row per frame: the frame number
(from 1), the time in seconds and the three coordinates of every marker, empty where the
marker is not seen (as Pose2Sim writes a missing marker).

OpenSim's world has Y up; ``z_up=True`` turns a Z-up world (a floor at ``z = 0``) into it as
Pose2Sim does: ``(x, y, z) → (y, z, x)``, a rotation (no mirror).
"""

from __future__ import annotations

import math
import os
from typing import Any, NamedTuple

import numpy as np

from .._expect import PATH, expect_args
from ._atomic import atomic_write
from ._errors import InputError

PathLike = str | os.PathLike  # a file name

_HEADER_KEYS = (
    "DataRate",
    "CameraRate",
    "NumFrames",
    "NumMarkers",
    "Units",
    "OrigDataRate",
    "OrigDataStartFrame",
    "OrigNumFrames",
)


class Trc(NamedTuple):
    """What :func:`load_trc` returns: ``markers (F, K, 3)`` (NaN where not seen), ``names``
    (``K``), ``rate`` (frames per second), ``units``, ``frame (F,)`` the frame numbers and
    ``time (F,)`` seconds."""

    markers: np.ndarray
    names: tuple[str, ...]
    rate: float
    units: str
    frame: np.ndarray
    time: np.ndarray


def save_trc(
    path: PathLike,
    markers: Any,
    names: Any,
    *,
    rate: float | int,
    units: str = "m",
    z_up: bool = False,
) -> None:
    """Write ``markers (F, K, 3)`` (scene units; NaN: not seen in that frame) named ``names``
    (``K`` strings: no tab, no line break, not empty, no two alike) as a ``.trc`` file of
    ``rate`` frames per second; ``units`` is written in the header (``"m"``, ``"mm"``, …);
    ``z_up``: the world's up axis is Z, written as OpenSim's Y (module docstring)."""
    expect_args("save_trc", path=(path, PATH))
    X = np.asarray(markers, np.float64)
    if X.ndim != 3 or X.shape[2] != 3:
        raise ValueError(f"save_trc: markers must have shape (F, K, 3); got {X.shape}")
    _save_trc_rows(path, lambda: iter((X,)), X.shape[0], names, rate, units, z_up)


def _save_trc_rows(
    path: PathLike, blocks: Any, F: int, names: Any, rate: Any, units: Any, z_up: bool
) -> None:
    """:func:`save_trc` of the ``F`` frames that ``blocks()`` yields a block at a time
    (``(F_k, K, 3)`` arrays, frames in order; called once the arguments are checked)."""
    names = tuple(str(n) for n in names)
    bad = [n for n in names if not n or any(c in n for c in "\t\r\n")]
    if bad:
        raise ValueError(
            f"save_trc: a marker name must be non-empty text without tabs or line breaks; got {bad[0]!r}"
        )
    if len(set(names)) != len(names):
        raise ValueError(
            f"save_trc: marker names must be distinct; {sorted(n for n in set(names) if names.count(n) > 1)[0]!r} repeats"
        )
    if (
        isinstance(rate, bool)
        or not isinstance(rate, (int, float))
        or not (rate > 0 and math.isfinite(rate))
    ):
        raise ValueError(f"save_trc: rate must be a number of frames per second > 0; got {rate!r}")
    if not isinstance(units, str) or not units or any(c.isspace() for c in units):
        raise ValueError(f"save_trc: units must be a word such as 'm' or 'mm'; got {units!r}")
    K = len(names)
    for X in blocks():  # checked whole before the file is opened
        if X.shape[1:] != (K, 3):
            raise ValueError(f"save_trc: {X.shape[1]} markers need {X.shape[1]} names; got {K}")
        if np.isinf(X).any():
            raise ValueError(
                "save_trc: markers hold an infinite coordinate (NaN marks a marker not seen)"
            )
    values = (_number(rate), _number(rate), F, K, units, _number(rate), 1, F)
    lines = [
        "\t".join(("PathFileType", "4", "(X/Y/Z)", os.path.basename(os.fspath(path)))),
        "\t".join(_HEADER_KEYS),
        "\t".join(str(v) for v in values),
        "\t".join(("Frame#", "Time", *(f"{n}\t\t" for n in names))).rstrip("\t"),
        "\t\t" + "\t".join(f"X{k}\tY{k}\tZ{k}" for k in range(1, K + 1)),
        "",
    ]
    with atomic_write(path, "w", newline="") as f:
        f.write("\n".join(lines) + "\n")
        i = 0
        for X in blocks():
            X = np.asarray(X, np.float64)
            if z_up:
                X = X[..., [1, 2, 0]]
            for frame in X:
                row = [str(i + 1), repr(round(i / rate, 9))]
                row += ["" if math.isnan(v) else repr(float(v)) for v in frame.reshape(-1)]
                f.write("\t".join(row) + "\n")
                i += 1


def load_trc(path: PathLike) -> Trc:
    """Read a ``.trc`` file (as :func:`save_trc` writes it, or OpenSim's and Pose2Sim's):
    empty or ``NaN`` coordinates are NaN. Raises :class:`InputError` naming the file and
    line for a header that is not a TRC header, a row of the wrong length or a value that is
    not a number."""
    expect_args("load_trc", path=(path, PATH))
    path = os.fspath(path)
    with open(path, encoding="utf-8-sig") as f:
        lines = f.read().splitlines()
    if len(lines) < 5 or not lines[0].startswith("PathFileType"):
        raise InputError(f"{path}: not a TRC file (the first line must start with PathFileType)")
    keys, values = lines[1].split("\t"), lines[2].split("\t")
    header = dict(zip(keys, values))
    missing = [k for k in ("DataRate", "NumMarkers", "Units") if k not in header]
    if missing:
        raise InputError(f"{path}: line 2: the TRC header has no {', '.join(missing)}")
    try:
        rate, K = float(header["DataRate"]), int(header["NumMarkers"])
    except ValueError:
        raise InputError(
            f"{path}: line 3: DataRate and NumMarkers must be numbers; got {header['DataRate']!r}, {header['NumMarkers']!r}"
        ) from None
    names = tuple(n for n in lines[3].split("\t")[2:] if n)
    if len(names) != K:
        raise InputError(f"{path}: line 4 names {len(names)} markers; the header says {K}")
    rows = []
    for number, line in enumerate(lines[5:], start=6):
        if not line.strip():
            continue
        cells = line.split("\t")
        cells += [""] * (2 + 3 * K - len(cells))  # trailing empty markers may be cut
        if len(cells) != 2 + 3 * K:
            raise InputError(
                f"{path}: line {number}: {len(cells)} columns; {2 + 3 * K} expected (frame, time, x y z of {K} markers)"
            )
        try:
            rows.append([float(c) if c.strip() else math.nan for c in cells])
        except ValueError:
            raise InputError(f"{path}: line {number}: a value is not a number") from None
    data = np.asarray(rows, np.float64).reshape(len(rows), 2 + 3 * K)
    return Trc(
        data[:, 2:].reshape(len(rows), K, 3),
        names,
        rate,
        header["Units"],
        data[:, 0].astype(np.int64),
        data[:, 1],
    )


def _number(v: float | int) -> str:
    return str(int(v)) if float(v).is_integer() else repr(float(v))


def person_markers(people: Any) -> dict[int, np.ndarray]:
    """``{person id: (F, C, 3)}`` the skeleton of every person of a :class:`cdog_jax.People`
    over all its frames (NaN where the person or the joint is not seen)."""
    points, ids = np.asarray(people.points), np.asarray(people.person_id)
    return {
        pid: _person_rows(points, ids, pid)
        for pid in range(int(people.num_people))
        if np.any(ids == pid)
    }


def _person_rows(points: np.ndarray, ids: np.ndarray, pid: int) -> np.ndarray:
    """``(F, C, 3)`` person ``pid``'s joints in every frame of ``points (F, N, C, 3)`` whose
    rows ``ids (F, N)`` name it (NaN in frames without it)."""
    X = np.full((points.shape[0],) + points.shape[2:], np.nan, points.dtype)
    f, n = np.nonzero(ids == pid)
    X[f] = points[f, n]
    return X


def marker_names(class_names: Any, num_classes: int) -> tuple[str, ...]:
    """The class names as marker names, ``class<k>`` where names are not known."""
    return (
        tuple(class_names)
        if class_names is not None
        else tuple(f"class{k}" for k in range(num_classes))
    )


def save_people_trc(
    path: PathLike, people: Any, *, rate: float | int, units: str = "m", z_up: bool = False
) -> list[str]:
    """One ``.trc`` file per person of a :class:`cdog_jax.People` (the joints its markers,
    named by class): ``<path's stem>_person<id>.trc`` beside ``path``, every file over all
    frames (a person's rows are empty where it is not seen). Returns the paths written."""
    stem, _ = os.path.splitext(os.fspath(path))
    names = marker_names(people.class_names, np.asarray(people.points).shape[2])
    written = []
    for pid, X in person_markers(people).items():
        target = f"{stem}_person{pid}.trc"
        save_trc(target, X, names, rate=rate, units=units, z_up=z_up)
        written.append(target)
    return written


def track_markers(tracked: Any) -> tuple[np.ndarray, tuple[str, ...]]:
    """``(F, T, 3)`` the point of every track of a :class:`cdog_jax.TrackedAssociation` in
    every frame (NaN where not seen) and the markers' names: ``<class name>_<track>`` with
    classes, ``track<id>`` without."""
    out, cls = _track_points(tracked)
    return out, _track_names(tracked, cls)


def _track_points(tracked: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(F, T, 3)`` the point of every track in every frame (NaN where not seen) and
    ``(T,)`` each track's class (−1: none, or not seen in these frames)."""
    a = tracked.association
    valid, tid, X = np.asarray(a.valid), np.asarray(tracked.track_id), np.asarray(a.points3d)
    F, T = valid.shape[0], int(tracked.num_tracks)
    out = np.full((F, T, 3), np.nan, X.dtype)
    f, g = np.nonzero(valid & (tid >= 0))
    out[f, tid[f, g]] = X[f, g]
    cls = np.full(T, -1)
    if tracked.group_class is not None:
        cls[tid[f, g]] = np.asarray(tracked.group_class)[f, g]
    return out, cls


def _track_names(tracked: Any, cls: np.ndarray) -> tuple[str, ...]:
    """The markers' names of :func:`track_markers` for tracks of classes ``cls (T,)``."""
    if tracked.group_class is None:
        return tuple(f"track{t}" for t in range(len(cls)))
    names = marker_names(tracked.class_names, int(tracked.num_classes))
    return tuple(f"{names[c] if c >= 0 else 'class'}_{t}" for t, c in enumerate(cls))


class TrcParts:
    """The ``.trc`` output of a recording given a part at a time (:meth:`add`: each part's
    tracked association and people, frames in order), kept on disk in ``folder`` until
    :meth:`write_people` or :meth:`write_tracks` writes the files: what
    :func:`save_people_trc` and :func:`save_trc` of :func:`track_markers` write of the whole
    recording. Memory: one part's arrays at a time."""

    def __init__(self, folder: str):
        self.folder = folder
        self.parts: list[tuple[int, str]] = []  # (frames, file)
        self.tracked = self.people = None  # the last part's: its names and counts
        self.track_class = np.zeros(0, np.int64)  # each track's class, over all parts
        self.person_ids: set[int] = set()

    def add(self, tracked: Any, xy: Any = None, mask: Any = None, **details: Any) -> None:
        """One part: ``tracked`` (a :class:`cdog_jax.TrackedAssociation`) and, in
        ``details``, ``people`` (a :class:`cdog_jax.People` or None); the detections and
        other keywords (those of :class:`NpzParts`) are not written to a ``.trc``."""
        people = details.get("people")
        ext = ".npy" if people is None else ".npz"
        file = os.path.join(self.folder, f"{len(self.parts)}{ext}")
        if people is not None:
            points, ids = np.asarray(people.points), np.asarray(people.person_id)
            np.savez(file, points=points, person_id=ids)
            self.person_ids.update(int(i) for i in np.unique(ids[ids >= 0]))
            self.people = people
            frames = points.shape[0]
        else:
            markers, cls = _track_points(tracked)
            np.save(file, markers)
            grown = np.full(len(cls), -1, np.int64)
            grown[: len(self.track_class)] = self.track_class
            self.track_class = np.where(grown >= 0, grown, cls)
            self.tracked = tracked
            frames = markers.shape[0]
        self.parts.append((frames, file))

    @property
    def frames(self) -> int:
        return sum(n for n, _ in self.parts)

    def people_files(self, path: PathLike) -> list[str]:
        """The files :meth:`write_people` writes: one per person seen."""
        stem, _ = os.path.splitext(os.fspath(path))
        return [f"{stem}_person{pid}.trc" for pid in sorted(self.person_ids)]

    def write_people(
        self, path: PathLike, *, rate: float | int, units: str = "m", z_up: bool = False
    ) -> list[str]:
        """:func:`save_people_trc` of the whole recording. Returns the paths written."""
        C = np.asarray(self.people.points).shape[2]
        names = marker_names(self.people.class_names, C)
        written = []
        for pid, target in zip(sorted(self.person_ids), self.people_files(path)):

            def blocks(pid=pid):
                for _, file in self.parts:
                    with np.load(file) as part:
                        yield _person_rows(part["points"], part["person_id"], pid)

            _save_trc_rows(target, blocks, self.frames, names, rate, units, z_up)
            written.append(target)
        return written

    def write_tracks(
        self, path: PathLike, *, rate: float | int, units: str = "m", z_up: bool = False
    ) -> int:
        """:func:`save_trc` of :func:`track_markers` of the whole recording (every part's
        tracks, the last part's count). Returns the number of markers."""
        T = len(self.track_class)

        def blocks():
            for _, file in self.parts:
                X = np.load(file)
                if X.shape[1] < T:  # tracks born in later parts: not seen here
                    X = np.concatenate(
                        [X, np.full((X.shape[0], T - X.shape[1], 3), np.nan, X.dtype)], axis=1
                    )
                yield X

        names = _track_names(self.tracked, self.track_class)
        _save_trc_rows(path, blocks, self.frames, names, rate, units, z_up)
        return T
