"""δ-overlap scores of the graph's edges and weak-edge pruning (paper Alg. 2, ALGORITHM.md §3).

``C = A + I``, ``O = C Cᵀ``, ``θ(u, v) = O[u, v] / max(deg u, deg v)`` with closed degrees.
Only edges need θ, so instead of the dense ``N³`` product we count, for every edge
proposal ``u → v``, the common open neighbours of u and v: ``O[u, v] = |N(u) ∩ N(v)| + 2``
on an edge (u and v each lie in both closed neighbourhoods). The rows of ``A`` are packed
into 32-bit words, so a count is ``⌈N/32⌉`` AND + popcount operations.
"""

import jax
import jax.numpy as jnp

from .._types import Array, Bool, Float, UInt
from ._adjacency import EdgeTable


def pack_rows(A: Bool[Array, "N N"]) -> UInt[Array, "N W"]:
    """Rows of a boolean matrix as ``W = ⌈N/32⌉`` uint32 bitsets."""
    N = A.shape[1]
    W = -(-N // 32)
    padded = jnp.zeros((A.shape[0], 32 * W), bool).at[:, :N].set(A)
    bits = padded.reshape(A.shape[0], W, 32).astype(jnp.uint32)
    shifts = jnp.arange(32, dtype=jnp.uint32)[None, None, :]
    return jnp.sum(bits << shifts, axis=-1, dtype=jnp.uint32)


def edge_overlap(
    edges: EdgeTable, A: Bool[Array, "N N"], *, dtype=jnp.float32
) -> Float[Array, " E"]:
    """``θ (E,)`` of every proposal's edge (defined where the proposal is an edge of the
    ``(N, N)`` graph ``A``), in (0, 1], as ``dtype``."""
    rows = pack_rows(A)  # (N, W)
    both = rows[edges.src] & rows[edges.dst]  # (E, W)
    common = jnp.sum(jax.lax.population_count(both), axis=-1, dtype=jnp.int32)
    deg_closed = jnp.sum(A, axis=1, dtype=jnp.int32) + 1  # (N,)
    overlap = (common + 2).astype(dtype)
    return overlap / jnp.maximum(deg_closed[edges.src], deg_closed[edges.dst]).astype(dtype)


def remove_edges(
    A: Bool[Array, "N N"], edges: EdgeTable, remove: Bool[Array, " E"]
) -> Bool[Array, "N N"]:
    """``A (N, N)`` without the (undirected) edges of the flagged proposals ``remove (E,)``."""
    keep = ~remove
    A = A.at[edges.src, edges.dst].min(keep)
    return A.at[edges.dst, edges.src].min(keep)
