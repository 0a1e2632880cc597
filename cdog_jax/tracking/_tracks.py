"""Track ids across frames: each frame's groups linked to the previous frame's by the 3D
distance of their points (docs/ALGORITHM.md §19, beyond the paper).

A frame's groups are matched one to one with the groups alive in the frame before (same
class only), greedily, cheapest pair first, under a gate on the distance a point may move
between two frames. A matched group inherits the track id; an unmatched one starts a new
id; ids are never reused. With ``temporal_prior=True`` the tracks left unmatched are first
looked for among the frame's unassigned detections (:mod:`cdog_jax.tracking._temporal_prior`).

The association of all frames runs first, in one batched call (it does not depend on the
tracks: the prior only adds groups made of detections the association left unassigned);
then one ``lax.scan`` over the frames links and recovers, a pure function of padded, masked
tensors (``vmap`` it over sequences), since each frame needs the previous frame's final
tracks, recovered points included.
"""

from __future__ import annotations

from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .._expect import expect_args
from .._result import Association, batched_association
from .._runtime.xla_kernels import jit
from .._types import Array, Bool, Float, Int
from .._validate import as_array
from ..geometry._camera import Rig
from ..geometry._distortion import as_lens, undistorted_frames
from ..geometry._vectors import distance
from ..people._classes import frame_of_scenes
from ._matching import greedy_match
from ._temporal_prior import recover_tracks

DEFAULT_MAX_STEP_PX = 60.0
"""Default gate of a track's step between frames (pixels at the point's depth): a wrist
swinging at 2.4 m/s, filmed at 10 fps from 5 m with f = 1200 px, moves ≈ 58 px."""


class TrackedAssociation(NamedTuple):
    """Groups of ``F`` frames with a track id each (what :func:`track_groups` and
    :func:`cdog_jax.associate_sequence` return).

    Attributes:
        association: an :class:`Association` with a leading frame axis, ``G'`` groups per
            frame: the input's ``G`` rows, then (``temporal_prior=True``) ``G`` more rows for
            groups recovered by the prior; ``labels (F, M, P)`` include the recovered
            members. Valid groups come first in every frame.
        track_id: ``(F, G')`` int32 track of every group, ``-1`` where not valid. Ids start at
            0, in order of first appearance, and are never reused.
        recovered: ``(F, G')`` bool, the group was recovered by the temporal prior.
        group_class: ``(F, G')`` int32 class of every group (``-1`` where not valid), or
            ``None`` when the detections carry no classes.
        class_names: the names by class id, or ``None``.
        num_classes: ``C``, or ``None`` without classes.
        num_tracks: the number of track ids given.
        unplaced: ``(F,)`` int32 tracks the prior found but could not store (the frame's
            ``G`` extra rows were full); ``0`` everywhere in any ordinary sequence.
    """

    association: Association
    track_id: np.ndarray
    recovered: np.ndarray
    group_class: np.ndarray | None
    class_names: tuple[str, ...] | None
    num_classes: int | None
    num_tracks: int
    unplaced: np.ndarray


def scene_units_per_px(rig: Rig, X: Float[Array, "G 3"]) -> Float[Array, " G"]:
    """Scene units that one pixel spans at the depth of each point ``X (G, 3)``, averaged
    over the views: ``|z_cam · K₂₂| / sqrt|K₀₀ K₁₁|`` (a small motion ``d`` across a view's
    line of sight moves the point by about ``d / units_per_px`` pixels)."""
    z = jnp.abs(jnp.einsum("mj,gj->gm", rig.R[:, 2, :], X) + rig.t[None, :, 2])  # (G, M)
    K = rig.K
    per_view = jnp.abs(K[:, 2, 2]) / jnp.sqrt(jnp.abs(K[:, 0, 0] * K[:, 1, 1]))  # (M,)
    return jnp.mean(z * per_view[None, :], axis=1)


