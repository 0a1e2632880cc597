"""Association of a sequence of frames with track ids (docs/ALGORITHM.md §19): every frame
associated in one batched call, then the groups linked over time (and, optionally, points
missed in a frame recovered from the previous frame's)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._associate import associate_batch
from .._expect import expect_args
from .._validate import as_array
from ..geometry._camera import Rig
from ..people._classes import associate_classes
from ._tracks import DEFAULT_MAX_STEP_PX, TrackedAssociation, track_groups


def associate_sequence(
    rig: Rig,
    xy: Any,
    mask: Any,
    *,
    classes: Any = None,
    temporal_prior: bool = True,
    max_step: float | None = None,
    max_step_px: float = DEFAULT_MAX_STEP_PX,
    max_err_px: float | None = None,
    max_gap: int = 0,
    min_views: int = 2,
    dist: Any = None,
    **options: Any,
) -> TrackedAssociation:
    """Associate ``F`` frames and give every group a track id that it keeps while it is seen.

    Args:
        rig: the ``M`` cameras (shared by all frames).
        xy: ``(F, M, P, 2)`` detections (pixels), ``mask (F, M, P)`` bool.
        classes: optional ``(F, M, P)`` int class ids: the frames are then associated by
            :func:`cdog_jax.associate_classes` and tracks never change class; without them,
            by :func:`cdog_jax.associate_batch`.
        temporal_prior: recover a track missed in a frame from that frame's unassigned
            detections (as in :func:`cdog_jax.track_groups`); on by default here: it raised
            recall on real and synthetic recordings (docs/GUIDE.md).
        max_step, max_step_px, max_err_px, max_gap: as in :func:`cdog_jax.track_groups`.
        min_views, dist: shared by the association and the prior.
        options: passed to the association (``method``, ``sigma``, ``batch_size``, …;
            ``associate_batch``'s σ defaults to ``"auto"`` here).

    Returns:
        A :class:`cdog_jax.TrackedAssociation`. Checks as the association and
        :func:`cdog_jax.track_groups` do, before any work.
    """
    expect_args("associate_sequence", rig=(rig, Rig))
    xy, mask = np.asarray(as_array(xy)), np.asarray(as_array(mask))
    if xy.ndim != 4:
        raise ValueError(f"associate_sequence: xy must have shape (F, M, P, 2); got {xy.shape}")
    if classes is not None:
        result = associate_classes(
            rig, xy, mask, classes, min_views=min_views, dist=dist, **options
        )
    else:
        options.setdefault("sigma", "auto")
        result = associate_batch(rig, xy, mask, min_views=min_views, dist=dist, **options)
    return track_groups(
        rig,
        result,
        xy=xy,
        mask=mask,
        classes=classes,
        temporal_prior=temporal_prior,
        max_step=max_step,
        max_step_px=max_step_px,
        max_err_px=max_err_px,
        max_gap=max_gap,
        min_views=min_views,
        dist=dist,
    )
