"""The dense, padded form every detections reader and converter ends in (docs/CONVENTIONS.md §2)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


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
        instances: ``(F, M, P)`` int64 per-view instance index of every detection (the 2D
            skeleton it belongs to in its view; ``-1`` unknown or padding), or ``None``;
            for ``associate_classes(..., instances=, person_vote=True)``.
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
    instances: np.ndarray | None = None

    def scene(self, f: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """``(xy (M, P, 2), mask (M, P), confidence (M, P) or None)`` of frame ``f``, ready
        for :func:`cdog_jax.associate`."""
        conf = None if self.confidence is None else self.confidence[f]
        return self.xy[f], self.mask[f], conf