def link_frame(
    prev_X: Float[Array, "H 3"],
    prev_valid: Bool[Array, " H"],
    prev_class: Int[Array, " H"],
    X: Float[Array, "G 3"],
    valid: Bool[Array, " G"],
    cls: Int[Array, " G"],
    gate: Float[Array, " H"],
) -> Int[Array, " H"]:
    """The group of this frame ``(H,)`` (``-1``: none) of every previous group: greedy
    cheapest-first on the 3D distance, same class, at most ``gate (H,)`` (scene units, per
    previous group)."""
    d = distance(prev_X[:, None, :], X[None, :, :])  # (H, G)
    allowed = (
        prev_valid[:, None]
        & valid[None, :]
        & (prev_class[:, None] == cls[None, :])
        & (d <= gate[:, None])
    )
    return greedy_match(jnp.where(allowed, d, jnp.inf))


class _Frame(NamedTuple):
    """One frame's groups, capacity ``H`` (the inputs' ``G`` rows, padded)."""

    X: Float[Array, "H 3"]
    valid: Bool[Array, " H"]
    cls: Int[Array, " H"]
    groups: Int[Array, "H M"]
    bpe: Float[Array, " H"]
    err_px: Float[Array, " H"]
    labels: Int[Array, "M P"]
    xy: Float[Array, "M P 2"]
    mask: Bool[Array, "M P"]
    det_class: Int[Array, "M P"]
    err_gate_px: Float[Array, ""]


class _Out(NamedTuple):
    X: Float[Array, "H 3"]
    valid: Bool[Array, " H"]
    cls: Int[Array, " H"]
    groups: Int[Array, "H M"]
    bpe: Float[Array, " H"]
    err_px: Float[Array, " H"]
    labels: Int[Array, "M P"]
    track: Int[Array, " H"]
    recovered: Bool[Array, " H"]
    unplaced: Int[Array, ""]


def track_step(
    rig: Rig,
    carry: tuple,
    f: _Frame,
    max_step: Float[Array, ""],
    max_step_px: Float[Array, ""],
    *,
    prior: bool,
    min_views: int,
    max_gap: int,
) -> tuple[tuple, _Out]:
    """Link (and with ``prior``, recover) one frame ``f`` (``H`` rows, the last rows free for
    recovered groups) to the tracks in ``carry`` (:func:`initial_tracks`): the new carry and
    the frame's final table. ``max_step``: the gate in scene units, or ``nan``:
    ``max_step_px`` pixels at each point's depth; a track unseen for ``a <= max_gap`` frames
    is still linked from its last point, with ``a + 1`` times the gate."""
    H = f.valid.shape[0]
    prev_X, prev_valid, prev_class, prev_track, prev_age, next_id = carry
    steps = (prev_age + 1).astype(prev_X.dtype)
    gate = steps * jnp.where(
        jnp.isnan(max_step), max_step_px * scene_units_per_px(rig, prev_X), max_step
    )
    match = link_frame(prev_X, prev_valid, prev_class, f.X, f.valid, f.cls, gate)  # (T,)
    rows = jnp.arange(H, dtype=jnp.int32)
    linked = jnp.any(match[:, None] == rows[None, :], axis=0)  # (H,) rows that continue a track
    inherited = jnp.max(jnp.where(match[:, None] == rows[None, :], prev_track[:, None], -1), axis=0)
    new = f.valid & ~linked
    track = jnp.where(
        linked, inherited, jnp.where(new, next_id + jnp.cumsum(new, dtype=jnp.int32) - 1, -1)
    ).astype(jnp.int32)
    next_id = next_id + jnp.sum(new, dtype=jnp.int32)
    out = _Out(
        f.X,
        f.valid,
        f.cls,
        f.groups,
        f.bpe,
        f.err_px,
        f.labels,
        track,
        jnp.zeros(H, bool),
        jnp.int32(0),
    )
    if prior:
        lost = prev_valid & (match < 0)
        out = recover_tracks(
            rig,
            out,
            prev_X,
            lost,
            prev_class,
            prev_track,
            f.xy,
            f.mask,
            f.det_class,
            steps * max_step_px,
            f.err_gate_px,
            min_views,
        )
    carried = (out.X, out.valid, out.cls, out.track, jnp.zeros(H, jnp.int32))
    if max_gap:
        seen = jnp.any((prev_track[:, None] == out.track[None, :]) & out.valid[None, :], axis=1)
        unseen = prev_valid & ~seen & (prev_age < max_gap)
        at = jnp.where(
            unseen, jnp.cumsum(unseen) - 1, H
        )  # the k-th unseen track in row k of the second half
        second = lambda a, fill: (
            jnp.full((H, *a.shape[1:]), fill, a.dtype).at[at].set(a, mode="drop")
        )  # noqa: E731
        tail = (
            second(prev_X, 0),
            second(unseen, False),
            second(prev_class, -1),
            second(prev_track, -1),
            second(prev_age + 1, 0),
        )
        carried = tuple(jnp.concatenate([a, b]) for a, b in zip(carried, tail))
    return (*carried, next_id), out


