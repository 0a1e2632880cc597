"""Gated epipolar candidate pairs shared by the pairwise baselines.

The symmetric epipolar cost of detections ``(m, i)`` and ``(n, j)`` is
``c = ½ (d[m, i, n, j] + d[n, j, m, i])`` (pixels): the mean of the two point-to-line
distances, so that the cost of a pair does not depend on which end proposes it.
"""

import jax
import jax.numpy as jnp

from .._types import Array, Bool, Float, Int


def symmetric_cost(d: Float[Array, "M P M P"], mask: Bool[Array, "M P"]) -> Float[Array, "M P M P"]:
    """``c[m, i, n, j] = ½ (d[m, i, n, j] + d[n, j, m, i])`` (pixels), ``+inf`` where either
    slot is padding or either distance is not a number (masked before any arithmetic)."""
    ok = mask[:, :, None, None] & mask[None, None, :, :]
    d = jnp.where(ok & ~jnp.isnan(d), d, jnp.inf)
    return 0.5 * (d + jnp.transpose(d, (2, 3, 0, 1)))


def other_views(num_views: int) -> Int[Array, "M Mo"]:
    """``(M, M − 1)``: row m lists the views other than m (``m + 1, m + 2, …`` modulo M)."""
    m = jnp.arange(num_views, dtype=jnp.int32)[:, None]
    r = jnp.arange(num_views - 1, dtype=jnp.int32)[None, :]
    return (m + 1 + r) % num_views


def nearest_candidates(
    c: Float[Array, "M P M P"], tau_px: Float[Array, ""], k: int
) -> tuple[Int[Array, " E"], Int[Array, " E"], Float[Array, " E"], Bool[Array, " E"]]:
    """The ``k`` cheapest detections of every node in every other view: ``E = N·(M−1)·k``
    directed candidates ``src → dst`` (nodes ``m * P + i``), their cost (pixels) and
    ``ok = cost < τ``. Equal costs go to the smallest slot; where a view has fewer than
    ``k`` finite costs the rest are not ok."""
    M, P = c.shape[:2]
    k = min(k, P)
    views = jnp.arange(M, dtype=jnp.int32)[:, None]
    others = other_views(M)  # (M, M-1)
    c_mn = jnp.transpose(c, (0, 2, 1, 3))[views, others]  # (M, M-1, P, P): [m, r, i, j]
    # top_k puts the lower index first among equal values: ties go to the smallest slot.
    neg, slot = jax.lax.top_k(-c_mn, k)  # (M, M-1, P, k)
    cost = -neg
    src = views[:, :, None, None] * P + jnp.arange(P, dtype=jnp.int32)[None, None, :, None]
    dst = others[:, :, None, None] * P + slot.astype(jnp.int32)
    src = jnp.broadcast_to(src, dst.shape)
    return src.reshape(-1), dst.reshape(-1), cost.reshape(-1), (cost < tau_px).reshape(-1)
