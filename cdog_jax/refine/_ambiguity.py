"""Detaching ambiguous members (beyond the paper; ``Config.detach_ambiguous``).

In a dense scene at large σ two points can project a few pixels apart in a view: a group
then often holds the detection of its neighbour there, which fits its point as well as its
own (the reprojection error does not tell them apart). A member is *ambiguous* when
another detection of its view lies within ``ambiguous_frac · τ`` pixels as close to the
group's point as the member itself: ``e_other − e_member < ambiguous_frac · τ``, both
distances to the group's point projected into that view. Each group of three or more
members detaches its worst ambiguous member (the one farthest from the point) and is
refitted; a group of two keeps both (it would dissolve). One round: detaching is rare and
a second round would mostly cost correct members.
"""

import jax.numpy as jnp

from .._types import Array, Bool, Float, Int
from ..cdog._config import Range, Switch, Threshold
from ..cdog._stage import GroupTable, Scene, Stage, State
from ._fit import fit_groups
from ._reassign import _node_errors, _usable


def ambiguous_members(
    groups: Int[Array, "G M"],
    member: Bool[Array, "G M"],
    err: Float[Array, "G N"],
    margin_px: Float[Array, ""],
) -> Bool[Array, "G M"]:
    """``(G, M)``: members of ``groups (G, M)`` (slots, ``member`` the valid ones) with
    another detection of their view within ``margin_px`` as close to the group's point;
    ``err (G, N)`` the pixel distance of every node (``view · P + slot``) to every point
    (``+inf`` where unusable)."""
    G, M = groups.shape
    P = err.shape[1] // M
    per_view = err.reshape(G, M, P)
    own_slot = jnp.where(member, groups, 0)
    own = jnp.take_along_axis(per_view, own_slot[:, :, None], axis=2)[:, :, 0]  # (G, M)
    is_own = jnp.arange(P, dtype=jnp.int32)[None, None, :] == own_slot[:, :, None]
    other = jnp.min(jnp.where(is_own, jnp.inf, per_view), axis=2)  # (G, M)
    return member & jnp.isfinite(own) & (other - own < margin_px)


def detach_ambiguous(
    table: GroupTable,
    member: Bool[Array, "G M"],
    err: Float[Array, "G N"],
    margin_px: Float[Array, ""],
) -> GroupTable:
    """The table with each group of ≥ 3 members rid of its worst ambiguous member
    (:func:`ambiguous_members`; the one with the largest error)."""
    G, M = table.groups.shape
    P = err.shape[1] // M
    ambiguous = ambiguous_members(table.groups, member, err, margin_px)
    own = jnp.take_along_axis(
        err.reshape(G, M, P), jnp.where(member, table.groups, 0)[:, :, None], axis=2
    )[:, :, 0]
    worst = jnp.argmax(jnp.where(ambiguous, own, -jnp.inf), axis=1).astype(jnp.int32)  # (G,)
    large = jnp.sum(member, axis=1) >= 3
    drop = (large & jnp.any(ambiguous, axis=1))[:, None] & (
        jnp.arange(M, dtype=jnp.int32)[None, :] == worst[:, None]
    )
    return GroupTable(jnp.where(drop, -1, table.groups), table.valid)


def ambiguity_stage(scene: Scene, state: State, options: None) -> State:
    """Detach each group's worst ambiguous member and refit (needs a fit)."""
    fit = state.fit
    table = state.table
    err = _node_errors(scene, fit.X, _usable(table, fit.X))
    table = detach_ambiguous(
        table, fit.member & table.valid[:, None], err, scene.thresholds.ambiguous_frac * scene.tau
    )
    return state._replace(table=table, fit=fit_groups(scene, table))


AMBIGUITY = Stage(
    "detach_ambiguous",
    ambiguity_stage,
    None,
    Switch(
        "detach_ambiguous",
        False,
        "detach from each group of ≥ 3 its worst member that another detection fits as well (beyond the paper)",
    ),
    thresholds=(
        Threshold(
            "ambiguous_frac",
            0.1,
            Range(0.0),
            doc="a member is ambiguous when another detection of its view is within ambiguous_frac · τ as close to the point",
        ),
    ),
)