def initial_tracks(rows: int, max_gap: int, dtype) -> tuple:
    """The tracks before the first frame of frames of ``rows`` rows: none (``T = rows``, or
    ``2 · rows`` with ``max_gap``, carried rows), the next id 0."""
    T = (
        rows if max_gap == 0 else 2 * rows
    )  # tracks carried: this frame's rows, then the unseen ones
    return (
        np.zeros((T, 3), dtype),
        np.zeros(T, bool),
        np.zeros(T, np.int32),
        np.full(T, -1, np.int32),
        np.zeros(T, np.int32),
        np.int32(0),
    )


@partial(jax.jit, static_argnames=("prior", "min_views", "max_gap"))
def track_sequence(
    rig: Rig,
    init: tuple,
    frames: _Frame,
    max_step: Float[Array, ""],
    max_step_px: Float[Array, ""],
    *,
    prior: bool,
    min_views: int,
    max_gap: int,
) -> tuple[tuple, _Out]:
    """:func:`track_step` over the ``F`` frames of ``frames`` (fields with a leading ``F``), as
    one ``lax.scan`` from the tracks ``init`` (:func:`initial_tracks`, or where an earlier
    part of the recording stopped). Returns the tracks after the last frame and the frames'
    final tables, ``(F, …)``."""
    step = partial(
        track_step,
        rig,
        max_step=max_step,
        max_step_px=max_step_px,
        prior=prior,
        min_views=min_views,
        max_gap=max_gap,
    )
    return lax.scan(step, init, frames)


track_one = jit(track_step, static_argnames=("prior", "min_views", "max_gap"))
"""One frame of :func:`track_step`, compiled (the live loop's linking)."""


@partial(jit, static_argnames=("rows", "prior", "min_views", "max_gap"))
def track_scenes(
    rig: Rig,
    carry: tuple,
    result: Association,
    slot: Int[Array, "B M Pc"],
    scene_class: Int[Array, " B"],
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    det_class: Int[Array, "M P"],
    max_err_px: Float[Array, ""],
    max_step: Float[Array, ""],
    max_step_px: Float[Array, ""],
    *,
    rows: int,
    prior: bool,
    min_views: int,
    max_gap: int,
) -> tuple[tuple, _Out, Int[Array, ""]]:
    """One frame's class scenes ``result (B, G, …)`` (as the association program returns
    them; ``slot``, ``scene_class`` as in :func:`~cdog_jax.people._classes.frame_of_scenes`)
    made the frame's table of ``rows`` groups and tracked (:func:`track_step`), in one
    program: the association's group tables go from its program to this one without the
    host. ``xy``, ``mask``, ``det_class``:
    the frame's detections (the prior's; zeros without it); ``max_err_px``: the prior's
    error gate, or NaN for the frame's τ. Returns the new carry, the frame's final table and
    the frame's number of groups: more than ``rows`` and the table holds only the first
    ``rows`` (the caller raises ``rows`` and runs the frame again)."""
    H = 2 * rows if prior else rows
    X, valid, cls, groups, bpe, err_px, labels, found, tau = frame_of_scenes(
        result, slot, scene_class, mask.shape[1], rows, H
    )
    err_gate = jnp.where(jnp.isnan(max_err_px), tau, max_err_px).astype(X.dtype)
    frame = _Frame(X, valid, cls, groups, bpe, err_px, labels, xy, mask, det_class, err_gate)
    carry, out = track_step(
        rig, carry, frame, max_step, max_step_px, prior=prior, min_views=min_views, max_gap=max_gap
    )
    return carry, out, found


