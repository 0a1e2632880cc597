"""Two-view hypotheses checked by the other views: each gated pair of detections is
triangulated and reprojected, and the nearest eligible detection of every other view within
a gate votes for it (used by seeding, ALGORITHM.md §8f, and the ``voting`` baseline)."""

from typing import NamedTuple

import jax.numpy as jnp

from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ..geometry._projection import pixel_distances, project_views_last
from ..geometry._triangulate import solve_normal_3x3


class ScoredHypotheses(NamedTuple):
    """``ok (H,)``: usable (gated pair, well-conditioned point in front of both cameras);
    ``count (H,)``: its members, the pair and the voters (0 when not ``ok``); ``err (H,)``:
    their mean reprojection error (px, ``inf`` when not ``ok``); ``X (H, 3)`` the point;
    ``xy_hat (H, M, 2)`` its pixel in every view and ``vote_views (H, M)`` the views where a
    detection may vote (in front of the camera, not the pair's). :func:`voter_distances`
    of one row gives that hypothesis' ``(M, P)`` distances again: the ``(H, M, P)`` table is
    never stored (at 10 views × 130 slots it would hold 17 million entries)."""

    ok: Bool[Array, " H"]
    count: Int[Array, " H"]
    err: Float[Array, " H"]
    X: Float[Array, "H 3"]
    xy_hat: Float[Array, "H M 2"]
    vote_views: Bool[Array, "H M"]


def voter_distances(
    xy: Float[Array, "M P 2"],
    eligible: Bool[Array, "M P"],
    xy_hat: Float[Array, "*S M 2"],
    vote_views: Bool[Array, "*S M"],
) -> Float[Array, "*S M P"]:
    """Pixel distance ``(*S, M, P)`` from each hypothesis' point ``xy_hat (*S, M, 2)`` to every
    eligible detection of a view where it may vote (``vote_views (*S, M)``); ``inf`` elsewhere."""
    votes = eligible[(None,) * (vote_views.ndim - 1)] & vote_views[..., None]  # (*S, M, P)
    return jnp.where(votes, pixel_distances(xy_hat, xy), jnp.inf)


def accepted_row(
    xy: Float[Array, "M P 2"],
    eligible: Bool[Array, "M P"],
    used: Bool[Array, "M P"],
    xy_hat: Float[Array, "M 2"],
    vote_views: Bool[Array, " M"],
    src: Int[Array, ""],
    dst: Int[Array, ""],
    gate_px: Float[Array, ""],
) -> Int[Array, " M"]:
    """The group row ``(M,)`` (slot per view or -1) that accepting one hypothesis makes: its
    pair ``src``, ``dst`` (flat nodes ``view · P + slot``) and, in every other view where it
    may vote, the nearest ``eligible`` detection not yet ``used`` within ``gate_px`` of its
    point's pixel ``xy_hat`` (the first of equals: the smallest slot). Shared by seeding and
    the ``voting`` baseline, which differ only in the order they try hypotheses in."""
    P = eligible.shape[1]
    dist = jnp.where(used, jnp.inf, voter_distances(xy, eligible, xy_hat, vote_views))  # (M, P)
    slot = jnp.argmin(dist, axis=-1).astype(jnp.int32)
    row = jnp.where(jnp.min(dist, axis=-1) < gate_px, slot, -1)
    return row.at[src // P].set(src % P).at[dst // P].set(dst % P)


def score_hypotheses(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    eligible: Bool[Array, "M P"],
    blocks: tuple,
    src: Int[Array, " H"],
    dst: Int[Array, " H"],
    ok: Bool[Array, " H"],
    gate_px: Float[Array, ""],
) -> ScoredHypotheses:
    """Score the hypotheses ``(src, dst)`` (flat node indices ``view · P + slot``; ``ok`` the
    pairs that passed the epipolar gate) on ``xy (M, P, 2)`` (pixels, padding already
    neutral), voters among ``eligible``, with the per-node DLT ``blocks``."""
    M, P = eligible.shape
    N = M * P
    views = jnp.arange(M, dtype=jnp.int32)
    view_a, view_b = src // P, dst // P
    N_node, r_node, origin = blocks
    N_node, r_node = N_node.reshape(N, 3, 3), r_node.reshape(N, 3)
    X, ok_dlt = solve_normal_3x3(N_node[src] + N_node[dst], r_node[src] + r_node[dst])
    X = X + origin[None, :]
    xy_hat, front = project_views_last(rig, X)  # (H, M, 2), (H, M)
    hyp = jnp.arange(src.shape[0], dtype=jnp.int32)
    ok = ok & ok_dlt & front[hyp, view_a] & front[hyp, view_b]

    base = (views[None, :] == view_a[:, None]) | (views[None, :] == view_b[:, None])  # (H, M)
    vote_views = front & ~base
    reproj = voter_distances(xy, eligible, xy_hat, vote_views)  # (H, M, P) px, reduced at once

    flat_xy = xy.reshape(N, 2)

    def pair_error(node, view):
        e = jnp.where(ok[:, None], xy_hat[hyp, view] - flat_xy[node], 0.0)
        return jnp.sqrt(jnp.sum(e * e, axis=-1))

    nearest = jnp.min(reproj, axis=-1)  # (H, M)
    voter = nearest < gate_px
    count = jnp.where(ok, 2 + jnp.sum(voter, axis=-1, dtype=jnp.int32), 0)
    total = (
        pair_error(src, view_a)
        + pair_error(dst, view_b)
        + jnp.sum(jnp.where(voter, nearest, 0.0), axis=-1)
    )
    err = jnp.where(ok, total / jnp.maximum(count, 1).astype(total.dtype), jnp.inf)
    return ScoredHypotheses(ok, count, err, X, xy_hat, vote_views)
