"""View-uniqueness: split components that hold two nodes of one view (ALGORITHM.md §4).

A group may hold at most one detection per view. While a component conflicts, its single
weakest edge (lowest θ, then largest epipolar distance, then smallest node pair) is
removed; after ``max_iters`` rounds, the last resort keeps in each over-full view the node
with the smallest mean edge distance and detaches the others, and the returned status says
so (``Status.SPLIT_CAPPED``).
"""

import jax
import jax.numpy as jnp

from .._status import Status
from .._types import Array, Bool, Float, Int
from ._adjacency import EdgeTable, alive_edges, undirected_ids
from ._components import component_view_counts, connected_components_capped
from ._overlap import remove_edges


def _conflicting(labels, node_view, valid, num_views):
    counts = component_view_counts(labels, node_view, valid, num_views)  # (N, M)
    return jnp.any(counts >= 2, axis=1), counts  # per label


def _segment_argbest(key, active, seg, num_segments, minimise=True):
    """Per segment, the best key among active entries, broadcast back to the entries."""
    if jnp.issubdtype(key.dtype, jnp.integer):
        info = jnp.iinfo(key.dtype)
        fill = info.max if minimise else info.min
    else:
        fill = jnp.inf if minimise else -jnp.inf
    k = jnp.where(active, key, fill)
    init = jnp.full((num_segments,), fill, key.dtype)
    best = init.at[seg].min(k) if minimise else init.at[seg].max(k)
    return active & (k == best[seg])


def _remove(alive, remove, pair):
    """``alive (E,)`` without the undirected edges of the flagged proposals ``remove (E,)``
    (every proposal joining the same two nodes, ``pair`` from :func:`undirected_ids`)."""
    removed = jnp.zeros(alive.shape, bool).at[pair].max(remove, mode="drop")
    return alive & ~removed.at[pair].get(mode="fill", fill_value=False)


def split_conflicts(
    A: Bool[Array, "N N"],
    edges: EdgeTable,
    theta: Float[Array, " E"],
    edge_dist: Float[Array, " E"],
    node_view: Int[Array, " N"],
    valid: Bool[Array, " N"],
    num_views: int,
    max_iters: int,
    per_node: int | None = None,
) -> tuple[Bool[Array, "N N"], Int[Array, " N"], Int[Array, ""]]:
    """Remove edges until every component is view-unique.

    ``A (N, N)``; per proposal ``theta (E,)`` and ``edge_dist (E,)`` (pixels); per node
    ``node_view (N,)`` and ``valid (N,)``. Returns the graph ``(N, N)``, its labels ``(N,)``
    and an int32 :class:`~cdog_jax.Status` ``()``: ``SPLIT_CAPPED`` when conflicts were left
    after ``max_iters`` rounds (the last resort decided them), ``COMPONENTS_CAPPED`` when a
    components pass stopped at its bound.

    Every edge of ``A`` that the splitting works on is a proposal, so the loop carries the
    proposals' ``(E,)`` liveness rather than the ``(N, N)`` matrix (E = N·M ≪ N²).
    ``per_node``: each node's proposals are consecutive, ``per_node`` of them (the pipeline's
    edge table; see :func:`connected_components_capped`); None for any edge list.
    """
    N = A.shape[0]
    pair_lo = jnp.minimum(edges.src, edges.dst)
    pair_hi = jnp.maximum(edges.src, edges.dst)
    # The node pair (lo, hi) in one int32 key, lo · N + hi, ordered as the pair is: one
    # segment minimum instead of two, where N² fits.
    one_key = N * N < 2**31
    if one_key:
        node_pair = pair_lo * N + pair_hi
    pair = undirected_ids(edges, N)

    def components(alive):
        return connected_components_capped(edges, alive, N, per_node=per_node)

    # The loop carries each label's conflict, found after its last removal: the next round
    # starts from it.
    def cond(carry):
        _, _, conflict, _, it = carry
        return jnp.any(conflict) & (it < max_iters)

    def body(carry):
        alive, labels, conflict, comp_capped, it = carry
        seg = labels[edges.src] if per_node is None else jnp.repeat(labels, per_node)
        cand = alive & conflict[seg]
        # Lexicographic (θ ↑, distance ↓, pair ↑) best per component; both proposals of
        # one undirected edge tie on every key and are removed together.
        cand = _segment_argbest(theta, cand, seg, N)
        cand = _segment_argbest(edge_dist, cand, seg, N, minimise=False)
        if one_key:
            cand = _segment_argbest(node_pair, cand, seg, N)
        else:
            cand = _segment_argbest(pair_lo, cand, seg, N)
            cand = _segment_argbest(pair_hi, cand, seg, N)
        alive = _remove(alive, cand, pair)
        labels, capped = components(alive)
        conflict, _ = _conflicting(labels, node_view, valid, num_views)
        return alive, labels, conflict, comp_capped | capped, it + 1

    alive = alive_edges(edges, A)
    labels, comp_capped = components(alive)
    conflict, _ = _conflicting(labels, node_view, valid, num_views)
    carry = (alive, labels, conflict, comp_capped, jnp.int32(0))
    alive, labels, conflict, comp_capped, _ = jax.lax.while_loop(cond, body, carry)
    any_conflict = jnp.any(conflict)
    alive, labels, last_capped = jax.lax.cond(
        any_conflict,
        lambda: _detach_last_resort(
            alive, labels, edges, edge_dist, pair, node_view, valid, num_views, per_node
        ),
        lambda: (alive, labels, jnp.bool_(False)),
    )
    # The graph: A without every proposal-edge that was removed (edges of A that are not
    # proposals cannot exist: A is built from them).
    removed = edges.ok & A[edges.src, edges.dst] & ~alive
    A = remove_edges(A, edges, removed)
    status = jnp.where(any_conflict, jnp.int32(int(Status.SPLIT_CAPPED)), jnp.int32(0))
    return (
        A,
        labels,
        status
        | jnp.where(
            comp_capped | last_capped, jnp.int32(int(Status.COMPONENTS_CAPPED)), jnp.int32(0)
        ),
    )