def _unpack(result: Any) -> tuple[Any, np.ndarray | None, tuple | None, int | None]:
    if hasattr(result, "association") and hasattr(result, "group_class"):
        gc = None if result.group_class is None else np.asarray(result.group_class)
        return result.association, gc, result.class_names, result.num_classes
    return result, None, None, None


def track_groups(
    rig: Rig,
    result: Any,
    *,
    xy: Any = None,
    mask: Any = None,
    classes: Any = None,
    temporal_prior: bool = False,
    max_step: float | None = None,
    max_step_px: float = DEFAULT_MAX_STEP_PX,
    max_err_px: float | None = None,
    max_gap: int = 0,
    min_views: int = 2,
    dist: Any = None,
) -> TrackedAssociation:
    """Give every group of a sequence of frames a track id, optionally recovering points the
    association missed from the previous frame's points (ALGORITHM.md §19).

    Args:
        rig: the ``M`` cameras.
        result: the association of ``F`` frames: what :func:`cdog_jax.associate_classes`
            returns, or an :class:`Association` with a leading frame axis
            (:func:`cdog_jax.associate_batch`: ``labels (F, M, P)``).
        xy, mask: ``(F, M, P, 2)`` and ``(F, M, P)``, the detections ``result`` was computed
            from; needed by the prior only.
        classes: ``(F, M, P)`` their class ids; needed by the prior when ``result`` has classes.
        temporal_prior: look for every track that ends in a frame among that frame's
            unassigned detections of its class near the reprojections of its last point
            (within ``max_step_px``); with detections in ``>= min_views`` views that
            triangulate to a point reprojecting within ``max_err_px`` of each, the track
            continues with that new group.
        max_step: the most a point moves between frames (scene units); ``None``:
            ``max_step_px`` pixels at the point's depth (:func:`scene_units_per_px`).
        max_step_px: the step gate in pixels (default 60 px: 10 fps walking people at 5 m).
        max_err_px: a recovered group's largest reprojection error (px); ``None``: the
            frame's epipolar gate ``tau_px``.
        max_gap: the most frames a track may go unseen and still continue (linked, or found
            by the prior, from its last point with the gates times the frames since); ``0``
            (default): a point keeps its id while it is seen in consecutive frames.
        min_views: the fewest views of a recovered group.
        dist: the lens of every view (``(M, 5)`` or a ``Fisheye``) when ``xy`` are recorded
            pixels, as given to the association.

    Returns:
        A :class:`TrackedAssociation`. Raises ``ValueError`` before any work for a result of
        one scene, shapes that do not match, or a gate that is not a positive number.
    """
    return track_part(
        rig,
        result,
        None,
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
    )[0]


class TrackerState(NamedTuple):
    """Where the tracker stopped in a recording: the tracks it carries (the layout of
    :func:`initial_tracks`) for frame tables of ``rows`` group rows."""

    carry: tuple
    rows: int


