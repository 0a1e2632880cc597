"""Connected components by min-label propagation with pointer jumping (``lax.while_loop``).

Every node ends with the smallest node index of its component as its label. Each round
pulls the smallest label across every edge (both directions) and then follows labels
twice (``l ← l[l]``), which halves path lengths; the loop stops when nothing changes, at
most ``N`` rounds by default.

The default bound cannot be reached: every label is a node of its component no larger than
the node itself, so after ``k`` rounds a node's label is at most the smallest node within
``k`` edges (following labels only lowers it further). Labels are therefore final after
``diameter ≤ N − 1`` rounds and round ``N`` at the latest sees no change. A smaller bound
(``max_rounds``) can stop the loop early; :func:`connected_components_capped` says so.
"""

import jax
import jax.numpy as jnp

from .._types import Array, Bool, Int
from ._adjacency import EdgeTable


def connected_components_capped(
    edges: EdgeTable,
    alive: Bool[Array, " E"],
    num_nodes: int,
    *,
    max_rounds: int | None = None,
    per_node: int | None = None,
) -> tuple[Int[Array, " N"], Bool[Array, ""]]:
    """Labels ``(N,)`` as :func:`connected_components`, and ``()`` True when the loop stopped
    at ``max_rounds`` (default ``N``) while the last round still changed labels.

    ``per_node``: the edges are the pipeline's proposals, ``per_node`` of them from each node
    in order (``src = repeat(arange(N), per_node)``, as :func:`nearest_neighbour_edges`
    makes them); a round then reads and lowers the sources' labels in place of a gather and
    a scatter, the same labels at about half a round's cost."""
    big = jnp.int32(num_nodes)
    bound = num_nodes if max_rounds is None else max_rounds
    src, dst = edges.src, edges.dst

    def step(labels):
        if per_node is None:
            from_src = jnp.where(alive, labels[src], big)
        else:
            from_src = jnp.where(alive, jnp.repeat(labels, per_node), big)
        from_dst = jnp.where(alive, labels[dst], big)
        labels = labels.at[dst].min(from_src)
        if per_node is None:
            labels = labels.at[src].min(from_dst)
        else:  # a node's proposals are consecutive: the scatter to src is a row minimum
            labels = jnp.minimum(labels, jnp.min(from_dst.reshape(num_nodes, per_node), axis=1))
        labels = labels[labels]
        return labels[labels]

    def cond(carry):
        _, changed, it = carry
        return changed & (it < bound)

    def body(carry):
        labels, _, it = carry
        new = step(labels)
        return new, jnp.any(new != labels), it + 1

    labels0 = jnp.arange(num_nodes, dtype=jnp.int32)
    labels, changed, _ = jax.lax.while_loop(
        cond, body, (labels0, jnp.bool_(num_nodes > 0), jnp.int32(0))
    )
    return labels, changed


def connected_components(
    edges: EdgeTable, alive: Bool[Array, " E"], num_nodes: int, *, max_rounds: int | None = None
) -> Int[Array, " N"]:
    """Labels ``(N,)``: the smallest node index in each node's component of the graph formed
    by the alive proposals ``alive (E,)`` (undirected)."""
    return connected_components_capped(edges, alive, num_nodes, max_rounds=max_rounds)[0]


def component_view_counts(
    labels: Int[Array, " N"], node_view: Int[Array, " N"], valid: Bool[Array, " N"], num_views: int
) -> Int[Array, "N M"]:
    """``counts[c, m]``: how many valid nodes of view m carry label c."""
    N = labels.shape[0]
    return jnp.zeros((N, num_views), jnp.int32).at[labels, node_view].add(valid.astype(jnp.int32))
