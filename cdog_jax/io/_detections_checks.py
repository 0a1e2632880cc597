"""Checks on decoded detections, before any work: capacity (padding, or packing a view),
duplicates, the image bounds, whether any group is possible, the float range; and the
:class:`~cdog_jax.io.Detections` they end in (``_finish``)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._runtime import memory
from ._detections_type import Detections
from ._errors import _Where
from ._scores import clip_scores


def _finish(
    xy,
    mask,
    conf,
    frames,
    where,
    notes,
    capacity,
    image_size,
    classes=None,
    names=None,
    frame_ids=None,
    instances=None,
    part: bool = False,
) -> Detections:
    """The checks every reader's detections pass, and the :class:`Detections` (``part``: a
    part of a longer recording, whose caller checks that some frame of the whole has
    detections in 2 views)."""
    xy = np.where(mask[..., None], xy, 0.0)
    if conf is not None:
        conf, note = clip_scores(conf, mask, where.error)
        notes += [note] if note else []
    if classes is not None:
        classes = np.where(mask, classes, -1)
    if instances is not None:
        instances = np.where(mask, instances, -1)
    counts = mask.sum(axis=-1).astype(np.int64)
    if capacity is not None:
        _check_padded_size(mask.shape, capacity, counts, where, conf, classes, instances)
        xy, mask, conf, classes, instances = _fit_capacity(
            xy, mask, conf, counts, capacity, where, notes, classes, instances
        )
    _check_duplicates(xy, mask, where, classes)
    if image_size is not None:
        _check_in_image(xy, mask, image_size, where)
    _check_groups_possible(counts, frames, where, notes, part)
    for f, m in np.argwhere(counts == 0):
        notes.append(f"{where.loc(int(f), int(m))}: empty view")
    return Detections(
        xy, mask, conf, bool(frames), counts, notes, classes, names, frame_ids, instances
    )


def _size(num_bytes: int) -> str:
    return f"{num_bytes / 1e9:,.1f} GB" if num_bytes >= 1e9 else f"{num_bytes / 1e6:,.1f} MB"


def _check_padded_size(shape, capacity, counts, where, *optional) -> None:
    """Refuse a ``capacity`` whose padded arrays (``(F, M, capacity)`` coordinates, mask and
    the ``optional`` per-slot arrays given) would take more than half this machine's
    memory, before they are made: the kernel would kill the process instead."""
    F, M, P = shape
    total = memory.physical_memory()
    if capacity <= P or not total:
        return
    per_slot = 2 * 8 + 1 + 8 * sum(a is not None for a in optional)
    need = F * M * capacity * per_slot
    if need > total / 2:
        raise where.error(
            f"capacity {capacity}: padding {F} frame(s) × {M} view(s) to {capacity} slots takes "
            f"{_size(need)}, more than half of this machine's {_size(total)}; the "
            f"fullest view holds {int(counts.max()) if counts.size else 0} detections"
        )


def _check_groups_possible(
    counts: np.ndarray, frames: bool, where: _Where, notes: list[str], part: bool = False
) -> None:
    """A group needs detections in 2 views. One scene without that is refused (nothing to
    associate: most likely the wrong file); so is a list of frames none of which has it.
    Frames without it among others (a subject out of view) are kept, with a note: they
    get zero groups."""
    views_seen = (counts > 0).sum(axis=1)  # (F,)
    hopeless = np.flatnonzero(views_seen < 2)
    if not frames and hopeless.size:
        seen = np.flatnonzero(counts[0] > 0)
        which = f" (view {int(seen[0])})" if len(seen) else ""
        raise where.error(
            f"{len(seen)} view(s) with detections{which}; association needs at least 2"
        )
    if hopeless.size == counts.shape[0] and not part:
        raise where.error(
            f"no frame has detections in 2 views (of {counts.shape[0]} frames); association needs at least 2"
        )
    if hopeless.size and not part:  # a part's: said once for the whole recording
        notes.append(few_views_note(hopeless, counts.shape[0]))


def few_views_note(hopeless: np.ndarray, F: int) -> str:
    """The note of the frames ``hopeless`` (of ``F``) without detections in 2 views."""
    shown = ", ".join(str(int(f)) for f in hopeless[:10]) + (", …" if hopeless.size > 10 else "")
    return (
        f"frame{'s' if hopeless.size > 1 else ''} {shown} ({hopeless.size} of {F}): fewer than 2 views "
        "with detections; they get zero groups"
    )


def check_float_range(
    det: Detections, dtype: Any, source: str | None = None, first_frame: int = 0
) -> None:
    """Refuse detections whose coordinates the float type ``dtype`` (e.g. float32) cannot
    hold: they would turn infinite when converted. ``source`` (the file) starts the message,
    which names the frame (``det``'s frame 0 is ``first_frame`` of the file), view and
    detection."""
    largest = float(np.finfo(dtype).max)
    bad = det.mask & (np.abs(det.xy) > largest).any(axis=-1)
    if bad.any():
        f, m, i = (int(v) for v in np.argwhere(bad)[0])
        x, y = det.xy[f, m, i]
        raise _Where(source, det.frames, first_frame).error(
            f"({x:g}, {y:g}) is out of {np.dtype(dtype).name} range (largest {largest:.4g}); these cannot be pixels",
            f,
            m,
            i,
        )


def _fit_capacity(xy, mask, conf, counts, capacity, where, notes, classes=None, instances=None):
    """Pad to ``capacity`` slots, or shrink to it when every view fits, packing views whose
    detections sit beyond it (slots change; said in ``notes``)."""
    over = counts > capacity
    if over.any():
        f, m = (int(v) for v in np.argwhere(over)[0])
        raise where.error(
            f"{counts[f, m]} detections exceed the capacity of {capacity} slots per view "
            "(pass a larger capacity, or None to fit the fullest view)",
            f,
            m,
        )
    P = mask.shape[-1]
    if P <= capacity:
        pad = ((0, 0), (0, 0), (0, capacity - P))
        conf = None if conf is None else np.pad(conf, pad)
        classes = None if classes is None else np.pad(classes, pad, constant_values=-1)
        instances = None if instances is None else np.pad(instances, pad, constant_values=-1)
        return np.pad(xy, (*pad, (0, 0))), np.pad(mask, pad), conf, classes, instances
    for f, m in np.argwhere(mask[..., capacity:].any(axis=-1)):
        order = np.argsort(~mask[f, m], kind="stable")  # detections first, in slot order
        xy[f, m], mask[f, m] = xy[f, m, order], mask[f, m, order]
        if conf is not None:
            conf[f, m] = conf[f, m, order]
        if classes is not None:
            classes[f, m] = classes[f, m, order]
        if instances is not None:
            instances[f, m] = instances[f, m, order]
        notes.append(
            f"{where.loc(int(f), int(m))}: detections moved to slots 0…{counts[f, m] - 1} to fit capacity {capacity}"
        )
    conf = None if conf is None else conf[..., :capacity]
    classes = None if classes is None else classes[..., :capacity]
    instances = None if instances is None else instances[..., :capacity]
    return xy[..., :capacity, :], mask[..., :capacity], conf, classes, instances


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
    same = (
        (f[1:] == f[:-1])
        & (m[1:] == m[:-1])
        & (c[1:] == c[:-1])
        & (x[1:] == x[:-1])
        & (y[1:] == y[:-1])
    )
    if same.any():
        # Report the pair earliest in (frame, view, first index) order.
        k = min(np.flatnonzero(same), key=lambda k: (f[k], m[k], i[k]))
        raise where.error(
            f"detections {i[k]} and {i[k + 1]} are duplicates (both at ({x[k]}, {y[k]}))",
            int(f[k]),
            int(m[k]),
        )


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
            f,
            m,
            i,
        )


def _image_size(image_size: Any) -> tuple[float, float]:
    ok = (
        isinstance(image_size, (list, tuple))
        and len(image_size) == 2
        and all(
            not isinstance(v, bool)
            and isinstance(v, (int, float, np.integer, np.floating))
            and v > 0
            for v in image_size
        )
    )
    if not ok:
        raise ValueError(
            f"image_size must be (width, height), two positive numbers; got {image_size!r}"
        )
    return float(image_size[0]), float(image_size[1])
