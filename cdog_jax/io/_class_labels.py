"""Classes of detections (keypoint type, marker colour, object category) as the readers take them.

A class is given per detection as an int id ``>= 0`` or as a name (a string); a file uses one
kind, not both. Names become ids: in the order of an explicit list of names when the file
has one, else in the order they first appear (frame by frame, view by view). Every reader
ends with ``classes (F, M, P)`` int64 (``-1`` where the slot holds no detection) and
``class_names`` (a tuple indexed by id, or ``None`` when only ids were given).

Detections JSON with classes (see :func:`cdog_jax.io.load_detections`):

- per detection: ``{"views": [[[x, y], …], …], "classes": [[c, …], …]}``, ``classes``
  shaped like ``views`` (one list per view, one class per detection);
- per-class lists: ``{"by_class": {"nose": [[[x, y], …], …], "neck": …}}``, each class
  holding one list per view (views in rig order); the detections of a view are the
  classes' lists one after another, in the object's order;
- either inside each ``{"frames": [...]}`` entry; an optional top-level
  ``"class_names": ["nose", "neck", …]`` names the ids (and fixes the ids of names).
"""

from __future__ import annotations

from typing import Any

import numpy as np


def views_and_labels(obj: dict, where: str) -> tuple[Any, list | None]:
    """The ``views`` lists of one scene object and its per-detection labels (``None``
    without classes); ``by_class`` is flattened view by view. ``where`` names the file
    and frame in messages."""
    if "by_class" not in obj:
        return obj["views"], obj.get("classes")
    if "views" in obj or "classes" in obj:
        raise ValueError(
            f'{where}: give either "by_class" or "views" (with optional "classes"), not both'
        )
    by = obj["by_class"]
    if not isinstance(by, dict) or not by:
        raise ValueError(
            f'{where}: "by_class" must be a non-empty object {{class name: [[[x, y], …] per view], …}}'
        )
    views: list[list] | None = None
    labels: list[list] = []
    for name, per_view in by.items():
        if not isinstance(per_view, list):
            raise ValueError(
                f'{where}: class "{name}": expected one list of detections per view; got {type(per_view).__name__}'
            )
        if views is None:
            views, labels = [[] for _ in per_view], [[] for _ in per_view]
        if len(per_view) != len(views):
            raise ValueError(
                f'{where}: class "{name}" has {len(per_view)} views; the first class has {len(views)}'
            )
        for m, view in enumerate(per_view):
            if not isinstance(view, list):
                raise ValueError(
                    f'{where}: class "{name}", view {m}: expected a list of detections; got {type(view).__name__}'
                )
            views[m] += view
            labels[m] += [name] * len(view)
    return views, labels


def class_array(
    labels: list, frames_views: list, shape: tuple[int, int, int], names: Any, error
) -> tuple[np.ndarray, tuple[str, ...] | None]:
    """Per-detection labels of every frame as ``(F, M, L)`` int64 ids (``-1`` beyond each
    view's list) and the names by id.

    Args:
        labels: per frame, ``None`` (no classes) or one list per view of labels.
        frames_views: per frame, the views' detection lists (to check the lengths).
        shape: ``(F, M, L)`` of the rows the detections were read into.
        names: ``None`` or a list of distinct strings naming ids ``0 …``.
        error: ``error(text, f, m, i)`` builds the exception for a location.
    """
    names = check_names(names, error)
    if all(lab is None for lab in labels):
        raise error(
            '"class_names" without classes (give "classes" beside "views", or "by_class")',
            None,
            None,
            None,
        )
    if any(lab is None for lab in labels):
        f = next(f for f, lab in enumerate(labels) if lab is None)
        raise error(
            'no "classes" in this frame while other frames have them (give classes in every frame or none)',
            f,
            None,
            None,
        )
    ids = np.full(shape, -1, np.int64)
    kind = None  # "id" or "name", the same for the whole file
    by_name = {} if names is None else {n: k for k, n in enumerate(names)}
    for f, (per_view, views) in enumerate(zip(labels, frames_views)):
        if not isinstance(per_view, list) or len(per_view) != len(views):
            got = len(per_view) if isinstance(per_view, list) else type(per_view).__name__
            raise error(
                f'"classes" must hold one list per view ({len(views)}); got {got}', f, None, None
            )
        for m, (labs, view) in enumerate(zip(per_view, views)):
            if not isinstance(labs, list) or len(labs) != len(view):
                got = len(labs) if isinstance(labs, list) else type(labs).__name__
                raise error(
                    f'"classes" must hold one class per detection ({len(view)}); got {got}',
                    f,
                    m,
                    None,
                )
            for i, c in enumerate(labs):
                this = (
                    "name"
                    if isinstance(c, str)
                    else "id"
                    if isinstance(c, (int, np.integer)) and not isinstance(c, bool)
                    else None
                )
                if this is None or (this == "id" and c < 0):
                    raise error(
                        f"class {c!r} is neither an int >= 0 nor a name (a string)", f, m, i
                    )
                if kind is None:
                    kind = this
                elif this != kind:
                    raise error(
                        f"class {c!r}: the file mixes class ids and class names; use one kind",
                        f,
                        m,
                        i,
                    )
                if this == "name":
                    if c not in by_name:
                        if names is not None:
                            raise error(f"class {c!r} is not in class_names {list(names)}", f, m, i)
                        by_name[c] = len(by_name)
                    ids[f, m, i] = by_name[c]
                else:
                    if names is not None and c >= len(names):
                        raise error(
                            f"class id {c} has no name: class_names has {len(names)} entries",
                            f,
                            m,
                            i,
                        )
                    ids[f, m, i] = c
    if names is None and kind == "name":
        names = tuple(by_name)
    return ids, names


def check_names(names: Any, error) -> tuple[str, ...] | None:
    """``names`` as a tuple of distinct non-empty strings, or ``None``."""
    if names is None:
        return None
    if not isinstance(names, (list, tuple)) or not all(isinstance(n, str) and n for n in names):
        raise error(
            f"class_names must be a list of non-empty strings; got {names!r}", None, None, None
        )
    seen = set()
    for n in names:
        if n in seen:
            raise error(f"class_names has {n!r} twice", None, None, None)
        seen.add(n)
    return tuple(names)
