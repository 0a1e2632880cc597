"""The temporal prior: a track that finds no group in a frame is looked for among the
frame's unassigned detections, near the reprojections of its last point (docs/ALGORITHM.md
§19, beyond the paper).

For every such track, in every view, the nearest unassigned detection of its class within
the step gate of its predicted pixel (one-to-one per view: each detection goes to the track
it is nearest to, cheapest pair first); the candidates are triangulated, the worst one is
dropped while some reprojects beyond the error gate (down to ``min_views``), and the track
continues with the new group when ``>= min_views`` detections remain, all within the gate
and in front of their cameras. A point the association missed in a frame (seen in too few
views for it, or its pair too ambiguous) is so recovered when its detections are where the
previous frame's point says they should be.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from jax import lax

from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ..geometry._projection import project_views_last, reprojection_errors_views_last
from ..geometry._triangulate import triangulate_views_last
from ..geometry._vectors import distance
from ._matching import greedy_match

FREE_SLOTS = 32
"""Unassigned detections per view that the candidate search holds at once: a frame's free
detections (missed by the association, strays) are few beside its slots (a live frame of
25 classes has 256 slots per view), so the search runs on them alone, packed to the front
in slot order; a frame with more in some view runs it on every slot. Either way the same
matches (the packing keeps every view's slot order, which breaks the matching's ties)."""


def _nearest_free(
    pred: Float[Array, "T M 2"],
    allowed_track: Bool[Array, "T M"],
    prev_class: Int[Array, " T"],
    gate_px: Float[Array, " T"],
    xy: Float[Array, "M P 2"],
    free: Bool[Array, "M P"],
    det_class: Int[Array, "M P"],
) -> Int[Array, "T M"]:
    """The slot ``(T, M)`` (``-1``: none) of every track's detection in every view: one to
    one per view, cheapest first, among the ``free`` detections of its class within
    ``gate_px`` of its predicted pixel ``pred``, where ``allowed_track``."""
    d = distance(pred[:, :, None, :], xy[None])  # (T, M, P)
    allowed = (
        allowed_track[:, :, None]
        & free[None]
        & (det_class[None] == prev_class[:, None, None])
        & (d <= gate_px[:, None, None])
    )
    return jax.vmap(greedy_match, in_axes=1, out_axes=1)(jnp.where(allowed, d, jnp.inf))


def _nearest_free_packed(
    pred: Float[Array, "T M 2"],
    allowed_track: Bool[Array, "T M"],
    prev_class: Int[Array, " T"],
    gate_px: Float[Array, " T"],
    xy: Float[Array, "M P 2"],
    free: Bool[Array, "M P"],
    det_class: Int[Array, "M P"],
    size: int,
) -> Int[Array, "T M"]:
    """:func:`_nearest_free` on each view's first ``size`` free detections, packed to the
    front in slot order (a view must hold at most ``size``): the same slots."""
    M, P = free.shape
    views = jnp.arange(M)
    slot = jax.vmap(lambda f: jnp.nonzero(f, size=size, fill_value=P - 1)[0])(free)  # (M, K)
    held = jnp.arange(size)[None, :] < jnp.sum(free, axis=1, keepdims=True)
    packed = _nearest_free(
        pred,
        allowed_track,
        prev_class,
        gate_px,
        xy[views[:, None], slot],
        held,
        det_class[views[:, None], slot],
    )  # (T, M): packed positions
    return jnp.where(packed >= 0, slot[views[None, :], jnp.maximum(packed, 0)], -1)


LOST_ROWS = 32
"""Lost tracks that the search holds at once: a frame loses few of its tracks (a live frame
carries 256 rows), so the search, the triangulations and the view dropping run on them
alone, packed to the front in row order; a frame that loses more runs them on every row.
Either way the same groups in the same rows (the packing keeps the tracks' order, which
breaks the matching's ties and gives each found track its free row), the points within
float32 round-off: where XLA fuses a multiply and an add into one rounding depends on a
program's shapes (bit for bit under the test suite's switches, which forbid that fusion)."""


def recover_tracks(
    rig: Rig,
    out: Any,
    prev_X: Float[Array, "T 3"],
    lost: Bool[Array, " T"],
    prev_class: Int[Array, " T"],
    prev_track: Int[Array, " T"],
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    det_class: Int[Array, "M P"],
    gate_px: Float[Array, " T"],
    err_gate_px: Float[Array, ""],
    min_views: int,
) -> Any:
    """One frame's table ``out`` (fields ``X (H, 3)``, ``valid``, ``cls``, ``groups (H, M)``,
    ``bpe``, ``err_px``, ``labels (M, P)``, ``track``, ``recovered``, ``unplaced``) with a
    group added in a free row for every ``lost (T,)`` track (last point ``prev_X (T, 3)``,
    class, id) found among the unassigned detections ``xy (M, P, 2)`` (pixels), ``mask``,
    ``det_class (M, P)``, within ``gate_px (T,)`` of its reprojections. ``unplaced``: tracks
    found with no free row left."""
    tracks = (prev_X, lost, prev_class, prev_track, gate_px)
    frame = (rig, out, xy, mask, det_class, err_gate_px, min_views)
    if prev_X.shape[0] <= LOST_ROWS:
        return _recover(*frame, *tracks)

    def packed(tracks):
        lost = tracks[1]
        rows = jnp.nonzero(lost, size=LOST_ROWS, fill_value=0)[0]
        held = jnp.arange(LOST_ROWS) < jnp.sum(lost)
        X, _, cls, track, gate = (a[rows] for a in tracks)
        return _recover(*frame, X, held, cls, track, gate)

    return lax.cond(
        jnp.sum(lost) <= LOST_ROWS, packed, lambda tracks: _recover(*frame, *tracks), tracks
    )


def _recover(
    rig,
    out,
    xy,
    mask,
    det_class,
    err_gate_px,
    min_views,
    prev_X,
    lost,
    prev_class,
    prev_track,
    gate_px,
) -> Any:
    """:func:`recover_tracks` on the tracks given (all, or the lost ones packed)."""
    H = out.valid.shape[0]
    T = prev_X.shape[0]
    M, P = mask.shape
    views = jnp.arange(M)
    pred, in_front = project_views_last(rig, prev_X)  # (T, M, 2), (T, M)
    free = mask & (out.labels < 0)
    search = (pred, lost[:, None] & in_front, prev_class, gate_px, xy, free, det_class)
    if P <= FREE_SLOTS:
        slot = _nearest_free(*search)  # (T, M)
    else:
        slot = lax.cond(
            jnp.all(jnp.sum(free, axis=1) <= FREE_SLOTS),
            lambda a: _nearest_free_packed(*a, FREE_SLOTS),
            lambda a: _nearest_free(*a),
            search,
        )
    member = slot >= 0
    pts = xy[views[None, :], jnp.maximum(slot, 0)]  # (T, M, 2)

    def member_errors(member):
        X, ok = triangulate_views_last(rig, pts, member)
        err = reprojection_errors_views_last(rig, X, pts)  # (T, M)
        _, front = project_views_last(rig, X)
        return X, ok, jnp.where(jnp.isfinite(err) & front, err, jnp.inf)

    def drop_worst(_, member):
        _, _, err = member_errors(member)
        err = jnp.where(member, err, -jnp.inf)
        worst = jnp.argmax(err, axis=1)
        drop = (jnp.max(err, axis=1) > err_gate_px) & (jnp.sum(member, axis=1) > min_views)
        return member & ~(drop[:, None] & (views[None, :] == worst[:, None]))

    member = lax.fori_loop(0, M - min_views, drop_worst, member)
    X, ok, err = member_errors(member)
    count = jnp.sum(member, axis=1)
    found = lost & ok & (count >= min_views) & jnp.all(~member | (err <= err_gate_px), axis=1)

    # The k-th found track takes the k-th free row.
    free_rows = jnp.nonzero(~out.valid, size=H, fill_value=H)[0]
    rank = jnp.cumsum(found) - 1
    row = jnp.where(found, free_rows[jnp.clip(rank, 0, H - 1)], H)
    row = jnp.where(rank < jnp.sum(~out.valid), row, H)
    placed = found & (row < H)
    at = jnp.where(placed, row, H)  # H: dropped by the scatters
    n = jnp.maximum(count, 1).astype(X.dtype)
    err_member = jnp.where(member, err, 0.0)
    m_at = jnp.where(placed[:, None] & member, views[None, :], M)  # (T, M)
    return out._replace(
        X=out.X.at[at].set(X, mode="drop"),
        valid=out.valid.at[at].set(True, mode="drop"),
        cls=out.cls.at[at].set(prev_class, mode="drop"),
        groups=out.groups.at[at].set(jnp.where(member, slot, -1), mode="drop"),
        bpe=out.bpe.at[at].set(jnp.sum(err_member**2, axis=1) / n, mode="drop"),
        err_px=out.err_px.at[at].set(jnp.sum(err_member, axis=1) / n, mode="drop"),
        labels=out.labels.at[m_at, jnp.maximum(slot, 0)].set(
            jnp.broadcast_to(row[:, None], (T, M)).astype(jnp.int32), mode="drop"
        ),
        track=out.track.at[at].set(prev_track, mode="drop"),
        recovered=out.recovered.at[at].set(True, mode="drop"),
        unplaced=out.unplaced + jnp.sum(found & ~placed, dtype=jnp.int32),
    )
