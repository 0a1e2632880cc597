"""Association graph initialisation (paper Alg. 1, ALGORITHM.md §2).

Every valid node ``u = m * P + i`` proposes at most one edge into each other view: to its
epipolar nearest neighbour there, if closer than τ. The undirected graph keeps an edge when
both ends propose it (``mutual``) or when either does (``union``). Every edge of either
graph is therefore one of these ``N × M`` proposals, which is the edge table the later
stages work on.
"""

from typing import NamedTuple

import jax.numpy as jnp

from .._types import Array, Bool, Float, Int
from ..cdog._config import Adjacency


class EdgeTable(NamedTuple):
    """The ``E = N * M`` proposals ``src → dst`` (entry ``u * M + n`` is u's proposal into
    view n). ``ok`` is False where u proposed nothing (then ``dst == src``)."""

    src: Int[Array, " E"]
    dst: Int[Array, " E"]
    ok: Bool[Array, " E"]


def min_and_first_index(
    x: Float[Array, "..."], axis: int
) -> tuple[Float[Array, "..."], Int[Array, "..."]]:
    """The smallest entry of ``x`` along ``axis`` and the first index attaining it, as
    ``jnp.min`` and ``jnp.argmin`` give them (a row of +inf gives index 0), from two plain
    reductions, which XLA vectorises: argmin's variadic reduce is several times slower on a
    CPU. (Where a row holds NaN, the index is the last one; argmin's would be the NaN's.)"""
    axis = axis % x.ndim
    n = x.shape[axis]
    low = jnp.min(x, axis=axis)
    index = jnp.arange(n, dtype=jnp.int32).reshape([n if a == axis else 1 for a in range(x.ndim)])
    first = jnp.min(jnp.where(x == jnp.expand_dims(low, axis), index, n), axis=axis)
    return low, jnp.minimum(first, n - 1)


def nearest_neighbour_edges(d: Float[Array, "M P M P"], tau_px: Float[Array, ""]) -> EdgeTable:
    """For every node and other view, the edge to the nearest valid point if ``d < τ``;
    ``d (M, P, M, P)`` is the epipolar distance table, the result has ``E = M·P·M`` entries.

    Ties go to the smallest slot; padded nodes and views propose nothing (``d = +inf``).
    """
    M, P = d.shape[:2]
    d_star, j_star = min_and_first_index(d, axis=-1)  # (M, P, M)
    ok = (d_star < tau_px).reshape(-1)  # (E,)
    src = jnp.repeat(jnp.arange(M * P, dtype=jnp.int32), M)
    dst = (jnp.arange(M, dtype=jnp.int32)[None, None, :] * P + j_star).reshape(-1)
    return EdgeTable(src=src, dst=jnp.where(ok, dst, src), ok=ok)


def _first_proposals(edges: EdgeTable, num_nodes: int) -> Int[Array, "N N"]:
    """``(N, N)``: the smallest index of an ``ok`` proposal ``u → v`` at ``[u, v]``, ``E``
    where there is none. Read at ``(v, u)`` by a gather, it answers what a transpose would,
    and a transpose of an ``(N, N)`` matrix is slow on a CPU (see :func:`adjacency_from_edges`)."""
    E, N = edges.src.shape[0], num_nodes
    return (
        jnp.full((N, N), E, jnp.int32)
        .at[jnp.where(edges.ok, edges.src, N), edges.dst]
        .min(jnp.arange(E, dtype=jnp.int32), mode="drop")
    )


def undirected_ids(edges: EdgeTable, num_nodes: int) -> Int[Array, " E"]:
    """``(E,)``: for every proposal that is an edge (``ok``), the smallest index of an ``ok``
    proposal joining the same two nodes in either direction (one id per undirected edge);
    ``E`` for the others."""
    E = edges.src.shape[0]
    first = _first_proposals(edges, num_nodes)
    pair = jnp.minimum(first[edges.src, edges.dst], first[edges.dst, edges.src])
    return jnp.where(edges.ok, pair, E)


def adjacency_from_edges(edges: EdgeTable, num_nodes: int, mode: Adjacency) -> Bool[Array, "N N"]:
    """Symmetric adjacency ``A (N, N)`` from the proposals: ``D ∧ Dᵀ`` (mutual) or ``D ∨ Dᵀ``
    (union), where ``D[u, v]`` says that u proposed v.

    One scatter of the kept proposals in both directions, without transposing an
    ``(N, N)`` matrix: XLA's CPU transpose of a boolean matrix a scatter just wrote took
    3.4 ms at N = 900, more than ten times this whole function.
    """
    N = num_nodes
    if mode == "mutual":
        # u → v is mutual when v proposed u too (u → u: itself).
        first = _first_proposals(edges, N)
        keep = edges.ok & (first[edges.dst, edges.src] < edges.src.shape[0])
    elif mode == "union":
        keep = edges.ok
    else:
        raise ValueError(f"unknown adjacency mode {mode!r}")
    # Rows out of range (N) are dropped: only kept edges are written, each as True.
    rows = jnp.concatenate([jnp.where(keep, edges.src, N), jnp.where(keep, edges.dst, N)])
    cols = jnp.concatenate([edges.dst, edges.src])
    return jnp.zeros((N, N), dtype=bool).at[rows, cols].set(True, mode="drop")


def alive_edges(edges: EdgeTable, A: Bool[Array, "N N"]) -> Bool[Array, " E"]:
    """``(E,)``: which proposals are edges of the (possibly pruned) graph ``A (N, N)``."""
    return edges.ok & A[edges.src, edges.dst]
