"""Seeding groups from two-view hypotheses on the leftovers (beyond the paper; ``Config.seed``).

What association, recovery and regrouping leave over is mostly points whose epipolar
edges were pruned as ambiguous: with many points and large σ, every epipolar band holds
several detections. A triangulated pair is checked by the other views instead: every
leftover detection is paired with its cheapest leftover detection in each other view
(symmetric epipolar cost ``½ (d[m, i, n, j] + d[n, j, m, i])`` below τ), the pair is
triangulated (two-view DLT, well conditioned, in front of both cameras) and reprojected
into the other views, where the nearest leftover detection within ``seed_frac · τ`` pixels
votes for it. A view that sees the point with no detection near counts against it
(:class:`SeedSupport`: with the support filter's estimate of the scene's miss rate, as many
such views as that rate makes plausible are allowed; without it, none). Hypotheses are
ranked by votes (more first), then mean reprojection error over all their members (smaller
first), then index; in that order each one whose two
detections are both still free becomes a group of its pair and its voters that are still
free (one per view). Each step of the loop takes the next hypothesis in that order whose
two detections are free (two reductions over the hypotheses, no sort), so it runs once per
hypothesis it accepts or refuses, never more than there are usable ones, and has no bound
to reach. Only the free detections' hypotheses are formed, :data:`SOURCE_CHUNK` detections
at a time.
"""

from typing import Annotated, NamedTuple

import jax
import jax.numpy as jnp

from .._types import Array, Bool, Float, Int
from ..cdog._config import AtLeast, Range, Switch, Threshold
from ..cdog._stage import GroupTable, Scene, Stage, State
from ..geometry._camera import Rig
from ..graph._adjacency import min_and_first_index
from ..graph._groups import compact_groups
from ._attach import leftover_nodes
from ._hypotheses import accepted_row, score_hypotheses
from ._support import misses_plausible, missing_views


class SeedOptions(NamedTuple):
    """``seed_min_views``: the fewest members (pair + voters) a seeded group needs."""

    seed_min_views: Annotated[int, AtLeast(2)] = 2


SOURCE_CHUNK = 8
"""Free detections whose hypotheses are made and scored at a time, a chunk after another
until none is left (all at once in a scene of at most this many detections). A scene's
leftovers are few (13 of 1,920 detections at 10 views × 192 slots; a few in each keypoint
class of a live frame): no table of all pairs of the scene's detections is formed, each
hypothesis is checked against every detection, and a batch of scenes runs as many chunks as
its scene with the most leftovers needs (25 class scenes of 5 views × 8 slots: one chunk of
40 hypotheses each rather than all 200, the association a quarter faster; a single scene
of 10 views × 130 points as fast with chunks of 8, 16 or 64)."""


class SeedSupport(NamedTuple):
    """When a view that sees a hypothesis' point without a detection within ``radius_px``
    refuses it. Without a miss rate (``None``, or NaN: the support filter has not run), one
    such view does. With the scene's miss rate ``q`` (the support filter's estimate), the
    support filter's own test: ``k`` such views beside ``n`` members are refused when
    ``P(Bin(n + k, q) ≥ k) < alpha``, so that a point whose detection the detector missed in
    a view can still be seeded where misses are common."""

    radius_px: Float[Array, ""]
    miss_rate: Float[Array, ""] | None = None
    alpha: Float[Array, ""] | None = None

    def plausible(self, missing: Bool[Array, "R M"], count: Int[Array, " R"]) -> Bool[Array, " R"]:
        """``(R,)``: the hypotheses of ``count`` members and ``missing (R, M)`` views kept."""
        none_missing = ~jnp.any(missing, axis=1)
        if self.miss_rate is None:
            return none_missing
        q, M = self.miss_rate, missing.shape[1]
        k = jnp.sum(missing, axis=1, dtype=jnp.int32)
        # A voter's view can count as missing too when the support radius is below the vote
        # gate (seed_support_frac < seed_frac): the views that should detect are at most M.
        seen = jnp.minimum(count + k, M)
        tested = misses_plausible(k, seen, jnp.where(jnp.isnan(q), 0.5, q), self.alpha, M)
        return jnp.where(jnp.isnan(q), none_missing, tested)