def track_part(
    rig: Rig,
    result: Any,
    state: TrackerState | None,
    *,
    xy: Any,
    mask: Any,
    classes: Any,
    temporal_prior: bool,
    max_step: float | None,
    max_step_px: float,
    max_err_px: float | None,
    max_gap: int,
    min_views: int,
    dist: Any,
) -> tuple[TrackedAssociation, TrackerState]:
    """:func:`track_groups` of one part of a recording, continued from where the part before
    stopped (``state``; ``None``: the first part) with the same options; returns the part's
    tracks and the state to continue from. The parts of a recording tracked one after the
    other give the groups and track ids of the whole tracked at once (a long recording then
    needs the memory of one part). A part may hold more group rows than the one before
    (the tracks carried grow); track ids count on over the parts."""
    expect_args("track_groups", rig=(rig, Rig))
    assoc, group_class, names, C = _unpack(result)
    missing = [
        k
        for k in ("labels", "groups", "valid", "points3d", "bpe", "err_px", "tau_px")
        if not hasattr(assoc, k)
    ]
    if missing:
        raise TypeError(
            f"track_groups: result must be an Association, a ClassAssociation or an object with their fields; "
            f"got {type(result).__name__} without {', '.join(missing)}"
        )
    labels = np.asarray(assoc.labels)
    if labels.ndim != 3:
        raise ValueError(
            f"track_groups: result must hold F frames (labels (F, M, P)); got labels of shape {labels.shape}"
        )
    F, M, P = labels.shape
    if M != rig.num_views:
        raise ValueError(f"track_groups: result has {M} views but the rig has {rig.num_views}")
    _check_gate("max_step", max_step, allow_none=True)
    _check_gate("max_step_px", max_step_px)
    _check_gate("max_err_px", max_err_px, allow_none=True)
    if isinstance(max_gap, bool) or not isinstance(max_gap, (int, np.integer)) or max_gap < 0:
        raise ValueError(f"track_groups: max_gap must be an int >= 0; got {max_gap!r}")
    if (
        isinstance(min_views, bool)
        or not isinstance(min_views, (int, np.integer))
        or not 2 <= min_views <= M
    ):
        raise ValueError(f"track_groups: min_views must be an int in [2, {M}]; got {min_views!r}")
    dtype = np.asarray(assoc.points3d).dtype
    if temporal_prior:
        if xy is None or mask is None:
            raise ValueError(
                "track_groups: temporal_prior=True needs the detections xy (F, M, P, 2) and mask (F, M, P)"
            )
        xy, mask = np.asarray(as_array(xy), dtype), np.asarray(as_array(mask))
        if xy.shape != (F, M, P, 2) or mask.shape != (F, M, P) or mask.dtype != bool:
            raise ValueError(
                f"track_groups: xy and mask must have shapes {(F, M, P, 2)} and {(F, M, P)} (bool) like the result's "
                f"labels; got xy {xy.shape}, mask {mask.shape} {mask.dtype}"
            )
        if group_class is not None and classes is None:
            raise ValueError(
                "track_groups: the result has classes: temporal_prior=True needs the detections' classes (F, M, P)"
            )
        det_class = np.zeros((F, M, P), np.int32) if group_class is None else np.asarray(classes)
        if det_class.shape != (F, M, P) or not np.issubdtype(det_class.dtype, np.integer):
            raise ValueError(
                f"track_groups: classes must be integer class ids of shape {(F, M, P)}; got {det_class.shape} {det_class.dtype}"
            )
        if dist is not None:
            lens = as_lens(dist, dtype)
            xy = np.asarray(undistorted_frames(rig, xy, mask, lens))
    else:
        xy, mask, det_class = (
            np.zeros((F, M, P, 2), dtype),
            np.zeros((F, M, P), bool),
            np.zeros((F, M, P), np.int32),
        )
    rows = np.asarray(assoc.valid).shape[1]
    table = lambda r: 2 * r if temporal_prior else r  # noqa: E731  (the prior's free rows)
    if state is None:
        carry = initial_tracks(table(rows), max_gap, dtype)
    else:
        carry = state.carry
        if rows > state.rows:
            carry = grown_tracks(carry, table(state.rows), table(rows), max_gap)
        rows = max(rows, state.rows)
    frames = tracking_frames(
        assoc, group_class, labels, xy, mask, det_class, max_err_px, rows, temporal_prior
    )
    step_units = jnp.asarray(np.nan if max_step is None else max_step, dtype)
    carry, out = track_sequence(
        rig,
        carry,
        frames,
        step_units,
        jnp.asarray(max_step_px, dtype),
        prior=temporal_prior,
        min_views=int(min_views),
        max_gap=int(max_gap),
    )
    return _tracked(assoc, out, group_class is not None, names, C), TrackerState(carry, rows)


def grown_tracks(carry: tuple, old: int, new: int, max_gap: int) -> tuple:
    """The tracker's state for frame tables of ``old`` rows (two blocks of them with
    ``max_gap``: the frame's tracks, then the unseen ones) as ``new`` rows: empty rows
    appended to each block (they hold no track)."""
    X, valid, cls, track, age, next_id = (np.asarray(a) for a in carry)
    fills = (0, False, -1, -1, 0)
    halves = 1 if max_gap == 0 else 2
    out = []
    for a, fill in zip((X, valid, cls, track, age), fills):
        parts = np.split(a, halves)
        out.append(
            np.concatenate(
                [
                    np.concatenate([p, np.full((new - old, *a.shape[1:]), fill, a.dtype)])
                    for p in parts
                ]
            )
        )
    return (*out, next_id)


