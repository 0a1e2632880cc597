"""Attaching leftover detections to groups, shared by the second association (§2.7) and
the recovery by reprojection: each node picks its cheapest group, and where nodes of one
view compete for a group the cheapest wins (ties: smallest node index)."""

import jax.numpy as jnp

from .._types import Array, Bool, Float, Int
from ..graph._adjacency import min_and_first_index


def attach_cheapest(
    groups: Int[Array, "G M"], cost: Float[Array, "G N"], gate: Float[Array, ""]
) -> Int[Array, "G M"]:
    """The group table ``(G, M)`` with every node ``u`` whose smallest ``cost[:, u]`` is
    below ``gate`` attached to that group (ties: lowest group id), one node per (group,
    view). ``cost`` must be ``+inf`` where a node may not join a group."""
    return attach_nearest(groups, *min_and_first_index(cost, axis=0), gate)


def attach_nearest(
    groups: Int[Array, "G M"],
    best_cost: Float[Array, " N"],
    best_group: Int[Array, " N"],
    gate: Float[Array, ""],
) -> Int[Array, "G M"]:
    """:func:`attach_cheapest` from each node's smallest cost ``best_cost (N,)`` and the
    first group attaining it ``best_group (N,)`` (as :func:`min_and_first_index` gives them
    along the groups)."""
    G, M = groups.shape
    N = best_cost.shape[0]
    P = N // M
    node = jnp.arange(N, dtype=jnp.int32)
    node_view = node // P
    target = jnp.where(best_cost < gate, best_group, G)  # G: attaches nowhere
    safe = jnp.minimum(target, G - 1)
    lowest = (
        jnp.full((G, M), jnp.inf, best_cost.dtype).at[target, node_view].min(best_cost, mode="drop")
    )
    is_best = (target < G) & (best_cost == lowest[safe, node_view])
    first = (
        jnp.full((G, M), N, jnp.int32)
        .at[jnp.where(is_best, target, G), node_view]
        .min(node, mode="drop")
    )
    winner = is_best & (first[safe, node_view] == node)
    return groups.at[jnp.where(winner, target, G), node_view].set(node % P, mode="drop")


def leftover_nodes(
    groups: Int[Array, "G M"], valid: Bool[Array, " G"], mask: Bool[Array, "M P"]
) -> Bool[Array, " N"]:
    """``(N,)``: detections (``mask (M, P)``) that are in no valid group of ``groups (G, M)``."""
    M, P = mask.shape
    member = valid[:, None] & (groups >= 0)
    views = jnp.arange(M, dtype=jnp.int32)[None, :]
    in_group = jnp.zeros((M, P + 1), bool).at[views, jnp.where(member, groups, P)].set(True)
    return (mask & ~in_group[:, :P]).reshape(-1)
