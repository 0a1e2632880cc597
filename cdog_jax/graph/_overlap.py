"""δ-overlap scores of the graph's edges and weak-edge pruning (paper Alg. 2, ALGORITHM.md §3).

``C = A + I``, ``O = C Cᵀ``, ``θ(u, v) = O[u, v] / max(deg u, deg v)`` with closed degrees.
Only edges need θ, so instead of the dense ``N³`` product we count, for every edge
proposal ``u → v``, the common open neighbours of u and v from two rows of ``A``:
``O[u, v] = |N(u) ∩ N(v)| + 2`` on an edge (u and v each lie in both closed
neighbourhoods).
"""

import jax.numpy as jnp

from .._types import Array, Bool, Float
from ._adjacency import EdgeTable


def edge_overlap(edges: EdgeTable, A: Bool[Array, "N N"], *, dtype=jnp.float32) -> Float[Array, " E"]:
    """``θ (E,)`` of every proposal's edge (defined where the proposal is an edge of the
    ``(N, N)`` graph ``A``), in (0, 1], as ``dtype``."""
    A_f = A.astype(jnp.float32)
    common = jnp.einsum("ew,ew->e", A_f[edges.src], A_f[edges.dst])  # (E,) exact integers
    deg_closed = jnp.sum(A_f, axis=1) + 1.0  # (N,)
    overlap = common + 2.0
    theta = overlap.astype(dtype) / jnp.maximum(deg_closed[edges.src], deg_closed[edges.dst]).astype(dtype)
    return theta


def remove_edges(A: Bool[Array, "N N"], edges: EdgeTable, remove: Bool[Array, " E"]) -> Bool[Array, "N N"]:
    """``A (N, N)`` without the (undirected) edges of the flagged proposals ``remove (E,)``."""
    keep = ~remove
    A = A.at[edges.src, edges.dst].min(keep)
    return A.at[edges.dst, edges.src].min(keep)
