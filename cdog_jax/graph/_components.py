"""Connected components by min-label propagation with pointer jumping (``lax.while_loop``).

Every node ends with the smallest node index of its component as its label. Each round
pulls the smallest label across every edge (both directions) and then follows labels
twice (``l ← l[l]``), which halves path lengths; the loop stops when nothing changes, at
most ``N`` rounds.
"""

import jax
import jax.numpy as jnp

from .._types import Array, Bool, Int
from ._adjacency import EdgeTable


def connected_components(edges: EdgeTable, alive: Bool[Array, " E"], num_nodes: int) -> Int[Array, " N"]:
    """Labels ``(N,)``: the smallest node index in each node's component of the graph formed
    by the alive proposals ``alive (E,)`` (undirected)."""
    big = jnp.int32(num_nodes)
    src, dst = edges.src, edges.dst

    def step(labels):
        from_src = jnp.where(alive, labels[src], big)
        from_dst = jnp.where(alive, labels[dst], big)
        labels = labels.at[dst].min(from_src).at[src].min(from_dst)
        labels = labels[labels]
        return labels[labels]

    def cond(carry):
        _, changed, it = carry
        return changed & (it < num_nodes)

    def body(carry):
        labels, _, it = carry
        new = step(labels)
        return new, jnp.any(new != labels), it + 1

    labels0 = jnp.arange(num_nodes, dtype=jnp.int32)
    labels, _, _ = jax.lax.while_loop(cond, body, (labels0, jnp.bool_(True), jnp.int32(0)))
    return labels


def component_view_counts(labels: Int[Array, " N"], node_view: Int[Array, " N"], valid: Bool[Array, " N"], num_views: int) -> Int[Array, "N M"]:
    """``counts[c, m]``: how many valid nodes of view m carry label c."""
    N = labels.shape[0]
    return jnp.zeros((N, num_views), jnp.int32).at[labels, node_view].add(valid.astype(jnp.int32))