def _detach_last_resort(
    alive, labels, edges, edge_dist, pair, node_view, valid, num_views, per_node
):
    """In each conflicting component, keep per over-full view the node of smallest mean edge
    distance (ties: smallest index) and remove every edge of the others; returns the
    proposals' liveness, the labels and whether the components pass stopped at its bound."""
    N = labels.shape[0]
    conflict, counts = _conflicting(labels, node_view, valid, num_views)
    # Each undirected edge counts once at each end, through its first proposal, with the
    # largest distance among its proposals.
    counted = alive & (pair == jnp.arange(pair.shape[0], dtype=jnp.int32))
    other_end = counted & (edges.src != edges.dst)
    dist = edge_dist.dtype
    pair_dist = (
        jnp.zeros(edge_dist.shape, dist).at[pair].max(jnp.where(alive, edge_dist, 0.0), mode="drop")
    )
    pair_dist = pair_dist.at[pair].get(mode="fill", fill_value=0.0)
    total = (
        jnp.zeros((N,), dist)
        .at[edges.src]
        .add(jnp.where(counted, pair_dist, 0.0))
        .at[edges.dst]
        .add(jnp.where(other_end, pair_dist, 0.0))
    )
    deg = (
        jnp.zeros((N,), dist)
        .at[edges.src]
        .add(counted.astype(dist))
        .at[edges.dst]
        .add(other_end.astype(dist))
    )
    mean_dist = total / jnp.maximum(deg, 1.0)
    over_full = conflict[labels] & (counts[labels, node_view] >= 2) & valid  # (N,)
    # Winner per (label, view): smallest mean distance, then smallest node index.
    key = jnp.where(over_full, mean_dist, jnp.inf)
    best = jnp.full((N, num_views), jnp.inf, key.dtype).at[labels, node_view].min(key)
    tied = over_full & (key == best[labels, node_view])
    idx = jnp.where(tied, jnp.arange(N, dtype=jnp.int32), N)
    first = jnp.full((N, num_views), N, jnp.int32).at[labels, node_view].min(idx.astype(jnp.int32))
    detach = over_full & (first[labels, node_view] != jnp.arange(N, dtype=jnp.int32))
    alive = alive & ~detach[edges.src] & ~detach[edges.dst]
    return (alive, *connected_components_capped(edges, alive, N, per_node=per_node))
