"""Association results on disk (docs/ALGORITHM.md §11, docs/CONVENTIONS.md §3): JSON records, NPZ arrays, a CSV of points.

The JSON lists every valid detection exactly once: as a member of a group or in
``"unassigned"``. Rows are ``[view, slot, x, y]`` (``[view, slot, x, y, confidence]`` when
a confidence is given), pixels; points are in scene units. Per group, the same two
numbers as :class:`cdog_jax.Association`, with the same names, in the JSON, the NPZ and the
CSV (and the CLI's summary reports ``err_px``):

- ``err_px``: *the* reprojection error of a group, the mean over its member views of the
  pixel distance ``‖π_m(X) − x_m‖`` (px),
- ``bpe_px2``: the paper's back-projection error ``mean_m ‖π_m(X) − x_m‖²`` (px²), the
  number the BPE filter ranks (NPZ: ``bpe``).

Numbers are written with ``repr`` (exact float64 round trip); a non-finite number is
written as ``null``.

Classes: every writer also takes what :func:`cdog_jax.associate_classes` returns (a
``ClassAssociation``). Each group then carries its class: ``"class"`` (id) and
``"class_name"`` (when names are known) in the JSON, with the names by id as top-level
``"class_names"`` and the classes of the unassigned detections as ``"unassigned_classes"``
(when the detections' ``classes`` are given); columns ``class, class_name`` at the end of
the CSV; arrays ``group_class``, ``class_names`` (and ``classes``) in the NPZ.

Tracks: every writer also takes what :func:`cdog_jax.track_groups` and
:func:`cdog_jax.associate_sequence` return (a ``TrackedAssociation``). Each group then
carries its track id: ``"track"`` (and ``"recovered"``, true for a group the temporal prior
recovered) in the JSON, a last column ``track`` in the CSV, arrays ``track_id`` and
``recovered`` in the NPZ.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import zipfile
from types import SimpleNamespace
from typing import Any

import numpy as np

from .._expect import ARRAY, PATH, Kind, expect_args
from ._atomic import atomic_write
from ._read_files import read_json

PathLike = str | os.PathLike  # a file name

# Every field of cdog_jax.Association, as written to NPZ.
ASSOCIATION_FIELDS = (
    "labels",
    "groups",
    "valid",
    "points3d",
    "bpe",
    "err_px",
    "n_views",
    "num_groups",
    "sigma_px",
    "tau_px",
    "status",
)
# Any object with an Association's fields will do (e.g. one frame of a batch).
_ASSOCIATION = Kind(
    "an Association (or an object with its fields)",
    lambda v: all(hasattr(v, f) for f in ("groups", "valid", "points3d")),
)
CSV_COLUMNS = ("frame", "group", "x", "y", "z", "err_px", "bpe_px2", "n_views")
CSV_NOTE = (
    "# err_px: mean reprojection distance over the group's member views (pixels); "
    "bpe_px2: mean squared distance (BPE, pixels^2); x, y, z in scene units"
)


def association_records(
    assoc: Any,
    xy: Any,
    mask: Any,
    *,
    confidence: Any = None,
    rig: Any = None,
    group_class: Any = None,
    class_names: Any = None,
    classes: Any = None,
    track_id: Any = None,
    recovered: Any = None,
    person: Any = None,
    mixed: Any = None,
    people: Any = None,
) -> dict:
    """One scene's association as JSON-ready records.

    Args:
        assoc: the :class:`cdog_jax.Association` of one scene (NumPy or JAX arrays): ``labels
            (M, P)``, ``groups (G, M)``, ``valid (G,)``, ``points3d (G, 3)``, ``bpe``,
            ``err_px``, ``n_views (G,)``, ``sigma_px``, ``tau_px``.
        xy: ``(M, P, 2)`` the detections it was computed from (pixels).
        mask: ``(M, P)`` bool, valid detections.
        confidence: optional ``(M, P)``; appended to every row.
        rig: optional cameras (``K, R (M, 3, 3)``, ``t (M, 3)``); then each group also gets
            ``member_err_px``, the reprojection distance (px) of each member, in member order.
        group_class: optional ``(G,)`` class id of every group: each group gets ``"class"``
            (and ``"class_name"`` from ``class_names``, the names by id).
        classes: optional ``(M, P)`` class ids of the detections: ``"unassigned_classes"``
            lists those of the unassigned rows, in their order.
        track_id, recovered: optional ``(G,)`` track id and "recovered by the temporal
            prior" flag of every group: each group gets ``"track"`` and ``"recovered"``.
        person, mixed: optional ``(G,)`` person id of every group (-1: none; written
            ``null``) and "holds detections of two people seen in one view" flag: each group
            gets ``"person"`` and ``"mixed"``.
        people: optional list of the scene's people, ``{"person", "merged", "split"}``
            (:func:`cdog_jax.identify_people`), written as ``"people"``.

    Returns:
        ``{"groups": [{"id", "members": [[view, slot, x, y], …], "point3d": [X, Y, Z],
        "err_px", "bpe_px2", "n_views"(, "member_err_px")}, …], "unassigned":
        [[view, slot, x, y], …], "num_views", "capacity", "sigma_px", "tau_px"}``. Only
        ``valid`` groups are listed; ``id`` is the group's row in ``assoc.groups``.
    """
    expect_args(
        "association_records", assoc=(assoc, _ASSOCIATION), xy=(xy, ARRAY), mask=(mask, ARRAY)
    )
    a = _host(assoc)
    xy, mask = np.asarray(xy, np.float64), np.asarray(mask, bool)
    conf = None if confidence is None else np.asarray(confidence, np.float64)
    if a["labels"].ndim != 2:
        raise ValueError(
            f"expected the Association of one scene, labels (M, P); got labels {a['labels'].shape}"
        )
    M, P = a["labels"].shape
    if xy.shape != (M, P, 2) or mask.shape != (M, P):
        raise ValueError(
            f"xy and mask must have shapes {(M, P, 2)} and {(M, P)} like assoc.labels; got {xy.shape}, {mask.shape}"
        )
    if conf is not None and conf.shape != (M, P):
        raise ValueError(f"confidence must have shape {(M, P)}; got {conf.shape}")

    def row(m: int, i: int) -> list:
        r = [m, i, _num(xy[m, i, 0]), _num(xy[m, i, 1])]
        return r + [_num(conf[m, i])] if conf is not None else r

    cams = None if rig is None else _host_rig(rig, M)
    groups, used = [], np.zeros((M, P), bool)
    for g in np.flatnonzero(a["valid"]):
        views = np.flatnonzero(a["groups"][g] >= 0)
        slots = a["groups"][g, views]
        if (slots >= P).any() or not mask[views, slots].all():
            raise ValueError(
                f"group {g} has a member in a slot where mask is False; are assoc and xy from the same scene?"
            )
        used[views, slots] = True
        X = a["points3d"][g]
        record = {
            "id": int(g),
            "members": [row(int(m), int(i)) for m, i in zip(views, slots)],
            "point3d": [_num(v) for v in X],
            "err_px": _num(a["err_px"][g]),
            "bpe_px2": _num(a["bpe"][g]),
            "n_views": int(a["n_views"][g]),
        }
        if cams is not None:
            record["member_err_px"] = [
                _num(e) for e in _member_errors(cams, X, views, xy[views, slots])
            ]
        if group_class is not None:
            record.update(_class_fields(int(np.asarray(group_class)[g]), class_names))
        if track_id is not None:
            record["track"] = int(np.asarray(track_id)[g])
            record["recovered"] = bool(recovered is not None and np.asarray(recovered)[g])
        if person is not None:
            pid = int(np.asarray(person)[g])
            record["person"] = pid if pid >= 0 else None
            record["mixed"] = bool(mixed is not None and np.asarray(mixed)[g])
        groups.append(record)
    left = np.argwhere(mask & ~used)
    unassigned = [row(int(m), int(i)) for m, i in left]
    out = {
        "groups": groups,
        "unassigned": unassigned,
        "num_views": M,
        "capacity": P,
        "sigma_px": _num(a["sigma_px"]),
        "tau_px": _num(a["tau_px"]),
    }
    if classes is not None:
        cls = np.asarray(classes)
        out["unassigned_classes"] = [int(cls[m, i]) for m, i in left]
    if people is not None:
        out["people"] = people
    return out


def _class_fields(c: int, names: Any) -> dict:
    fields: dict = {"class": c}
    if names is not None:
        fields["class_name"] = names[c] if 0 <= c < len(names) else None
    return fields


def _unpack(result: Any) -> tuple[Any, np.ndarray | None, tuple | None]:
    """``(association, group_class, class_names)`` of an Association, a ClassAssociation or
    a TrackedAssociation (whose group_class may be None)."""
    if hasattr(result, "group_class") and hasattr(result, "association"):
        gc = None if result.group_class is None else np.asarray(result.group_class)
        return result.association, gc, result.class_names
    return result, None, None


def _tracks(result: Any) -> tuple[np.ndarray | None, np.ndarray | None]:
    """``(track_id, recovered)`` of a TrackedAssociation, else ``(None, None)``."""
    if getattr(result, "track_id", None) is None:
        return None, None
    return np.asarray(result.track_id), np.asarray(result.recovered)


def _people(people: Any, F: int | None) -> tuple[Any, Any, Any]:
    """``(group_person, mixed, people lists)`` of a :class:`cdog_jax.People` (``(F, G)``,
    ``(F, G)``, one list per frame), or ``(None, None, None)``; ``F`` the result's frames
    (``None``: one scene)."""
    if people is None:
        return None, None, None
    gp, ids = np.asarray(people.group_person), np.asarray(people.person_id)
    if gp.ndim != 2 or (F is not None and gp.shape[0] != F) or (F is None and gp.shape[0] != 1):
        raise ValueError(
            f"people must be the People of this result ({F or 1} frame(s)); got group_person {gp.shape}"
        )
    merged, split = np.asarray(people.merged), np.asarray(people.split)
    lists = [
        [
            {"person": int(ids[f, n]), "merged": bool(merged[f, n]), "split": bool(split[f, n])}
            for n in np.flatnonzero(ids[f] >= 0)
        ]
        for f in range(ids.shape[0])
    ]
    return gp, np.asarray(people.mixed), lists


def save_association_json(
    path: PathLike,
    assoc: Any,
    xy: Any,
    mask: Any,
    *,
    confidence: Any = None,
    rig: Any = None,
    classes: Any = None,
    people: Any = None,
) -> None:
    """Write :func:`association_records` as JSON: one scene (``labels (M, P)``, ``xy (M, P, 2)``),
    or a batch (``labels (B, M, P)``, ``xy (B, M, P, 2)``, ``mask (B, M, P)``, from
    :func:`cdog_jax.associate_batch`) as ``{"frames": [one object per scene, …]}``.
    ``rig`` is shared by all scenes. ``assoc`` may be a ``ClassAssociation`` (frames;
    ``classes (F, M, P)``, the detections' class ids, optional), or a ``TrackedAssociation``:
    see the module docstring. ``people``: the :class:`cdog_jax.People` of ``assoc``
    (:func:`cdog_jax.identify_people`): every group gets ``"person"`` and ``"mixed"``, every
    frame ``"people"``."""
    expect_args("save_association_json", path=(path, PATH))
    records, names = _json_records(
        assoc, xy, mask, confidence=confidence, rig=rig, classes=classes, people=people
    )
    data = {"frames": records} if isinstance(records, list) else records
    if names is not None:
        data["class_names"] = list(names)
    with atomic_write(path, "w") as f:
        json.dump(data, f, allow_nan=False)
        f.write("\n")


def _json_records(
    assoc: Any, xy: Any, mask: Any, *, confidence: Any, rig: Any, classes: Any, people: Any
) -> tuple[list[dict] | dict, Any]:
    """What :func:`save_association_json` writes: ``(records, class names or None)``, the
    records one object per frame (a list) for a batch, one object for one scene."""
    tracks, recovered = _tracks(assoc)
    assoc, group_class, names = _unpack(assoc)
    expect_args(
        "save_association_json",
        assoc=(assoc, _ASSOCIATION),
        xy=(xy, ARRAY),
        mask=(mask, ARRAY),
    )
    labels = np.asarray(assoc.labels)
    if labels.ndim == 3:
        B = labels.shape[0]
        xy, mask = np.asarray(xy), np.asarray(mask)
        if xy.shape[:1] != (B,) or mask.shape[:1] != (B,):
            raise ValueError(
                f"a batch of {B} results needs xy (B, M, P, 2) and mask (B, M, P); got {xy.shape}, {mask.shape}"
            )
        conf = [None] * B if confidence is None else np.asarray(confidence)
        gc = [None] * B if group_class is None else group_class
        cls = [None] * B if classes is None else np.asarray(classes)
        tid = [None] * B if tracks is None else tracks
        rec = [None] * B if recovered is None else recovered
        gp, mixed, plist = _people(people, B)
        gp, mixed, plist = ([None] * B,) * 3 if people is None else (gp, mixed, plist)
        return [
            association_records(
                _scene(assoc, b),
                xy[b],
                mask[b],
                confidence=conf[b],
                rig=rig,
                group_class=gc[b],
                class_names=names,
                classes=cls[b],
                track_id=tid[b],
                recovered=rec[b],
                person=gp[b],
                mixed=mixed[b],
                people=plist[b],
            )
            for b in range(B)
        ], names
    return association_records(
        assoc,
        xy,
        mask,
        confidence=confidence,
        rig=rig,
        group_class=group_class,
        class_names=names,
        classes=classes,
        track_id=tracks,
        recovered=recovered,
        **_one_scene_people(people),
    ), names


def _one_scene_people(people: Any) -> dict:
    gp, mixed, plist = _people(people, None)
    return {} if people is None else {"person": gp[0], "mixed": mixed[0], "people": plist[0]}


def load_association_json(path: PathLike) -> dict:
    """Read a file written by :func:`save_association_json` and check its structure.

    Returns the parsed object: ``{"groups": […], "unassigned": […], …}`` for one scene or
    ``{"frames": [such objects]}``. Raises ``ValueError`` naming the file, frame and group
    for a missing key or a malformed member row.
    """
    expect_args("load_association_json", path=(path, PATH))
    path = os.fspath(path)
    data = read_json(path)
    if isinstance(data, dict) and "frames" in data:
        if not isinstance(data["frames"], list):
            raise ValueError(f'{path}: "frames" must be a list of result objects')
        for b, scene in enumerate(data["frames"]):
            _check_records(scene, f"{path}: frame {b}")
    else:
        _check_records(data, path)
    return data


def save_association_npz(
    path: PathLike,
    assoc: Any,
    *,
    xy: Any = None,
    mask: Any = None,
    confidence: Any = None,
    classes: Any = None,
    people: Any = None,
) -> None:
    """Write every :class:`cdog_jax.Association` field as an array (``labels``, ``groups``,
    ``valid``, ``points3d``, ``bpe`` (px²), ``err_px``, ``n_views``, ``num_groups``,
    ``sigma_px``, ``tau_px``; with a leading ``B`` for a batch), plus ``xy``, ``mask``,
    ``confidence`` and ``classes`` when given; for a ``ClassAssociation`` also
    ``group_class (F, G)`` and ``class_names`` (strings, when known); for a
    ``TrackedAssociation`` also ``track_id (F, G)`` and ``recovered (F, G)``; with ``people``
    (:func:`cdog_jax.identify_people`) also ``person_id (F, G)`` of every group (-1: none),
    ``mixed (F, G)``, and the skeletons ``people_points (F, N, C, 3)`` (NaN: not seen),
    ``people_id (F, N)`` (-1: padding), ``people_merged``, ``people_split (F, N)``. Read it
    with ``np.load``."""
    expect_args("save_association_npz", path=(path, PATH))
    arrays = association_arrays(
        assoc, xy=xy, mask=mask, confidence=confidence, classes=classes, people=people
    )
    with atomic_write(path, "wb") as f:  # a file object: np.savez would append ".npz" to a str path
        np.savez(f, **arrays)


def association_arrays(
    assoc: Any, *, xy=None, mask=None, confidence=None, classes=None, people=None
) -> dict[str, np.ndarray]:
    """The arrays :func:`save_association_npz` writes, by name."""
    tracks, recovered = _tracks(assoc)
    assoc, group_class, names = _unpack(assoc)
    expect_args("save_association_npz", assoc=(assoc, _ASSOCIATION))
    arrays = _host(assoc)
    if group_class is not None:
        arrays["group_class"] = group_class
    if names is not None:
        arrays["class_names"] = np.asarray(names, dtype=str)
    if tracks is not None:
        arrays["track_id"], arrays["recovered"] = tracks, recovered
    if people is not None:
        labels = arrays["labels"]
        gp, mixed, _ = _people(people, labels.shape[0] if labels.ndim == 3 else None)
        arrays["person_id"], arrays["mixed"] = (
            (gp, mixed) if labels.ndim == 3 else (gp[0], mixed[0])
        )
        arrays["people_points"], arrays["people_id"] = (
            np.asarray(people.points),
            np.asarray(people.person_id),
        )
        arrays["people_merged"], arrays["people_split"] = (
            np.asarray(people.merged),
            np.asarray(people.split),
        )
    for name, v in (("xy", xy), ("mask", mask), ("confidence", confidence), ("classes", classes)):
        if v is not None:
            arrays[name] = np.asarray(v)
    return arrays


# What pads the arrays of a part whose rows (groups, people) are fewer than another part's.
_PADDING = {
    "labels": -1,
    "groups": -1,
    "valid": False,
    "points3d": 0,
    "bpe": 0,
    "err_px": 0,
    "n_views": 0,
    "group_class": -1,
    "track_id": -1,
    "recovered": False,
    "person_id": -1,
    "mixed": False,
    "people_points": np.nan,
    "people_id": -1,
    "people_merged": False,
    "people_split": False,
    "xy": 0,
    "mask": False,
    "confidence": 0,
    "classes": -1,
}


class NpzParts:
    """The ``.npz`` of :func:`save_association_npz` for a recording given a part at a time
    (:meth:`add`: each part's batch result and detections, frames in order), kept on disk in
    ``folder`` until :meth:`write` writes the file: every array the parts' one after the
    other along frames, other axes padded to the widest part's (empty groups and people);
    ``class_names`` the first part's. Memory: one part's arrays at a time."""

    def __init__(self, folder: str):
        self.folder = folder
        self.parts: list[dict[str, tuple[str, tuple, np.dtype]]] = []

    def add(self, assoc: Any, xy: Any, mask: Any, **details: Any) -> None:
        """One part: ``assoc``, ``xy``, ``mask`` and the keywords of
        :func:`save_association_npz` (``confidence``, ``classes``, ``people``)."""
        arrays = association_arrays(assoc, xy=xy, mask=mask, **details)
        stored = {}
        for name, a in arrays.items():
            file = os.path.join(self.folder, f"{len(self.parts)}_{name}.npy")
            np.save(file, a)
            stored[name] = (file, a.shape, a.dtype)
        self.parts.append(stored)

    def write(self, path: PathLike) -> None:
        names = list(self.parts[0])
        if any(list(p) != names for p in self.parts):
            raise ValueError("NpzParts: every part must hold the same arrays")
        with atomic_write(path, "wb") as f, zipfile.ZipFile(f, "w", zipfile.ZIP_STORED) as z:
            for name in names:
                if name == "class_names":
                    with z.open(f"{name}.npy", "w", force_zip64=True) as out:
                        np.lib.format.write_array(out, np.load(self.parts[0][name][0]))
                    continue
                shapes = [p[name][1] for p in self.parts]
                dtype = self.parts[0][name][2]
                shape = (
                    sum(s[0] for s in shapes),
                    *(max(s[k] for s in shapes) for k in range(1, len(shapes[0]))),
                )
                header = {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False}
                with z.open(f"{name}.npy", "w", force_zip64=True) as out:
                    np.lib.format.write_array_header_2_0(out, {**header, "shape": shape})
                    for part in self.parts:
                        a = np.load(part[name][0], mmap_mode="r")
                        if a.shape[1:] != shape[1:]:
                            wide = np.full((a.shape[0], *shape[1:]), _PADDING[name], dtype)
                            wide[tuple(slice(0, n) for n in a.shape)] = a
                            a = wide
                        out.write(np.ascontiguousarray(a).tobytes())


def save_association_csv(path: PathLike, assoc: Any, *, people: Any = None) -> None:
    """One row per 3D point (valid group): ``frame, group, x, y, z, err_px, bpe_px2, n_views``.

    Like anipose's point tables. ``err_px`` is the group's reprojection error, the mean
    pixel distance over its member views, and ``bpe_px2`` its BPE (px²), exactly the
    result's ``err_px`` and ``bpe``; ``x, y, z`` are in scene units. ``frame`` is the scene index of a batch (``labels (B, M, P)``), 0 for one
    scene. The file starts with a ``#`` comment line saying so (pandas: ``comment="#"``).
    A ``ClassAssociation`` adds the columns ``class, class_name`` (the name empty when
    names are not known); a ``TrackedAssociation`` a column ``track``; ``people``
    (:func:`cdog_jax.identify_people`) a last column ``person`` (empty: no person).
    """
    expect_args("save_association_csv", path=(path, PATH))
    header, rows, _ = _csv_table(assoc, people)
    with atomic_write(path, "w", newline="") as f:
        f.write(CSV_NOTE + "\n")
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows(rows(0))


def _csv_table(assoc: Any, people: Any) -> tuple[list[str], Any, int]:
    """What :func:`save_association_csv` writes: ``(header, rows, frames)``; ``rows(first)``
    yields the rows, frames numbered from ``first``."""
    tracks, _ = _tracks(assoc)
    assoc, group_class, names = _unpack(assoc)
    expect_args("save_association_csv", assoc=(assoc, _ASSOCIATION))
    a = _host(assoc)
    batch = a["labels"].ndim == 3
    frames = a["labels"].shape[0] if batch else 1
    person, _, _ = _people(people, frames if batch else None)
    if person is not None and not batch:
        person = person[0]
    header = (
        list(CSV_COLUMNS)
        + (["class", "class_name"] if group_class is not None else [])
        + (["track"] if tracks is not None else [])
        + (["person"] if person is not None else [])
    )

    def rows(first: int):
        for b in range(frames):
            valid = a["valid"][b] if batch else a["valid"]
            for g in np.flatnonzero(valid):
                at = (b, g) if batch else (g,)
                X = a["points3d"][at]
                yield [
                    first + b,
                    int(g),
                    *(repr(float(v)) for v in X),
                    repr(float(a["err_px"][at])),
                    repr(float(a["bpe"][at])),
                    int(a["n_views"][at]),
                    *_class_columns(group_class, at, names),
                    *([] if tracks is None else [int(tracks[at])]),
                    *([] if person is None else [int(person[at]) if person[at] >= 0 else ""]),
                ]

    return header, rows, frames


class _TextParts:
    """A text file of a recording given a part at a time: each part's text waits in
    ``folder`` until :meth:`_join` writes the file, the parts' texts between ``head`` and
    ``tail`` (``separator`` between two non-empty ones). Memory: one part at a time."""

    def __init__(self, folder: str, suffix: str):
        self.folder, self.suffix = folder, suffix
        self.files: list[str] = []

    def _keep(self, text_of_part) -> None:
        file = os.path.join(self.folder, f"{len(self.files)}{self.suffix}")
        with open(file, "w", encoding="utf-8", newline="") as f:
            text_of_part(f)
        self.files.append(file)

    def _join(self, path: PathLike, head: str, tail: str, separator: str = "") -> None:
        with atomic_write(path, "w", newline="") as out:
            out.write(head)
            written = False
            for file in self.files:
                with open(file, encoding="utf-8", newline="") as f:
                    text = f.read()
                if text:
                    out.write(separator if written else "")
                    out.write(text)
                    written = True
            out.write(tail)


class JsonParts(_TextParts):
    """The JSON of :func:`save_association_json` for a recording given a part at a time
    (:meth:`add`: each part's batch result and detections, frames in order): the same bytes
    as the whole written at once; ``class_names`` the first part's."""

    def __init__(self, folder: str):
        super().__init__(folder, ".json")
        self.names = None

    def add(self, assoc: Any, xy: Any, mask: Any, **details: Any) -> None:
        """One part: ``assoc``, ``xy``, ``mask`` and the keywords of
        :func:`save_association_json` (``confidence``, ``rig``, ``classes``, ``people``)."""
        records, names = _json_records(
            assoc,
            xy,
            mask,
            **{"confidence": None, "rig": None, "classes": None, "people": None, **details},
        )
        if not isinstance(records, list):
            raise ValueError("JsonParts.add: a part is a batch of frames (labels (F, M, P))")
        if not self.files:
            self.names = names
        self._keep(lambda f: f.write(", ".join(json.dumps(r, allow_nan=False) for r in records)))

    def write(self, path: PathLike) -> None:
        names = "" if self.names is None else ', "class_names": ' + json.dumps(list(self.names))
        self._join(path, '{"frames": [', "]" + names + "}\n", ", ")


class CsvParts(_TextParts):
    """The CSV of :func:`save_association_csv` for a recording given a part at a time
    (:meth:`add`: each part's batch result, frames in order, numbered on from the part
    before): the same bytes as the whole written at once."""

    def __init__(self, folder: str):
        super().__init__(folder, ".csv")
        self.header: list[str] | None = None
        self.frames = 0

    def add(self, assoc: Any, xy: Any = None, mask: Any = None, *, people: Any = None, **_) -> None:
        """One part: ``assoc`` and its ``people`` (the CSV holds no detections: ``xy``,
        ``mask`` and the other keywords of :meth:`JsonParts.add` are taken and not used)."""
        header, rows, frames = _csv_table(assoc, people)
        if self.header is not None and header != self.header:
            raise ValueError(
                f"CsvParts.add: every part must have the columns {self.header}; got {header}"
            )
        self.header = header
        self._keep(lambda f: csv.writer(f).writerows(rows(self.frames)))
        self.frames += frames

    def write(self, path: PathLike) -> None:
        head = io.StringIO()
        head.write(CSV_NOTE + "\n")
        csv.writer(head).writerow(self.header or list(CSV_COLUMNS))
        self._join(path, head.getvalue(), "")


# Helpers -----------------------------------------------------------------------------------


def _class_columns(group_class: np.ndarray | None, at: tuple, names: Any) -> list:
    if group_class is None:
        return []
    c = int(group_class[at])
    return [c, names[c] if names is not None and 0 <= c < len(names) else ""]


def _host(assoc: Any) -> dict[str, np.ndarray]:
    missing = [k for k in ASSOCIATION_FIELDS if not hasattr(assoc, k)]
    if missing:
        raise ValueError(
            f"expected a cdog_jax.Association; {type(assoc).__name__} has no {', '.join(missing)}"
        )
    return {k: np.asarray(getattr(assoc, k)) for k in ASSOCIATION_FIELDS}


def _scene(assoc: Any, b: int) -> Any:
    """Scene ``b`` of a batched result, as a plain object with the same fields."""
    return SimpleNamespace(**{k: np.asarray(getattr(assoc, k))[b] for k in ASSOCIATION_FIELDS})


def _num(v: Any) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def _host_rig(rig: Any, M: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    K, R, t = (np.asarray(x, np.float64) for x in (rig.K, rig.R, rig.t))
    if K.shape != (M, 3, 3) or R.shape != (M, 3, 3) or t.shape != (M, 3):
        raise ValueError(
            f"rig must have K, R (M, 3, 3) and t (M, 3) with M={M} like the result; got K {K.shape}"
        )
    return K, R, t


def _member_errors(cams, X: np.ndarray, views: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Pixel distance between each member ``xy (k, 2)`` and the projection of ``X`` in its view
    (dividing by the third homogeneous coordinate, whatever its sign: docs/CONVENTIONS.md §1)."""
    K, R, t = (c[views] for c in cams)
    h = np.einsum("kij,kj->ki", K, np.einsum("kij,j->ki", R, X) + t)  # (k, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.linalg.norm(h[:, :2] / h[:, 2:] - xy, axis=-1)


def _check_records(obj: Any, where: str) -> None:
    if not isinstance(obj, dict) or "groups" not in obj or "unassigned" not in obj:
        raise ValueError(f'{where}: expected an object with "groups" and "unassigned"')
    for g, group in enumerate(obj["groups"]):
        for key in ("members", "point3d", "n_views"):
            if not isinstance(group, dict) or key not in group:
                raise ValueError(f'{where}, group {g}: missing key "{key}"')
        if not isinstance(group["point3d"], list) or len(group["point3d"]) != 3:
            raise ValueError(f'{where}, group {g}: "point3d" must be [X, Y, Z]')
        for k, r in enumerate(group["members"]):
            if not isinstance(r, list) or len(r) not in (4, 5):
                raise ValueError(
                    f"{where}, group {g}, member {k}: expected [view, slot, x, y(, confidence)]; got {r!r}"
                )
    for k, r in enumerate(obj["unassigned"]):
        if not isinstance(r, list) or len(r) not in (4, 5):
            raise ValueError(
                f"{where}, unassigned {k}: expected [view, slot, x, y(, confidence)]; got {r!r}"
            )
