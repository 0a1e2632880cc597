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

At most ``reassign_iters`` rounds. A round reads nothing but the table (and the scene), so
a round that returns its table unchanged has reached a fixed point: every later round would
return it again, and the loop stops there with the same table (in a batch, once every scene
has stopped).
"""

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp

from .._types import Array, Bool, Float, Int
from ..cdog._config import Range, Switch, Threshold
from ..cdog._stage import GroupTable, Scene, Stage, State
from ..geometry._projection import distances_to_detections, project_views_last
from ..graph._adjacency import min_and_first_index
from ..graph._groups import compact_groups
from ._attach import attach_nearest
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


ROW_BLOCK = 64
"""Group rows the re-assignment measures at a time, when the table has more than twice as
many: only the rows that hold a group are measured (130 points on 10 views fill 130 of the
table's 960 rows)."""


def min_over_rows(
    cost_of_rows: Callable[[Int[Array, ""]], Float[Array, "B N"]],
    num_rows: int,
    filled: Int[Array, ""] | None,
) -> tuple[Float[Array, " N"], Int[Array, " N"]]:
    """``min_and_first_index(cost, axis=0)`` of a ``(num_rows, N)`` table whose rows from
    ``filled`` on are all ``+inf``, with ``cost_of_rows(start)`` the rows ``start …
    start + B − 1``. ``filled`` None: one call for the whole table (``start`` 0, ``B`` =
    ``num_rows``); else :data:`ROW_BLOCK` rows at a time, only up to ``filled`` (a last block
    that would pass the table's end starts earlier: rows seen twice change neither the
    smallest cost nor its first row)."""
    if filled is None:
        return min_and_first_index(cost_of_rows(jnp.int32(0)), axis=0)
    shape = jax.eval_shape(cost_of_rows, jnp.int32(0))
    assert shape.shape[0] == ROW_BLOCK <= num_rows

    def body(carry):
        low, first, start = carry
        at = jnp.minimum(start, num_rows - ROW_BLOCK)
        block_low, block_first = min_and_first_index(cost_of_rows(at), axis=0)
        # The earlier block keeps a tie; minimum keeps a NaN as jnp.min does.
        first = jnp.where(block_low < low, block_first + at, first)
        return jnp.minimum(low, block_low), first, start + ROW_BLOCK

    init = (
        jnp.full(shape.shape[1:], jnp.inf, shape.dtype),
        jnp.zeros(shape.shape[1:], jnp.int32),
        jnp.int32(0),
    )
    low, first, _ = jax.lax.while_loop(lambda c: c[2] < filled, body, init)
    return low, first


def _rows(a: Array, start: Int[Array, ""], filled: Int[Array, ""] | None) -> Array:
    """Rows ``start …`` of ``a``: :data:`ROW_BLOCK` of them, or all where ``filled`` is None."""
    if filled is None:
        return a
    return jax.lax.dynamic_slice_in_dim(a, start, ROW_BLOCK, axis=0)


def reassign_nearest(
    table: GroupTable,
    err_of_rows: Callable[[Int[Array, ""]], Float[Array, "B N"]],
    gate: Float[Array, ""],
    num_slots: int,
    filled: Int[Array, ""] | None = None,
) -> GroupTable:
    """Every detection attached to its nearest group within ``gate`` (``err_of_rows(start)``:
    the px distances ``(B, N)`` of group rows ``start …``, as :func:`min_over_rows` reads
    them), one per (group, view), losers retrying the open slots; groups of < 2 members
    dissolve."""
    G, M = table.groups.shape
    N = M * num_slots
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

        def open_cost(start, taken=taken, placed=placed):
            rows = _rows(taken, start, filled)
            open_slot = jnp.broadcast_to(~rows[:, :, None], (rows.shape[0], M, num_slots)).reshape(
                -1, N
            )  # taken[:, node_view]
            return jnp.where(open_slot & ~placed[None, :], err_of_rows(start), jnp.inf)

        groups = attach_nearest(groups, *min_over_rows(open_cost, G, filled), gate)
    valid = jnp.sum(groups >= 0, axis=1) >= 2
    return GroupTable(groups, valid).keep(valid)


def merge_split_groups(
    scene: Scene,
    table: GroupTable,
    X: Float[Array, "G 3"],
    gate: Float[Array, ""],
    filled: Int[Array, ""] | None = None,
) -> GroupTable:
    """Groups moved into a larger group with disjoint views whose point lies within
    ``gate`` px of all their members (``X (G, 3)`` the groups' points). ``filled``: every
    group lies in the rows before it (the rows measured as :func:`min_over_rows` says), or
    None."""
    G, M = table.groups.shape
    member = table.valid[:, None] & (table.groups >= 0)  # (G, M)
    size = jnp.sum(member, axis=1, dtype=jnp.int32)
    usable = _usable(table, X)
    index = jnp.arange(G, dtype=jnp.int32)
    member_xy = scene.xy[
        jnp.arange(M, dtype=jnp.int32)[None, :], jnp.where(member, table.groups, 0)
    ]  # (H, M, 2)

    def cost_of_rows(start):
        # The largest distance from the point of group k to a member of group h, a view at
        # a time: one (K, H) table, no gather and no (K, H, M) table (+inf where k's point is
        # not usable or behind the member's camera; -inf for a group without members).
        pix, in_front = project_views_last(scene.rig, _rows(X, start, filled))  # (K, M, 2)
        seen = _rows(usable, start, filled)[:, None] & in_front  # (K, M)
        member_k, size_k = _rows(member, start, filled), _rows(size, start, filled)
        worst_sq = jnp.full((pix.shape[0], G), -jnp.inf, X.dtype)
        for m in range(M):
            dx = pix[:, m, None, 0] - member_xy[None, :, m, 0]
            dy = pix[:, m, None, 1] - member_xy[None, :, m, 1]
            sq = jnp.where(
                member[None, :, m],
                jnp.where(seen[:, m, None], dx * dx + dy * dy, jnp.inf),
                -jnp.inf,
            )
            worst_sq = jnp.maximum(worst_sq, sq)
        worst = jnp.sqrt(
            jnp.maximum(worst_sq, 0.0)
        )  # (K, H) px: the root of the largest, the largest root
        index_k = _rows(index, start, filled)
        disjoint = ~jnp.any(member_k[:, None, :] & member[None, :, :], axis=-1)
        larger = (size_k[:, None] > size[None, :]) | (
            (size_k[:, None] == size[None, :]) & (index_k[:, None] < index[None, :])
        )
        allowed = disjoint & larger & (size[None, :] >= 2) & (size_k[:, None] >= 2)
        return jnp.where(allowed & (worst < gate), worst, jnp.inf)  # (K, H)

    nearest, target = min_over_rows(cost_of_rows, G, filled)  # (H,)
    moves = jnp.isfinite(nearest)
    # One group per target, the nearest (ties: the smallest h); a moving group takes none.
    best = (
        jnp.full((G,), jnp.inf, nearest.dtype)
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
    """Rounds of nearest-point re-assignment and merging of split groups, refitting between.

    A table of more than twice :data:`ROW_BLOCK` rows is first compacted (its groups to the
    front, in their order) and then measured only up to its last group: a round fills or merges
    only rows that held a group, and every tie goes to the earlier row in both orders, so
    the result is the same. The rounds stop early where one returns its table unchanged (a
    fixed point of :func:`reassign_round`)."""
    gate = scene.thresholds.reassign_frac * scene.tau
    table, filled = state.table, None
    if table.groups.shape[0] > 2 * ROW_BLOCK:
        groups, valid, _ = compact_groups(table.groups, table.valid)
        table, filled = GroupTable(groups, valid), jnp.sum(valid, dtype=jnp.int32)

    def body(carry):
        done, table, _ = carry
        new = reassign_round(scene, table, gate, filled)
        changed = jnp.any(new.groups != table.groups) | jnp.any(new.valid != table.valid)
        return done + 1, new, changed

    _, table, _ = jax.lax.while_loop(
        lambda carry: (carry[0] < options.reassign_iters) & carry[2],
        body,
        (jnp.int32(0), table, jnp.bool_(True)),
    )
    groups, valid, _ = compact_groups(table.groups, table.valid)
    return state._replace(table=GroupTable(groups, valid), fit=None)


def reassign_round(
    scene: Scene, table: GroupTable, gate: Float[Array, ""], filled: Int[Array, ""] | None = None
) -> GroupTable:
    """One round of :func:`reassign_stage`: the table fitted, every detection re-assigned to
    its nearest group point within ``gate`` px, the table fitted again and split groups
    merged. A function of the table alone (``filled`` as :func:`min_over_rows` reads it)."""
    P = scene.mask.shape[1]
    fit = fit_groups(scene, table)
    usable = _usable(table, fit.X)

    def err_of_rows(start):
        return _node_errors(scene, _rows(fit.X, start, filled), _rows(usable, start, filled))

    table = reassign_nearest(table, err_of_rows, gate, P, filled)
    return merge_split_groups(scene, table, fit_groups(scene, table).X, gate, filled)


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
