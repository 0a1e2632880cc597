"""Merging groups along edges taken in a fixed order, under view-uniqueness.

A union-find over the ``N = M · P`` detections in which every node holds its group's root,
the group's smallest node (a "quick-find": a merge relabels one group in ``O(N)``, a find is
one lookup, and the labels are those :func:`~cdog_jax.graph.groups_from_labels` expects),
and every root holds the views its group covers.
"""

import jax
import jax.numpy as jnp

from .._types import Array, Bool, Int


def merge_in_order(
    lo: Int[Array, " E"],
    hi: Int[Array, " E"],
    num_edges: Int[Array, ""],
    mask: Bool[Array, "M P"],
    *,
    freeze_on_conflict: bool,
) -> Int[Array, " N"]:
    """Labels ``(N,)`` (smallest node of each group) after visiting the edges
    ``lo[e] — hi[e]`` (nodes ``m * P + i``) for ``e < num_edges``, in that order.

    An edge between two groups merges them when the union holds at most one detection per
    view. Otherwise it is skipped; with ``freeze_on_conflict`` both groups are then frozen:
    neither merges again, and an edge touching a frozen group freezes the other end's group
    too. One step per edge, so the loop bound is the edge count.
    """
    M, P = mask.shape
    N = M * P
    node_view = jnp.arange(N, dtype=jnp.int32) // P
    views_of = (node_view[:, None] == jnp.arange(M, dtype=jnp.int32)[None, :]) & mask.reshape(
        N, 1
    )  # (N, M)

    def body(e, carry):
        labels, views_of, frozen = carry
        a, b = labels[lo[e]], labels[hi[e]]
        distinct = a != b
        fits = ~jnp.any(views_of[a] & views_of[b])
        merge = distinct & fits & ~frozen[a] & ~frozen[b]
        root, other = jnp.minimum(a, b), jnp.maximum(a, b)
        labels = jnp.where(merge & (labels == other), root, labels)
        views_of = views_of.at[root].set(
            jnp.where(merge, views_of[a] | views_of[b], views_of[root])
        )
        if freeze_on_conflict:
            freeze = distinct & ~merge
            frozen = frozen.at[a].set(frozen[a] | freeze).at[b].set(frozen[b] | freeze)
        return labels, views_of, frozen

    init = (jnp.arange(N, dtype=jnp.int32), views_of, jnp.zeros((N,), bool))
    labels, _, _ = jax.lax.fori_loop(0, num_edges, body, init)
    return labels
