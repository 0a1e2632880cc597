"""One-to-one matching, greedy, cheapest pair first: tracks to groups, tracks to detections."""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax

from .._types import Array, Float, Int
from ..graph._adjacency import min_and_first_index


def greedy_match(cost: Float[Array, "A B"]) -> Int[Array, " A"]:
    """One-to-one matching of rows and columns, cheapest pair first: ``(A,)`` the column of
    every row, ``-1`` where unmatched. ``cost (A, B)``: ``+inf`` where a pair is not allowed.
    Ties go to the smaller flat index ``a · B + b``.

    Computed in rounds of mutual best pairs rather than one pair a step: a pair that is the
    cheapest of its row and of its column among the rows and columns still free (ties by
    flat index) is taken by the cheapest-first order too, since no cheaper pair could claim
    its row or column first; so every round takes all such pairs at once and the result is
    the same. The cheapest remaining pair is always mutual, so each round takes at least
    one; a frame's tables need a few rounds where one pair a step needed one per match.
    """
    A, B = cost.shape
    cost_t = cost.T  # (B, A)

    def step(carry):
        k, row_free, col_free, match, _ = carry
        # The pairs of free rows and columns; the tables stay as they are (a round masks
        # them inside its reductions instead of writing them again).
        left = jnp.where(row_free[:, None] & col_free[None, :], cost, jnp.inf)
        left_t = jnp.where(col_free[:, None] & row_free[None, :], cost_t, jnp.inf)
        # argmin's answers (first of ties; the costs hold no NaN: a pair with none is +inf)
        # from plain reductions: argmin's variadic reduce cost 0.1–0.15 ms a round on a
        # live frame's (256, 256) table. Every reduction runs down the columns, of the table
        # or of its transpose: XLA's CPU kernels reduce a (256, 256) table along its rows
        # about three times slower than down its columns.
        best_col = min_and_first_index(left_t, axis=0)[1]  # (A,) first of ties: smaller b
        best_row = min_and_first_index(left, axis=0)[1]  # (B,) first of ties: smaller a
        row_ok = jnp.any(jnp.isfinite(left_t), axis=0)
        mutual = row_ok & (best_row[best_col] == jnp.arange(A, dtype=jnp.int32))  # (A,)
        match = jnp.where(mutual, best_col, match)
        taken_col = jnp.zeros((B,), bool).at[jnp.where(mutual, best_col, B)].set(True, mode="drop")
        return k + 1, row_free & ~mutual, col_free & ~taken_col, match, jnp.any(mutual)

    # Every round with a finite pair left matches at least one; a round that matches none
    # has none left, and the loop stops.
    init = (
        jnp.int32(0),
        jnp.ones((A,), bool),
        jnp.ones((B,), bool),
        jnp.full((A,), -1, jnp.int32),
        jnp.bool_(True),
    )
    _, _, _, match, _ = lax.while_loop(lambda c: (c[0] < min(A, B)) & c[4], step, init)
    return match
