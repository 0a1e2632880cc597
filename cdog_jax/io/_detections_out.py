"""Writing detections as the JSON that :func:`cdog_jax.io.load_detections` reads
(docs/CONVENTIONS.md §3), so that a scene made in Python (a synthetic one above all) can be
handed to ``cdog-jax associate``.

Each view's detections are listed in slot order, masked-out slots left out, so the slot of a
detection in the file (its index in its view's list) is its rank among the valid slots of
its view; :func:`detection_order` gives that mapping. Numbers are written with ``repr``
(exact float64 round trip).
"""

from __future__ import annotations

import json
import os
from typing import Any

import numpy as np

from .._expect import ARRAY, PATH, expect_args
from ._atomic import atomic_write

PathLike = str | os.PathLike  # a file name


def _frames(
    xy: Any, mask: Any, confidence: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, bool]:
    """``(xy (F, M, P, 2), mask (F, M, P), confidence (F, M, P) or None, had_frames)``, checked."""
    xy = np.asarray(xy, dtype=np.float64)
    mask = np.asarray(mask)
    if mask.dtype != bool:
        raise ValueError(f"save_detections_json: mask must be bool; got dtype {mask.dtype}")
    had_frames = xy.ndim == 4
    if xy.ndim not in (3, 4) or xy.shape[-1] != 2 or mask.shape != xy.shape[:-1]:
        raise ValueError(
            "save_detections_json: xy must be (M, P, 2) or (F, M, P, 2) and mask (M, P) or (F, M, P); "
            f"got xy {xy.shape} and mask {mask.shape}"
        )
    if not had_frames:
        xy, mask = xy[None], mask[None]
    conf = None
    if confidence is not None:
        conf = np.asarray(confidence, dtype=np.float64)
        conf = conf if had_frames else conf[None]
        if conf.shape != mask.shape:
            raise ValueError(
                f"save_detections_json: confidence must have the shape of mask {mask.shape[int(not had_frames) :]}; "
                f"got {np.shape(confidence)}"
            )
    bad = mask & ~np.isfinite(xy).all(axis=-1)
    if conf is not None:
        bad |= mask & ~((conf >= 0) & (conf <= 1))
    if bad.any():
        f, m, i = (int(v) for v in np.argwhere(bad)[0])
        where = (f"frame {f}, " if had_frames else "") + f"view {m}, slot {i}"
        raise ValueError(
            f"save_detections_json: {where}: a detection must be finite with a confidence in [0, 1]; "
            f"got xy {xy[f, m, i].tolist()}"
            + ("" if conf is None else f", confidence {conf[f, m, i]!r}")
        )
    return xy, mask, conf, had_frames


def save_detections_json(path: PathLike, xy: Any, mask: Any, *, confidence: Any = None) -> None:
    """Write detections as ``{"views": [[[x, y], …], …]}`` (one scene) or
    ``{"frames": [{"views": …}, …]}`` (a leading frame axis).

    Args:
        path: the ``.json`` file (replaced atomically).
        xy: ``(M, P, 2)`` or ``(F, M, P, 2)`` pixels.
        mask: ``(M, P)`` or ``(F, M, P)`` bool; masked-out slots are not written.
        confidence: optional, the shape of ``mask``, in [0, 1]; entries become ``[x, y, c]``.

    Raises:
        ValueError: shapes that do not match, or a valid detection that is not finite (or
            whose confidence is outside [0, 1]), naming the frame, view and slot.
    """
    expect_args("save_detections_json", path=(path, PATH), xy=(xy, ARRAY), mask=(mask, ARRAY))
    xy, mask, conf, had_frames = _frames(xy, mask, confidence)
    frames = []
    for f in range(xy.shape[0]):
        views = []
        for m in range(xy.shape[1]):
            slots = np.flatnonzero(mask[f, m])
            rows = xy[f, m, slots].tolist()
            if conf is not None:
                rows = [[x, y, c] for (x, y), c in zip(rows, conf[f, m, slots].tolist())]
            views.append("[" + ", ".join(json.dumps(r, allow_nan=False) for r in rows) + "]")
        frames.append('{"views": [\n  ' + ",\n  ".join(views) + "\n]}")
    text = frames[0] if not had_frames else '{"frames": [\n' + ",\n".join(frames) + "\n]}"
    with atomic_write(path, "w") as fh:
        fh.write(text + "\n")


def detection_order(mask: Any) -> np.ndarray:
    """Slots in the order :func:`save_detections_json` writes them: ``(M, P)`` int, the
    index of each valid slot in its view's list in the file, ``-1`` for masked-out slots."""
    mask = np.asarray(mask, dtype=bool)
    return np.where(mask, np.cumsum(mask, axis=-1) - 1, -1)
