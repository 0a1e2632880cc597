"""One-to-one matching, greedy, cheapest pair first: tracks to groups, tracks to detections."""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax

from ._types import Array, Float, Int


def greedy_match(cost: Float[Array, "A B"]) -> Int[Array, " A"]:
    """One-to-one matching of rows and columns, cheapest pair first: ``(A,)`` the column of
    every row, ``-1`` where unmatched. ``cost (A, B)``: ``+inf`` where a pair is not allowed.
    Ties go to the smaller flat index ``a · B + b``."""
    A, B = cost.shape

    def step(_, carry):
        cost, match = carry
        flat = jnp.argmin(cost)
        a, b = flat // B, flat % B
        ok = jnp.isfinite(cost[a, b])
        match = jnp.where(ok, match.at[a].set(b.astype(jnp.int32)), match)
        cost = jnp.where(ok, cost.at[a, :].set(jnp.inf).at[:, b].set(jnp.inf), cost)
        return cost, match

    # Each step matches a pair or finds none left, so min(A, B) steps match them all.
    _, match = lax.fori_loop(0, min(A, B), step, (cost, jnp.full((A,), -1, jnp.int32)))
    return match
