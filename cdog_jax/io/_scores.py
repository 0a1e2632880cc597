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
            f,
            m,
            i,
        )
    above = mask & (conf > 1.0)
    note = clipped_scores_note(int(above.sum()), float(conf[above].max())) if above.any() else None
    return np.where(mask, np.minimum(conf, 1.0), 0.0), note


def clipped_scores_note(count: int, top: float) -> str:
    """What :func:`clip_scores` says of ``count`` scores above 1, the largest ``top``."""
    return (
        f"{count} confidences above 1 (at most {top:.4g}) clipped to 1 "
        f"(scores up to {SCORE_TOLERANCE:g} are taken as 1)"
    )


def normalise_keypoint_scores(
    conf: np.ndarray,
    mask: np.ndarray,
    error: Callable[[str, int, int, int], Exception],
    largest: float | None = None,
) -> tuple[np.ndarray, str | None]:
    """Keypoint detector scores ``conf (F, M, P)`` on ``mask (F, M, P)`` mapped to [0, 1].

    The rule of the keypoint readers (OpenPose folders, tables), which take any
    non-negative score: when the file's largest score is at most :data:`SCORE_TOLERANCE`
    the scores are probabilities and :func:`clip_scores` applies (above 1 clipped to 1);
    when it is larger, the scores are on another scale and every score is divided by the
    largest, which becomes 1 (ratios kept; a note says so). A negative, infinite or NaN
    score refuses the file (``error(text, f, m, i)`` as in :func:`clip_scores`).
    ``largest``: the largest score of the whole recording when ``conf`` is a part of it (the
    rule then follows the whole, and the note is the caller's: :func:`scaled_scores_note`).
    """
    bad = mask & ~((conf >= 0.0) & np.isfinite(conf))
    if bad.any():
        f, m, i = (int(v) for v in np.argwhere(bad)[0])
        raise error(
            f"score {conf[f, m, i]} is negative, infinite or NaN (scores must be finite and >= 0)",
            f,
            m,
            i,
        )
    given = largest is not None
    if not given:
        largest = float(conf[mask].max()) if mask.any() else 0.0
    if largest <= SCORE_TOLERANCE:
        return clip_scores(conf, mask, error)
    return np.where(mask, conf / largest, 0.0), None if given else scaled_scores_note(largest)


def scaled_scores_note(largest: float) -> str:
    """What :func:`normalise_keypoint_scores` says when it divides every score by ``largest``."""
    return f"scores up to {largest:.4g} are not probabilities: all divided by the largest ({largest:.4g}), which becomes 1"
