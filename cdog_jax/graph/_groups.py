"""The ``(G, M)`` group table from component labels (ALGORITHM.md §5)."""

import jax.numpy as jnp

from .._types import Array, Bool, Int


def groups_from_labels(
    labels: Int[Array, " N"], valid: Bool[Array, " N"], num_views: int, num_slots: int
) -> tuple[Int[Array, "G M"], Bool[Array, " G"]]:
    """From ``labels (N,)`` and ``valid (N,)``: components with ≥ 2 valid nodes become groups, numbered by label (smallest node index)
    ascending. Returns ``groups[g, m]`` (slot in view m or -1) and ``valid[g]``; the capacity
    ``G = N // 2`` always suffices. Assumes view-unique components."""
    N = labels.shape[0]
    G = max(N // 2, 1)
    size = jnp.zeros((N,), jnp.int32).at[labels].add(valid.astype(jnp.int32))
    is_root = (jnp.arange(N, dtype=jnp.int32) == labels) & (size >= 2)
    group_of_root = jnp.cumsum(is_root, dtype=jnp.int32) - 1
    node_group = jnp.where(valid & is_root[labels], group_of_root[labels], G)  # G = dropped
    node = jnp.arange(N, dtype=jnp.int32)
    groups = (
        jnp.full((G, num_views), -1, jnp.int32)
        .at[node_group, node // num_slots]
        .set((node % num_slots).astype(jnp.int32), mode="drop")
    )
    group_valid = jnp.arange(G, dtype=jnp.int32) < jnp.sum(is_root, dtype=jnp.int32)
    return groups, group_valid


def labels_from_groups(
    groups: Int[Array, "G M"], valid: Bool[Array, " G"], num_slots: int
) -> Int[Array, "M P"]:
    """``labels (M, P)`` from ``groups (G, M)``: the group holding slot i of view m, or -1."""
    G, M = groups.shape
    member = valid[:, None] & (groups >= 0)
    gid = jnp.broadcast_to(jnp.arange(G, dtype=jnp.int32)[:, None], (G, M))
    view = jnp.broadcast_to(jnp.arange(M, dtype=jnp.int32)[None, :], (G, M))
    slot = jnp.where(member, groups, num_slots)
    return jnp.full((M, num_slots), -1, jnp.int32).at[view, slot].set(gid, mode="drop")


def compact_groups(
    groups: Int[Array, "G M"], valid: Bool[Array, " G"]
) -> tuple[Int[Array, "G M"], Bool[Array, " G"], Int[Array, " G"]]:
    """Move valid groups to the front, keeping their order; returns the permutation too
    (``order[k]`` = old index of new group k): a stable sort of the rows on ``~valid``, made
    of two running counts and one scatter (a sort is tens of kernels on a CPU, and a batch of
    small scenes compacts its tables a dozen times a call)."""
    G = valid.shape[0]
    is_valid = valid.astype(jnp.int32)
    num_valid = jnp.sum(is_valid, dtype=jnp.int32)
    new_row = jnp.where(
        valid,
        jnp.cumsum(is_valid, dtype=jnp.int32) - 1,
        num_valid + jnp.cumsum(1 - is_valid, dtype=jnp.int32) - 1,
    )
    order = jnp.zeros((G,), jnp.int32).at[new_row].set(jnp.arange(G, dtype=jnp.int32))
    return groups[order], valid[order], order


def gather_groups(groups: Int[Array, "G M"], per_node: Array) -> Array:
    """``per_node (M, P, ...)`` gathered to ``(G, M, ...)`` at the group slots (slot 0 where
    the group has no member; callers mask)."""
    M = groups.shape[1]
    return per_node[jnp.arange(M, dtype=jnp.int32)[None, :], jnp.maximum(groups, 0)]
