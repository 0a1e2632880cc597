"""Detector scores (confidences) as the library takes them: one rule for every reader.

Scores are probabilities in [0, 1]. Some detectors overshoot slightly: OpenPose's part
heatmap peaks reach about 1.04. A score in (1, :data:`SCORE_TOLERANCE`] is taken as 1
(clipped, and the clipping said in a note); a score above it, below 0, or NaN is not a
probability and refuses the file (rescale such scores to [0, 1] first).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

SCORE_TOLERANCE = 1.1  # largest score taken as 1


def clip_scores(
    conf: np.ndarray, mask: np.ndarray, error: Callable[[str, int, int, int], Exception]
) -> tuple[np.ndarray, str | None]:
    """Scores ``conf (F, M, P)`` of the detections on ``mask (F, M, P)`` in [0, 1].

    Args:
        conf: the scores as read (float).
        mask: which slots hold a detection; other slots are set to 0.
        error: ``error(text, f, m, i)`` builds the exception for detection ``i`` of view
            ``m`` in frame ``f`` (the caller knows the file and how to name the location).

    Returns:
        ``(conf, note)``: the scores with those in (1, SCORE_TOLERANCE] set to 1, and a note
        saying how many were clipped (``None`` when none were). Raises ``error(…)`` for the
        first score below 0, above ``SCORE_TOLERANCE``, or NaN.
    """
    bad = mask & ~((conf >= 0.0) & (conf <= SCORE_TOLERANCE))  # NaN fails both comparisons
    if bad.any():
        f, m, i = (int(v) for v in np.argwhere(bad)[0])
        raise error(
            f"confidence {conf[f, m, i]} is outside [0, 1] or NaN (scores up to {SCORE_TOLERANCE:g} are taken as 1; "
            "rescale other scores to [0, 1])",
            f, m, i,
        )  # fmt: skip
    above = mask & (conf > 1.0)
    note = None
    if above.any():
        note = (
            f"{int(above.sum())} confidences above 1 (at most {float(conf[above].max()):.4g}) clipped to 1 "
            f"(scores up to {SCORE_TOLERANCE:g} are taken as 1)"
        )
    return np.where(mask, np.minimum(conf, 1.0), 0.0), note
