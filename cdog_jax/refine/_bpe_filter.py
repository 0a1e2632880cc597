"""Error association group removal (paper §IV-E, ALGORITHM.md §8).

Groups sorted by back-projection error (BPE, px²) ascending; the first "sudden increase"
is a gap ``g_i = b_{i+1} − b_i`` larger than ``kappa`` times the median of the gaps before
it and larger than an absolute floor ``floor_px2 + (floor_sigma · σ)²``; every group after
it is discarded.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp

from .._expect import ARRAY, INT, expect_args
from .._types import Array, Bool, Float, Int
from ..cdog._config import Switch, Threshold, ThresholdsBase
from ..cdog._stage import Scene, Stage, State

PREFIX_CHUNK = 64
"""Prefixes whose median :func:`_prefix_medians` computes together (static)."""


def _prefix_medians(x: Float[Array, " K"], n: Int[Array, ""]) -> Float[Array, " K"]:
    """``med[i] = median(x[:i])`` for ``0 < i < n``; ``+inf`` for ``i = 0`` and ``i >= n``.

    Without sorting every prefix: sort once; the r-th smallest of a prefix is where the
    prefix's running count in sorted order reaches ``r + 1``. The prefixes are visited
    ``PREFIX_CHUNK`` at a time and only up to ``n``, so the cost is ``O(n K)``, not ``O(K²)``
    (``K`` is the static group capacity, ``n`` the groups that exist).
    """
    K = x.shape[0]
    C = min(PREFIX_CHUNK, K)
    K_pad = -(-K // C) * C
    order = jnp.argsort(x, stable=True).astype(jnp.int32)
    xs = x[order]

    def chunk(start, med):
        i = start + jnp.arange(C, dtype=jnp.int32)  # (C,) prefix lengths
        counts = jnp.cumsum(order[None, :] < i[:, None], axis=1, dtype=jnp.int32)  # (C, K)

        def kth(r):
            return xs[jnp.argmax(counts >= (r + 1)[:, None], axis=1)]

        m = 0.5 * (kth(jnp.maximum(i - 1, 0) // 2) + kth(i // 2))
        return start + C, jax.lax.dynamic_update_slice_in_dim(med, m, start, 0)

    med = jnp.full((K_pad,), jnp.inf, x.dtype)
    _, med = jax.lax.while_loop(
        lambda c: c[0] < jnp.minimum(n, K), lambda c: chunk(*c), (jnp.int32(0), med)
    )
    i = jnp.arange(K, dtype=jnp.int32)
    return jnp.where((i > 0) & (i < n), med[:K], jnp.inf)


def bpe_jump_keep(
    bpe: Float[Array, " G"],
    valid: Bool[Array, " G"],
    sigma_px: Float[Array, ""],
    thresholds: ThresholdsBase,
    min_gaps: int,
) -> Bool[Array, " G"]:
    """``(G,)``: which valid groups survive the jump rule, from ``bpe (G,)`` (px²) and
    ``valid (G,)``."""
    expect_args(
        "bpe_jump_keep",
        bpe=(bpe, ARRAY),
        valid=(valid, ARRAY),
        sigma_px=(sigma_px, ARRAY),
        thresholds=(thresholds, ThresholdsBase),
        min_gaps=(min_gaps, INT),
    )
    G = bpe.shape[0]
    if G < 2:
        return valid
    order = jnp.argsort(jnp.where(valid, bpe, jnp.inf), stable=True).astype(jnp.int32)
    b = jnp.where(valid, bpe, jnp.inf)[order]
    count = jnp.sum(valid, dtype=jnp.int32)
    gaps = b[1:] - b[:-1]  # (G-1,), meaningful for i < count - 1
    i = jnp.arange(G - 1, dtype=jnp.int32)
    med = _prefix_medians(gaps, count - 1)
    floor = thresholds.jump_floor_px2 + (thresholds.jump_floor_sigma * sigma_px) ** 2
    jump = (i >= min_gaps) & (i < count - 1) & (gaps > thresholds.jump_kappa * med) & (gaps > floor)
    first = jnp.where(jnp.any(jump), jnp.argmax(jump).astype(jnp.int32), G)
    rank_keep = jnp.arange(G, dtype=jnp.int32) <= first
    keep = jnp.zeros((G,), bool).at[order].set(rank_keep)
    return keep & valid


class BpeFilterOptions(NamedTuple):
    """Gaps needed before a jump can be declared. Its numbers: ``thresholds.jump_kappa``,
    ``jump_floor_px2``, ``jump_floor_sigma``."""

    jump_min_gaps: int = 3


def bpe_filter_stage(scene: Scene, state: State, options: BpeFilterOptions) -> State:
    """Drop the groups after the first jump of the sorted BPEs (needs a fit)."""
    keep = bpe_jump_keep(
        state.fit.bpe, state.table.valid, scene.sigma, scene.thresholds, options.jump_min_gaps
    )
    return state._replace(
        table=state.table.keep(keep),
        fit=state.fit._replace(member=state.fit.member & keep[:, None]),
    )


BPE_FILTER = Stage(
    "bpe_filter",
    bpe_filter_stage,
    BpeFilterOptions,
    Switch("bpe_filter", True, "drop the groups after the first BPE jump"),
    thresholds=(
        Threshold("jump_kappa", 10.0, doc="BPE jump: gap > jump_kappa · median(previous gaps)"),
        Threshold(
            "jump_floor_px2",
            4.0,
            doc="BPE jump: gap > jump_floor_px2 + (jump_floor_sigma · σ)² (px²)",
            unit="px2",
        ),
        Threshold("jump_floor_sigma", 3.0, doc="BPE jump: see jump_floor_px2"),
    ),
)
