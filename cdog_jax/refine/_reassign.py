"""Re-assignment of every detection to the nearest group point (beyond the paper;
``Config.reassign``).

The groups the graph stages, recovery and seeding build are fitted one by one; at large σ
some hold a detection of a neighbouring point, and some points are split over two groups
whose views do not overlap. Each of ``reassign_iters`` rounds, with the gate
``g = reassign_frac · τ`` (px):

1. **Re-assignment** (maximum likelihood under Gaussian pixel noise): every detection is
   offered to every usable group (≥ 2 members, a well-conditioned point in front of the
   detection's camera), at the distance between the detection and the group's point
   projected into its view. Every detection goes to its nearest group within ``g``; where
   detections of one view compete for a group the nearest wins (ties: smallest node
   index), and the losers try again among the (group, view) slots still open, up to
   ``REASSIGN_ROUNDS`` times. Detections that win nothing are detached; groups left with
   fewer than 2 members dissolve.
2. **Merging**: the groups are refitted; a group ``h`` whose views are disjoint from those
   of a group ``k`` at least as large (ties: ``k`` the smaller index), with every member of
   ``h`` within ``g`` of ``k``'s point, moves into the ``k`` whose largest such distance is
   smallest. Each ``k`` takes at most one group per round (the nearest), and a group that
   moves takes none.

The rounds are a ``fori_loop`` of fixed length: there is no bound to reach.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from .._types import Array, Bool, Float
from ..cdog._config import Range, Switch, Threshold
from ..cdog._stage import GroupTable, Scene, Stage, State
from ..geometry._projection import distances_to_detections, project_views_last
from ..graph._adjacency import min_and_first_index
from ..graph._groups import compact_groups
from ._attach import attach_cheapest
from ._fit import fit_groups

REASSIGN_ROUNDS = 3
"""Times the detections that lost a (group, view) slot try the slots still open."""


class ReassignOptions(NamedTuple):
    """``reassign_iters``: rounds of re-assignment, refitting and merging."""

    reassign_iters: int = 3


def _node_errors(
    scene: Scene, X: Float[Array, "G 3"], usable: Bool[Array, " G"]
) -> Float[Array, "G N"]:
    """Pixel distance between every detection and every usable group's point projected into
    the detection's view; ``+inf`` where the group is not usable, the point is behind that
    camera or the slot is padding."""
    G, (M, P) = X.shape[0], scene.mask.shape
    err, in_front = distances_to_detections(
        scene.rig, X, scene.xy
    )  # (G, M, P): node view · P + slot
    allowed = usable[:, None, None] & in_front[:, :, None] & scene.mask[None]
    return jnp.where(allowed, err, jnp.inf).reshape(G, M * P)


def _usable(table: GroupTable, X: Float[Array, "G 3"]) -> Bool[Array, " G"]:
    # fit_groups writes X = 0 exactly where the normal equations are near singular.
    enough = jnp.sum(table.valid[:, None] & (table.groups >= 0), axis=1) >= 2
    return table.valid & enough & jnp.any(X != 0.0, axis=1)


def reassign_nearest(
    table: GroupTable, err: Float[Array, "G N"], gate: Float[Array, ""], num_slots: int
) -> GroupTable:
    """Every detection attached to its nearest group within ``gate`` (``err (G, N)`` px),
    one per (group, view), losers retrying the open slots; groups of < 2 members dissolve."""
    G, M = table.groups.shape
    N = err.shape[1]
    groups = jnp.full((G, M), -1, jnp.int32)
    for _ in range(REASSIGN_ROUNDS):
        taken = groups >= 0  # (G, M)
        views = jnp.arange(M, dtype=jnp.int32)[None, :]
        placed = (
            jnp.zeros((M, num_slots + 1), bool)
            .at[views, jnp.where(taken, groups, num_slots)]
            .set(True)
        )
        placed = placed[:, :num_slots].reshape(N)
        open_slot = jnp.broadcast_to(~taken[:, :, None], (G, M, num_slots)).reshape(
            G, N
        )  # taken[:, node_view]
        open_cost = jnp.where(open_slot & ~placed[None, :], err, jnp.inf)
        groups = attach_cheapest(groups, open_cost, gate)
    valid = jnp.sum(groups >= 0, axis=1) >= 2
    return GroupTable(groups, valid).keep(valid)


def merge_split_groups(
    scene: Scene, table: GroupTable, X: Float[Array, "G 3"], gate: Float[Array, ""]
) -> GroupTable:
    """Groups moved into a larger group with disjoint views whose point lies within
    ``gate`` px of all their members (``X (G, 3)`` the groups' points)."""
    G, M = table.groups.shape
    member = table.valid[:, None] & (table.groups >= 0)  # (G, M)
    size = jnp.sum(member, axis=1, dtype=jnp.int32)
    # The largest distance from the point of group k to a member of group h, a view at a
    # time: one (K, H) table, no gather and no (K, H, M) table (+inf where k's point is not
    # usable or behind the member's camera; -inf for a group without members).
    pix, in_front = project_views_last(scene.rig, X)  # (K, M, 2)
    seen = _usable(table, X)[:, None] & in_front  # (K, M)
    member_xy = scene.xy[
        jnp.arange(M, dtype=jnp.int32)[None, :], jnp.where(member, table.groups, 0)
    ]  # (H, M, 2)
    worst_sq = jnp.full((G, G), -jnp.inf, X.dtype)
    for m in range(M):
        dx = pix[:, m, None, 0] - member_xy[None, :, m, 0]
        dy = pix[:, m, None, 1] - member_xy[None, :, m, 1]
        sq = jnp.where(
            member[None, :, m], jnp.where(seen[:, m, None], dx * dx + dy * dy, jnp.inf), -jnp.inf
        )
        worst_sq = jnp.maximum(worst_sq, sq)
    worst = jnp.sqrt(
        jnp.maximum(worst_sq, 0.0)
    )  # (K, H) px: the root of the largest, the largest root
    index = jnp.arange(G, dtype=jnp.int32)
    disjoint = ~jnp.any(member[:, None, :] & member[None, :, :], axis=-1)
    larger = (size[:, None] > size[None, :]) | (
        (size[:, None] == size[None, :]) & (index[:, None] < index[None, :])
    )
    allowed = disjoint & larger & (size[None, :] >= 2) & (size[:, None] >= 2) & (worst < gate)
    cost = jnp.where(allowed, worst, jnp.inf)  # (K, H)
    nearest, target = min_and_first_index(cost, axis=0)  # (H,)
    moves = jnp.isfinite(nearest)
    # One group per target, the nearest (ties: the smallest h); a moving group takes none.
    best = (
        jnp.full((G,), jnp.inf, cost.dtype)
        .at[jnp.where(moves, target, G)]
        .min(nearest, mode="drop")
    )
    win = moves & (nearest == best[target])
    first = jnp.full((G,), G, jnp.int32).at[jnp.where(win, target, G)].min(index, mode="drop")
    win = win & (first[target] == index) & ~moves[target]
    incoming = (
        jnp.full((G,), G, jnp.int32).at[jnp.where(win, target, G)].set(index, mode="drop")
    )  # (K,)
    has_incoming = incoming < G
    added = table.groups[jnp.minimum(incoming, G - 1)]  # (K, M)
    groups = jnp.where(has_incoming[:, None] & (added >= 0), added, table.groups)
    valid = table.valid & ~win
    return GroupTable(groups, valid).keep(valid)


def reassign_stage(scene: Scene, state: State, options: ReassignOptions) -> State:
    """Rounds of nearest-point re-assignment and merging of split groups, refitting between."""
    P = scene.mask.shape[1]
    gate = scene.thresholds.reassign_frac * scene.tau

    def one_round(_, table):
        fit = fit_groups(scene, table)
        table = reassign_nearest(table, _node_errors(scene, fit.X, _usable(table, fit.X)), gate, P)
        return merge_split_groups(scene, table, fit_groups(scene, table).X, gate)

    table = jax.lax.fori_loop(0, options.reassign_iters, one_round, state.table)
    groups, valid, _ = compact_groups(table.groups, table.valid)
    return state._replace(table=GroupTable(groups, valid), fit=None)


REASSIGN = Stage(
    "reassign",
    reassign_stage,
    ReassignOptions,
    Switch(
        "reassign", False, "each detection to its nearest group point, refitting (beyond the paper)"
    ),
    thresholds=(
        Threshold(
            "reassign_frac",
            2.0,
            Range(0.0, low_open=True),
            doc="re-assignment: a detection joins its nearest point within reassign_frac · τ",
        ),
    ),
)