class _Hypotheses(NamedTuple):
    """Two-view hypotheses, one row each (``R``): ``src``/``dst`` flat nodes ``view · P +
    slot``, ``ok`` usable (gated, well placed, ``count ≥ min_views``, its missing views
    plausible), ``err`` mean reprojection error (px; ``inf`` where not ok), ``count``
    members, ``xy_hat (R, M, 2)`` and ``vote_views (R, M)`` as in :class:`ScoredHypotheses`."""

    ok: Bool[Array, " R"]
    err: Float[Array, " R"]
    count: Int[Array, " R"]
    src: Int[Array, " R"]
    dst: Int[Array, " R"]
    xy_hat: Float[Array, "R M 2"]
    vote_views: Bool[Array, "R M"]


def _hypotheses_of(
    rig, xy, mask, free, d, blocks, sources, tau_px, gate_px, support, min_views
) -> _Hypotheses:
    """The hypotheses of the detections ``sources (C,)`` (flat nodes; ``N`` or a detection
    that is not free: none), ``C · M`` rows, source by source, view by view: each source
    paired with its cheapest free detection in every other view, at the symmetric epipolar
    cost ``½ (d[u, v] + d[v, u])`` (``d (N, N)`` px), gated below ``tau_px``."""
    M, P = free.shape
    N, C = M * P, sources.shape[0]
    views = jnp.arange(M, dtype=jnp.int32)
    node_view = jnp.arange(N, dtype=jnp.int32) // P
    flat_free = free.reshape(N)
    s = jnp.minimum(sources, N - 1)
    pair_ok = (
        ((sources < N) & flat_free[s])[:, None]
        & flat_free[None, :]
        & (node_view[None, :] != node_view[s][:, None])
    )
    out_d, in_d = d[s], d[:, s].T  # (C, N): from each source, and to it
    out_d = jnp.where(pair_ok & ~jnp.isnan(out_d), out_d, jnp.inf)
    in_d = jnp.where(pair_ok & ~jnp.isnan(in_d), in_d, jnp.inf)
    best_cost, best = min_and_first_index(
        (0.5 * (out_d + in_d)).reshape(C, M, P), axis=-1
    )  # (C, M): first of equals
    src = jnp.broadcast_to(s[:, None], (C, M)).reshape(-1)
    dst = (views[None, :] * P + best).reshape(-1)
    scored = score_hypotheses(
        rig, xy, free, blocks, src, dst, (best_cost < tau_px).reshape(-1), gate_px
    )
    pair = (views[None, :] == (src // P)[:, None]) | (
        views[None, :] == (dst // P)[:, None]
    )  # (C·M, M)
    missing, _ = missing_views(rig, xy, mask, scored.X, pair, support.radius_px)
    ok = scored.ok & (scored.count >= min_views) & support.plausible(missing, scored.count)
    return _Hypotheses(
        ok,
        jnp.where(ok, scored.err, jnp.inf),
        scored.count,
        src,
        dst,
        scored.xy_hat,
        scored.vote_views,
    )


def _all_hypotheses(
    rig, xy, mask, free, d, blocks, tau_px, gate_px, support, min_views
) -> _Hypotheses:
    """Every free detection's hypotheses (:func:`_hypotheses_of`), the free detections in
    node order, :data:`SOURCE_CHUNK` at a time; rows past the last free detection are not ok."""
    M, P = free.shape
    N = M * P
    d = d.reshape(N, N)

    def make(sources):
        return _hypotheses_of(
            rig, xy, mask, free, d, blocks, sources, tau_px, gate_px, support, min_views
        )

    if N <= SOURCE_CHUNK:
        return make(jnp.arange(N, dtype=jnp.int32))
    C = SOURCE_CHUNK
    width = -(-N // C) * C
    flat_free = free.reshape(N)
    num_free = jnp.sum(flat_free, dtype=jnp.int32)
    position = jnp.where(flat_free, jnp.cumsum(flat_free, dtype=jnp.int32) - 1, width)
    sources = (
        jnp.full((width,), N, jnp.int32)
        .at[position]
        .set(jnp.arange(N, dtype=jnp.int32), mode="drop")
    )

    def body(carry):
        start, table = carry
        chunk = make(jax.lax.dynamic_slice_in_dim(sources, start, C))
        table = jax.tree.map(
            lambda t, c: jax.lax.dynamic_update_slice_in_dim(t, c, start * M, 0), table, chunk
        )
        return start + C, table

    R = width * M
    empty = _Hypotheses(
        jnp.zeros((R,), bool),
        jnp.full((R,), jnp.inf, xy.dtype),
        jnp.zeros((R,), jnp.int32),
        jnp.zeros((R,), jnp.int32),
        jnp.zeros((R,), jnp.int32),
        jnp.zeros((R, M, 2), xy.dtype),
        jnp.zeros((R, M), bool),
    )
    _, table = jax.lax.while_loop(lambda c: c[0] < num_free, body, (jnp.int32(0), empty))
    return table


def seed_groups(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    free: Bool[Array, "M P"],
    d: Float[Array, "M P M P"],
    blocks: tuple,
    tau_px: Float[Array, ""],
    gate_px: Float[Array, ""],
    support: SeedSupport,
    min_views: int,
) -> Int[Array, "G M"]:
    """New groups ``(G, M)`` (slot per view or -1; unused rows all -1, ``G = M·P // 2``)
    made of the ``free (M, P)`` detections only; ``xy (M, P, 2)`` pixels, ``d`` the epipolar
    distances (px), ``blocks`` the per-node DLT blocks, ``tau_px`` the pair gate,
    ``gate_px`` the vote gate (px) and ``support`` the test of the views that see a
    hypothesis' point without a detection near."""
    M, P = free.shape
    N, G = M * P, max(M * P // 2, 1)
    slots = jnp.arange(P, dtype=jnp.int32)
    hyp = _all_hypotheses(rig, xy, mask, free, d, blocks, tau_px, gate_px, support, min_views)
    R = hyp.ok.shape[0]
    row_index = jnp.arange(R, dtype=jnp.int32)

    def cond(carry):
        _, _, num_groups, _, more = carry
        return more & (num_groups < G)

    def body(carry):
        used, groups, num_groups, tried, _ = carry
        # The next hypothesis in rank order (more votes, then a smaller error, then the
        # first row) among those not tried whose two detections are both still free.
        flat = used.reshape(N)
        alive = hyp.ok & ~tried & ~flat[hyp.src] & ~flat[hyp.dst]
        alive = alive & (hyp.count == jnp.max(jnp.where(alive, hyp.count, -1)))
        alive = alive & (hyp.err == jnp.min(jnp.where(alive, hyp.err, jnp.inf)))
        h = jnp.min(jnp.where(alive, row_index, R))
        found = h < R
        h = jnp.minimum(h, R - 1)
        row = accepted_row(
            xy, free, used, hyp.xy_hat[h], hyp.vote_views[h], hyp.src[h], hyp.dst[h], gate_px
        )
        # Voters taken by earlier groups may leave fewer than min_views members: skip it.
        accept = found & (jnp.sum(row >= 0, dtype=jnp.int32) >= min_views)
        groups = groups.at[num_groups].set(jnp.where(accept, row, groups[num_groups]), mode="drop")
        used = used | (accept & (slots[None, :] == row[:, None]))
        return used, groups, num_groups + accept.astype(jnp.int32), tried.at[h].set(True), found

    init = (
        ~free,
        jnp.full((G, M), -1, jnp.int32),
        jnp.int32(0),
        jnp.zeros((R,), bool),
        jnp.any(hyp.ok),
    )
    _, groups, _, _, _ = jax.lax.while_loop(cond, body, init)
    return groups


def seed_stage(scene: Scene, state: State, options: SeedOptions) -> State:
    """New groups seeded from two-view hypotheses on the leftover detections join the table."""
    table = state.table
    M, P = scene.mask.shape
    free = leftover_nodes(*table, scene.mask).reshape(M, P)
    new = seed_groups(
        scene.rig,
        scene.xy,
        scene.mask,
        free,
        scene.d,
        scene.blocks,
        scene.tau,
        scene.thresholds.seed_frac * scene.tau,
        SeedSupport(
            scene.thresholds.seed_support_frac * scene.tau,
            state.miss_rate,
            scene.thresholds.support_alpha,
        ),
        options.seed_min_views,
    )
    G = table.groups.shape[0]
    groups = jnp.concatenate([table.groups, new])
    valid = jnp.concatenate([table.valid, jnp.any(new >= 0, axis=1)])
    groups, valid, _ = compact_groups(jnp.where(valid[:, None], groups, -1), valid)
    return state._replace(table=GroupTable(groups[:G], valid[:G]), fit=None)


SEED = Stage(
    "seed",
    seed_stage,
    SeedOptions,
    Switch(
        "seed", False, "groups from two-view hypotheses on what is still left (beyond the paper)"
    ),
    thresholds=(
        Threshold(
            "seed_frac",
            1.5,
            Range(0.0, low_open=True),
            doc="seeding: a detection within seed_frac · τ votes for a two-view point",
        ),
        Threshold(
            "seed_support_frac",
            1.5,
            Range(0.0, low_open=True),
            doc="seeding: a view that sees a two-view point with no detection within seed_support_frac · τ counts against it (with the support filter, as in its test)",
        ),
    ),
)
