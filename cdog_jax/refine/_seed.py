"""Seeding groups from two-view hypotheses on the leftovers (beyond the paper; ``Config.seed``).

What association, recovery and regrouping leave over is mostly points whose epipolar
edges were pruned as ambiguous: with many points and large σ, every epipolar band holds
several detections. A triangulated pair is checked by the other views instead: every
leftover detection is paired with its cheapest leftover detection in each other view
(symmetric epipolar cost ``½ (d[m, i, n, j] + d[n, j, m, i])`` below τ), the pair is
triangulated (two-view DLT, well conditioned, in front of both cameras) and reprojected
into the other views, where the nearest leftover detection within ``seed_frac · τ`` pixels
votes for it. Hypotheses are ranked by votes (more first), then mean reprojection error
over all their members (smaller first), then index; in that order each one whose two
detections are both still free becomes a group of its pair and its voters that are still
free (one per view). The loop jumps from one accepted hypothesis to the next, so it runs
at most once per new group (at most ``N // 2 + 1`` steps) and has no bound to reach.
"""

from typing import Annotated, NamedTuple

import jax
import jax.numpy as jnp

from .._config import AtLeast, Number, Range, Switch
from .._stage import GroupTable, Scene, Stage, State
from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ..graph._adjacency import min_and_first_index
from ..graph._groups import compact_groups
from ._hypotheses import score_hypotheses, voter_distances
from ._attach import leftover_nodes
from ._support import missing_views


class SeedOptions(NamedTuple):
    """``seed_min_views``: the fewest members (pair + voters) a seeded group needs."""

    seed_min_views: Annotated[int, AtLeast(2)] = 2


HYPOTHESIS_CHUNK = 256
"""Two-view hypotheses scored at a time. Only pairs that pass the epipolar gate are scored,
a chunk at a time until none is left: a scene's leftovers are few (11–18 gated pairs of
19,200 hypotheses at 10 views × 192 slots), and each hypothesis is checked against every
detection of every view."""


