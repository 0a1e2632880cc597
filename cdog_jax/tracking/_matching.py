"""One-to-one matching, greedy, cheapest pair first: tracks to groups, tracks to detections."""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax

from .._types import Array, Float, Int


def greedy_match(cost: Float[Array, "A B"]) -> Int[Array, " A"]:
    """One-to-one matching of rows and columns, cheapest pair first: ``(A,)`` the column of
    every row, ``-1`` where unmatched. ``cost (A, B)``: ``+inf`` where a pair is not allowed.
    Ties go to the smaller flat index ``a · B + b``."""
    A, B = cost.shape

    def step(carry):
        k, cost, match, _ = carry
        flat = jnp.argmin(cost)
        a, b = flat // B, flat % B
        ok = jnp.isfinite(cost[a, b])
        match = jnp.where(ok, match.at[a].set(b.astype(jnp.int32)), match)
        cost = jnp.where(ok, cost.at[a, :].set(jnp.inf).at[:, b].set(jnp.inf), cost)
        return k + 1, cost, match, ok

    # Each step matches a pair or finds none left (then every later step would do nothing
    # too, so the loop stops), so at most min(A, B) steps match them all.
    init = (jnp.int32(0), cost, jnp.full((A,), -1, jnp.int32), jnp.bool_(True))
    _, _, match, _ = lax.while_loop(lambda c: (c[0] < min(A, B)) & c[3], step, init)
    return match