def tracking_frames(
    assoc, group_class, labels, xy, mask, det_class, max_err_px, rows: int, prior: bool
) -> _Frame:
    """The ``F`` frames of an association (fields ``(F, G, …)``; ``group_class (F, G)`` or
    ``None``) as the tracker reads them: ``rows`` group rows (the first ``rows`` of ``G``,
    valid groups first, or padded with empty rows), ``rows`` more free rows for recovered
    groups with ``prior``. ``labels``, ``xy``, ``mask``, ``det_class``: ``(F, M, P, …)``,
    the detections the prior searches (zeros without it). Host arrays: the compiled
    tracker takes them as they are."""
    dtype = np.asarray(assoc.points3d).dtype
    valid = np.asarray(assoc.valid)
    F = valid.shape[0]
    H = 2 * rows if prior else rows
    cls = (
        np.zeros(valid.shape, np.int32)
        if group_class is None
        else np.asarray(group_class).astype(np.int32)
    )
    err_gate = (
        np.asarray(assoc.tau_px, dtype) if max_err_px is None else np.full(F, max_err_px, dtype)
    )

    def at_rows(a, fill):
        a = np.asarray(a)[:, :rows]
        return np.concatenate(
            [a, np.full((F, H - a.shape[1], *a.shape[2:]), fill, a.dtype)], axis=1
        )

    return _Frame(
        at_rows(assoc.points3d, 0),
        at_rows(valid, False),
        at_rows(cls, -1),
        at_rows(assoc.groups, -1),
        at_rows(assoc.bpe, 0),
        at_rows(assoc.err_px, 0),
        np.asarray(labels),
        np.asarray(xy),
        np.asarray(mask),
        np.asarray(det_class, np.int32),
        err_gate,
    )


def _check_gate(name: str, value, allow_none: bool = False) -> None:
    if value is None and allow_none:
        return
    ok = (
        isinstance(value, (int, float, np.integer, np.floating))
        and not isinstance(value, bool)
        and np.isfinite(value)
        and value > 0
    )
    if not ok:
        raise ValueError(
            f"track_groups: {name} must be a finite number > 0{' or None' if allow_none else ''}; got {value!r}"
        )


def _tracked(assoc, out: _Out, classed: bool, names, C) -> TrackedAssociation:
    groups = np.asarray(out.groups)
    valid = np.asarray(out.valid)
    # Valid groups first in every frame (recovered groups fill the free rows in order).
    order = np.argsort(~valid, axis=1, kind="stable")
    take = lambda a: np.take_along_axis(
        np.asarray(a), order.reshape(order.shape + (1,) * (np.ndim(a) - 2)), axis=1
    )  # noqa: E731
    F, H = valid.shape
    rank = np.empty_like(order)
    np.put_along_axis(rank, order, np.arange(H)[None, :].repeat(F, 0), axis=1)
    labels = np.asarray(out.labels)
    labels = np.where(
        labels >= 0,
        np.take_along_axis(rank, np.maximum(labels, 0).reshape(F, -1), axis=1).reshape(
            labels.shape
        ),
        -1,
    )
    groups, valid = take(groups), take(valid)
    association = batched_association(  # host arrays; placed on the device there
        labels=labels.astype(np.int32),
        groups=groups,
        valid=valid,
        points3d=take(out.X),
        bpe=take(out.bpe),
        err_px=take(out.err_px),
        n_views=np.sum(groups >= 0, axis=2, dtype=np.int32),
        num_groups=np.sum(valid, axis=1, dtype=np.int32),
        sigma_px=assoc.sigma_px,
        tau_px=assoc.tau_px,
        status=assoc.status,
    )
    track = take(out.track)
    return TrackedAssociation(
        association=association,
        track_id=track,
        recovered=take(out.recovered),
        group_class=take(out.cls) if classed else None,
        class_names=names,
        num_classes=C,
        num_tracks=int(track.max()) + 1 if track.size and track.max() >= 0 else 0,
        unplaced=np.asarray(out.unplaced),
    )