def _score_gated(rig, xy, mask, free, blocks, src, dst, gated, gate_px, support_px, min_views):
    """The hypotheses ``(src, dst)`` (``H``) that pass the pair gate ``gated (H,)``, scored
    and checked for missing views: ``ok``, ``err`` (px, ``inf`` where not ok), ``count``,
    ``xy_hat (H', M, 2)``, ``vote_views (H', M)`` and ``hyp (H',)`` the hypothesis each row
    scores. Above one chunk, the gated hypotheses come first (in order) and the rows after
    them are not scored (not ok); at most one chunk, every row is row ``hyp``."""
    M, P = free.shape
    views = jnp.arange(M, dtype=jnp.int32)

    def score(a, b, g):
        scored = score_hypotheses(rig, xy, free, blocks, a, b, g, gate_px)
        pair = (views[None, :] == (a // P)[:, None]) | (views[None, :] == (b // P)[:, None])  # (K, M)
        missing, _ = missing_views(rig, xy, mask, scored.X, pair, support_px)
        ok = scored.ok & (scored.count >= min_views) & ~jnp.any(missing, axis=1)
        return ok, jnp.where(ok, scored.err, jnp.inf), scored.count, scored.xy_hat, scored.vote_views

    H = src.shape[0]
    if H <= HYPOTHESIS_CHUNK:
        return score(src, dst, gated) + (jnp.arange(H, dtype=jnp.int32),)
    K = HYPOTHESIS_CHUNK
    rows = -(-H // K) * K
    hyp = jnp.argsort(~gated, stable=True).astype(jnp.int32)  # the gated first, in order
    hyp = jnp.concatenate([hyp, jnp.zeros((rows - H,), jnp.int32)])
    num_gated = jnp.sum(gated, dtype=jnp.int32)
    is_gated = jnp.arange(rows, dtype=jnp.int32) < num_gated
    src, dst = src[hyp], dst[hyp]

    def body(carry):
        start, tables = carry
        chunk = [jax.lax.dynamic_slice_in_dim(v, start, K) for v in (src, dst, is_gated)]
        tables = tuple(jax.lax.dynamic_update_slice_in_dim(t, c, start, 0) for t, c in zip(tables, score(*chunk)))
        return start + K, tables

    tables = (
        jnp.zeros((rows,), bool), jnp.full((rows,), jnp.inf, xy.dtype), jnp.zeros((rows,), jnp.int32),
        jnp.zeros((rows, M, 2), xy.dtype), jnp.zeros((rows, M), bool),
    )
    _, tables = jax.lax.while_loop(lambda c: c[0] < num_gated, body, (jnp.int32(0), tables))
    return tables + (hyp,)


def seed_groups(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    free: Bool[Array, "M P"],
    d: Float[Array, "M P M P"],
    blocks: tuple,
    tau_px: Float[Array, ""],
    gate_px: Float[Array, ""],
    support_px: Float[Array, ""],
    min_views: int,
) -> Int[Array, "G M"]:
    """New groups ``(G, M)`` (slot per view or -1; unused rows all -1, ``G = M·P // 2``)
    made of the ``free (M, P)`` detections only; ``xy (M, P, 2)`` pixels, ``d`` the epipolar
    distances (px), ``blocks`` the per-node DLT blocks, ``tau_px`` the pair gate and
    ``gate_px`` the vote gate (px)."""
    M, P = free.shape
    N, G = M * P, max(M * P // 2, 1)
    views = jnp.arange(M, dtype=jnp.int32)
    slots = jnp.arange(P, dtype=jnp.int32)
    ok_pair = free[:, :, None, None] & free[None, None, :, :] & (views[:, None, None, None] != views[None, None, :, None])
    d = jnp.where(ok_pair & ~jnp.isnan(d), d, jnp.inf)
    cost = 0.5 * (d + jnp.transpose(d, (2, 3, 0, 1)))  # (M, P, M, P) px, symmetric
    best_cost, best = min_and_first_index(cost, axis=-1)  # (M, P, M): first of equals
    src = jnp.broadcast_to((views[:, None, None] * P + slots[None, :, None]), (M, P, M)).reshape(-1)  # (H,)
    dst = (views[None, None, :] * P + best).reshape(-1)
    ok, err, count, xy_hat, vote_views, hyp = _score_gated(
        rig, xy, mask, free, blocks, src, dst, (best_cost < tau_px).reshape(-1), gate_px, support_px, min_views
    )
    order = jnp.lexsort((hyp, err, jnp.where(ok, -count, 0)))
    src, dst, xy_hat, vote_views = src[hyp][order], dst[hyp][order], xy_hat[order], vote_views[order]
    num_ranked = jnp.sum(ok, dtype=jnp.int32)
    rank = jnp.arange(src.shape[0], dtype=jnp.int32)

    def cond(carry):
        _, _, num_groups, k = carry
        return (k < num_ranked) & (num_groups < G)

    def body(carry):
        used, groups, num_groups, k = carry
        flat = used.reshape(N)
        alive = (rank >= k) & (rank < num_ranked) & ~flat[src] & ~flat[dst]
        k = jnp.min(jnp.where(alive, rank, num_ranked))
        found = k < num_ranked
        h = jnp.minimum(k, src.shape[0] - 1)
        a, b = src[h], dst[h]
        dist = jnp.where(used, jnp.inf, voter_distances(xy, free, xy_hat[h], vote_views[h]))  # (M, P)
        slot = jnp.argmin(dist, axis=-1).astype(jnp.int32)
        row = jnp.where(jnp.min(dist, axis=-1) < gate_px, slot, -1)
        row = row.at[a // P].set(a % P).at[b // P].set(b % P)
        # Voters taken by earlier groups may leave fewer than min_views members: skip it.
        found = found & (jnp.sum(row >= 0, dtype=jnp.int32) >= min_views)
        groups = groups.at[num_groups].set(jnp.where(found, row, groups[num_groups]), mode="drop")
        used = used | (found & (slots[None, :] == row[:, None]))
        return used, groups, num_groups + found.astype(jnp.int32), k + 1

    init = (~free, jnp.full((G, M), -1, jnp.int32), jnp.int32(0), jnp.int32(0))
    _, groups, _, _ = jax.lax.while_loop(cond, body, init)
    return groups


def seed_stage(scene: Scene, state: State, options: SeedOptions) -> State:
    """New groups seeded from two-view hypotheses on the leftover detections join the table."""
    table = state.table
    M, P = scene.mask.shape
    free = leftover_nodes(*table, scene.mask).reshape(M, P)
    new = seed_groups(
        scene.rig, scene.xy, scene.mask, free, scene.d, scene.blocks, scene.tau, scene.th.seed_frac * scene.tau,
        scene.th.seed_support_frac * scene.tau, options.seed_min_views,
    )
    G = table.groups.shape[0]
    groups = jnp.concatenate([table.groups, new])
    valid = jnp.concatenate([table.valid, jnp.any(new >= 0, axis=1)])
    groups, valid, _ = compact_groups(jnp.where(valid[:, None], groups, -1), valid)
    return state._replace(table=GroupTable(groups[:G], valid[:G]), fit=None)


SEED = Stage(
    "seed", seed_stage, SeedOptions,
    Switch("seed", False, "groups from two-view hypotheses on what is still left (beyond the paper)"),
    numbers=(
        Number("seed_frac", 1.5, Range(0.0, low_open=True), doc="seeding: a detection within seed_frac · τ votes for a two-view point"),
        Number("seed_support_frac", 1.5, Range(0.0, low_open=True),
               doc="seeding: a two-view point is not seeded where a view sees it with no detection within seed_support_frac · τ"),
    ),
)
