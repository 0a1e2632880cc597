"""What a result can say about itself: bit flags in :attr:`Association.status`.

A pipeline never stops with an exception inside ``jit``; instead every condition that makes
a result less than fully trustworthy sets one bit of an ``int32`` status (as optimistix
reports ``RESULTS`` as a value). ``status == 0`` means nothing happened that the caller
should know about. Several flags can be set at once; :func:`status_messages` turns a status
into sentences, and :func:`check_status` raises on any flag.
"""

from __future__ import annotations

import enum

import numpy as np


class Status(enum.IntFlag):
    """Flags of :attr:`Association.status` (combine with ``|``; test with ``&``)."""

    OK = 0
    SPLIT_CAPPED = 1  # the view-uniqueness split stopped at Config.max_split_iters
    IQR_CAPPED = 2  # the IQR outlier loop stopped at Config.max_iqr_iters
    COMPONENTS_CAPPED = 4  # connected components stopped at their round bound
    SIGMA_FALLBACK = 8  # sigma="auto" had too little evidence and used its fallback
    REFINE_CAPPED = 16  # point refinement stopped at Config.refine_max_steps
    LENS_NOT_INVERTED = 32  # undistortion failed at some detection (the lens model folds there)
    NONFINITE_DETECTION = 64  # a valid slot held NaN or inf (under jit): left out
    AMBIGUOUS_GEOMETRY = 128  # groups the epipolar geometry could not vouch for: dissolved


_MESSAGES = {
    Status.SPLIT_CAPPED: "the view-uniqueness split stopped at its iteration bound (Config.max_split_iters); "
    "the last-resort detach decided the remaining conflicts",
    Status.IQR_CAPPED: "the IQR outlier loop stopped at its iteration bound (Config.max_iqr_iters); "
    "some groups may still hold outliers",
    Status.COMPONENTS_CAPPED: "connected components stopped at their round bound; labels may be incomplete",
    Status.SIGMA_FALLBACK: 'sigma="auto" found too few likely-true matches to estimate the noise and '
    "used its fallback value, 1 px (or an implausibly large one, and used 1 % of the focal length); "
    "pass sigma= explicitly if you know it",
    Status.REFINE_CAPPED: "point refinement stopped at its step bound (Config.refine_max_steps)",
    Status.NONFINITE_DETECTION: "a detection in a valid slot was not finite (NaN or inf) and was "
    "left out of the association (inside a compiled program it cannot be refused)",
    Status.AMBIGUOUS_GEOMETRY: "some groups were dissolved because the epipolar geometry cannot "
    "vouch for them: their point lies in one plane with the centres of the cameras "
    "that see it (closer than the gate can resolve), where every epipolar line is the same "
    "line, and another detection fits that "
    "line as well as a member (points at the height of a ring of cameras, or a rig whose "
    "centres are in a line); their detections are left unassigned",
    Status.LENS_NOT_INVERTED: "the lens model could not be inverted at some detection (distorting "
    "its undistorted pixel again misses it by more than 0.1 px: the distortion coefficients fold "
    "the image there, e.g. a large negative k1); those detections' points are unreliable: check "
    "the distortion",
}


def status_messages(status) -> list[str]:
    """One sentence per flag set in ``status`` (an int or a 0-d array); empty when 0."""
    code = int(np.asarray(status))
    return [text for flag, text in _MESSAGES.items() if code & int(flag)]


def check_status(status) -> None:
    """Raise ``RuntimeError`` listing every flag set in ``status`` (a scalar or an array of
    per-scene statuses); return quietly when all are 0."""
    codes = np.asarray(status).reshape(-1)
    bad = [(i, int(c)) for i, c in enumerate(codes) if int(c)]
    if not bad:
        return
    where = "" if codes.size == 1 else f"scene {bad[0][0]}: "
    raise RuntimeError(where + "; ".join(status_messages(bad[0][1])))
