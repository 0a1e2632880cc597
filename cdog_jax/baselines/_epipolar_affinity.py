"""The pairwise epipolar affinity matrix that the matrix baselines (MatchEIG, matchSVT,
spectral clustering) start from.

Nodes are the ``N = M·P`` detection slots, node ``m·P + i`` for slot ``i`` of view ``m``
(the order of ``graph.groups_from_labels``). Two detections of different views are
compared by the larger of their two directed epipolar distances, ``c = max(d[m,i,n,j],
d[n,j,m,i])`` (pixels), and gated by the shared σ-matched gate ``τ`` (``c < τ``). Inside
the gate the affinity is a Gaussian of ``c`` with scale ``width·τ``; the methods' default
``width = 1`` makes it fall only to ``e^{−½} ≈ 0.61`` at the gate's edge, so the gate
decides and the distance only ranks. (``width = ½``, a scale of ``√2·σ``, the spread of
one directed distance of a true match, was tried first: every method lost 1–7 points of
pair recall at σ = 1 and 3 px, see docs/ALGORITHM.md.) Outside the gate, between slots of
one view, and for padding the affinity is 0.
"""

import jax.numpy as jnp

from .._types import Array, Bool, Float


def epipolar_affinity(
    d: Float[Array, "M P M P"],
    mask: Bool[Array, "M P"],
    tau: Float[Array, ""],
    width: Float[Array, ""],
) -> Float[Array, "N N"]:
    """``W (N, N)``, symmetric, entries in ``[0, 1]``, zero diagonal: the gated Gaussian
    affinity ``exp(−½ (c / (width·τ))²)`` for ``c < τ``, else 0 (module docstring).

    ``d (M, P, M, P)`` pixels (``+inf`` where undefined), ``mask (M, P)``, ``tau`` and
    ``width`` scalars. Padded slots may hold anything: they are masked before any arithmetic.
    """
    M, P = mask.shape
    pair_ok = mask[:, :, None, None] & mask[None, None, :, :]
    d = jnp.where(pair_ok, d, jnp.inf)
    cost = jnp.maximum(d, jnp.transpose(d, (2, 3, 0, 1)))
    inside = pair_ok & (cost < tau)  # False for inf and NaN
    scaled = jnp.where(inside, cost, 0.0) / jnp.maximum(width * tau, jnp.finfo(d.dtype).tiny)
    w = jnp.where(inside, jnp.exp(-0.5 * scaled * scaled), 0.0)
    return w.reshape(M * P, M * P)
