"""Group-level outlier removal with the interquartile range (paper Alg. 3, ALGORITHM.md §6).

For a group with ≥ 3 members, every pair of member views is triangulated (two-view DLT)
and reprojected into the other members; a node's score is its mean reprojection error
(pixels) and scores outside the IQR fences are outliers. Repeated in a
``lax.while_loop`` until no group changes, at most ``Config.max_iqr_iters`` rounds; a loop
that is still changing groups at that bound is reported (``Status.IQR_CAPPED``).
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._expect import ARRAY, expect_args
from .._status import Status
from .._types import Array, Bool, Float
from ..cdog._config import IqrQuartiles, IqrScore, Switch, Threshold, ThresholdsBase
from ..cdog._stage import GroupTable, Scene, Stage, State
from ..geometry._camera import Rig
from ..geometry._projection import reprojection_errors_views_last
from ..geometry._triangulate import solve_normal_3x3
from ..graph._groups import gather_groups


class IqrOptions(NamedTuple):
    """Which score and quartiles, the reference's 10 px / 50 px guards, and the bound of the
    removal loop. Its numbers: ``thresholds.iqr_alpha``, ``iqr_floor_px``, ``iqr_min_px``,
    ``iqr_force_px``."""

    iqr_score: IqrScore = "exclude_own"
    iqr_quartiles: IqrQuartiles = "zero_pad"
    iqr_guards: bool = False
    max_iqr_iters: int = 16


def percentile_linear(values: Float[Array, " K"], count, q: float) -> Float[Array, ""]:
    """``()``: ``numpy.percentile`` (linear) at ``q`` (0–100) of the ``count`` smallest finite
    entries of ``values (K,)``; the others must be ``+inf``. Finite but meaningless if
    ``count == 0``."""
    expect_args("percentile_linear", values=(values, ARRAY), count=(count, ARRAY))
    v = jnp.sort(values)
    pos = (q / 100.0) * jnp.maximum(count - 1, 0).astype(values.dtype)
    lo = jnp.floor(pos).astype(jnp.int32)
    hi = jnp.minimum(lo + 1, jnp.maximum(count - 1, 0))
    frac = pos - lo.astype(values.dtype)
    v_lo, v_hi = v[lo], v[hi]
    v_hi = jnp.where(jnp.isfinite(v_hi), v_hi, v_lo)
    v_lo = jnp.where(jnp.isfinite(v_lo), v_lo, 0.0)
    return v_lo + frac * (v_hi - v_lo)


def node_scores(
    rig: Rig, N, r, origin, xy_g: Float[Array, "M 2"], member: Bool[Array, " M"], own: bool
) -> tuple[Float[Array, " M"], Bool[Array, " M"]]:
    """Scores ``(M,)``: mean pair-reprojection error (pixels) of every member view of one
    group, and ``(M,)`` whether it is defined. ``N (M, 3, 3)``, ``r (M, 3)`` DLT blocks,
    ``xy_g (M, 2)``, ``member (M,)``; ``own`` counts each pair's own two errors too."""
    expect_args("node_scores", rig=(rig, Rig), xy_g=(xy_g, ARRAY), member=(member, ARRAY))
    M = member.shape[0]
    pa, pb = np.triu_indices(M, k=1)  # the K = M(M-1)/2 unordered pairs a < b, static
    X, ok = solve_normal_3x3(N[pa] + N[pb], r[pa] + r[pb])  # (K, 3), (K,)
    X = X + origin[None, :]
    err = reprojection_errors_views_last(
        rig, X, jnp.broadcast_to(xy_g, (len(pa), M, 2))
    )  # e[p, c], (K, M)
    pair = ok & member[pa] & member[pb]
    weight = pair[:, None] & member[None, :]
    if not own:
        views = np.arange(M)
        weight = weight & jnp.asarray(
            (views[None, :] != pa[:, None]) & (views[None, :] != pb[:, None])
        )
    w = weight.astype(err.dtype)
    total = jnp.sum(w * err, axis=0)
    count = jnp.sum(w, axis=0)
    defined = count > 0
    return jnp.where(defined, total / jnp.where(defined, count, 1.0), 0.0), defined


def iqr_outliers(
    score: Float[Array, " M"],
    member: Bool[Array, " M"],
    thresholds: ThresholdsBase,
    options: IqrOptions,
) -> Bool[Array, " M"]:
    """Members whose score lies outside ``[max(0, Q1 − α IQR), Q3 + α IQR]``."""
    expect_args(
        "iqr_outliers",
        score=(score, ARRAY),
        member=(member, ARRAY),
        thresholds=(thresholds, ThresholdsBase),
        options=(options, IqrOptions),
    )
    if options.iqr_quartiles == "zero_pad":
        vals = jnp.concatenate([jnp.where(member, score, jnp.inf), jnp.zeros((1,), score.dtype)])
        count = jnp.sum(member, dtype=jnp.int32) + 1
    else:
        positive = member & (score > 0)
        vals = jnp.concatenate(
            [jnp.where(positive, score, jnp.inf), jnp.full((1,), jnp.inf, score.dtype)]
        )
        count = jnp.sum(positive, dtype=jnp.int32)
    q1 = percentile_linear(vals, count, 25.0)
    q3 = percentile_linear(vals, count, 75.0)
    iqr = q3 - q1
    lb = jnp.maximum(0.0, q1 - thresholds.iqr_alpha * iqr)
    ub = q3 + thresholds.iqr_alpha * iqr
    # The floor keeps float round-off (σ = 0: every score ~1e-4 px) from making outliers.
    out = member & ((score < lb) | (score > ub)) & (score > thresholds.iqr_floor_px) & (count > 0)
    if options.iqr_guards:
        top = jnp.max(jnp.where(member, score, -jnp.inf))
        out = out & (top >= thresholds.iqr_min_px)
        worst = jnp.argmax(jnp.where(member, score, -jnp.inf)).astype(jnp.int32)
        force = ~jnp.any(out) & (top > thresholds.iqr_force_px) & (top >= thresholds.iqr_min_px)
        out = out | (force & (jnp.arange(score.shape[0], dtype=jnp.int32) == worst))
    return out


IQR_CHUNK = 16
"""Groups processed together by :func:`remove_outliers` (static)."""


def remove_outliers(
    rig: Rig,
    N_g: Float[Array, "G M 3 3"],
    r_g: Float[Array, "G M 3"],
    origin: Float[Array, 3],
    xy_g: Float[Array, "G M 2"],
    member: Bool[Array, "G M"],
    thresholds: ThresholdsBase,
    options: IqrOptions,
) -> tuple[Bool[Array, "G M"], Bool[Array, ""]]:
    """Iterated IQR removal over all groups; returns the members ``(G, M)`` and ``()`` True
    when some chunk's loop stopped at ``options.max_iqr_iters`` while its last round still
    removed members (more outliers may be left).

    Per group ``N_g (G, M, 3, 3)``, ``r_g (G, M, 3)`` DLT blocks, ``xy_g (G, M, 2)`` pixels,
    ``member (G, M)``. Groups left with < 2 members dissolve (all False).

    Groups are independent, so only those with ≥ 3 members are visited: they are moved to
    the front and cleaned ``IQR_CHUNK`` at a time, each chunk iterated until none of its
    groups changes (at most ``options.max_iqr_iters`` rounds). The static capacity ``G`` is
    far larger than the number of real groups, so this costs what the real groups cost.
    """
    expect_args(
        "remove_outliers",
        rig=(rig, Rig),
        thresholds=(thresholds, ThresholdsBase),
        options=(options, IqrOptions),
    )
    own = options.iqr_score == "include_own"
    G, M = member.shape
    C = min(IQR_CHUNK, G)
    G_pad = -(-G // C) * C

    def one_group(N, r, xy, mem):
        big = jnp.sum(mem, dtype=jnp.int32) >= 3
        w = mem.astype(N.dtype)
        score, _ = node_scores(rig, N * w[:, None, None], r * w[:, None], origin, xy, mem, own)
        out = iqr_outliers(score, mem, thresholds, options) & big
        return mem & ~out

    def clean_chunk(N, r, xy, mem):
        def cond(carry):
            _, changed, it = carry
            return changed & (it < options.max_iqr_iters)

        def body(carry):
            mem, _, it = carry
            new = jax.vmap(one_group)(N, r, xy, mem)
            new = new & (jnp.sum(new, dtype=jnp.int32, axis=1, keepdims=True) >= 2)
            return new, jnp.any(new != mem), it + 1

        mem, changed, _ = jax.lax.while_loop(cond, body, (mem, jnp.bool_(True), jnp.int32(0)))
        return mem, changed

    big = jnp.sum(member, dtype=jnp.int32, axis=1) >= 3
    order = jnp.argsort(~big, stable=True).astype(jnp.int32)  # big groups first
    order = jnp.concatenate([order, jnp.zeros((G_pad - G,), jnp.int32)])
    live = jnp.arange(G_pad, dtype=jnp.int32) < jnp.sum(big, dtype=jnp.int32)
    N_s, r_s, xy_s = N_g[order], r_g[order], xy_g[order]
    mem_s = member[order] & live[:, None]

    def chunk_cond(carry):
        start, _, _ = carry
        return (start < G_pad) & live[jnp.minimum(start, G_pad - 1)]

    def chunk_body(carry):
        start, mem_s, capped = carry
        take = lambda a: jax.lax.dynamic_slice_in_dim(a, start, C)  # noqa: E731
        new, changed = clean_chunk(take(N_s), take(r_s), take(xy_s), take(mem_s))
        return (
            start + C,
            jax.lax.dynamic_update_slice_in_dim(mem_s, new, start, 0),
            capped | changed,
        )

    _, mem_s, capped = jax.lax.while_loop(
        chunk_cond, chunk_body, (jnp.int32(0), mem_s, jnp.bool_(False))
    )
    cleaned = (
        jnp.zeros((G, M), bool).at[order].max(mem_s & live[:, None])
    )  # padding rows add nothing
    keep = jnp.where(big[:, None], cleaned, member)  # groups of 2 are left as they are
    return keep & (jnp.sum(keep, dtype=jnp.int32, axis=1, keepdims=True) >= 2), capped


# The IQR runs twice in extended() (regroup): as a nested jit it is traced and lowered once
# and the second call reuses it.
@partial(jax.jit, static_argnames=("options",))
def iqr_table(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    table: GroupTable,
    blocks: tuple,
    thresholds: ThresholdsBase,
    options: IqrOptions,
) -> tuple[GroupTable, Bool[Array, ""]]:
    """Alg. 3 on the group table (per-node DLT ``blocks`` as in :func:`dlt_blocks`); returns
    the cleaned table (groups left with < 2 members are no longer valid) and ``()`` True
    when the loop stopped at its bound."""
    N_node, r_node, origin = blocks
    groups, valid = table
    member, capped = remove_outliers(
        rig,
        gather_groups(groups, N_node),
        gather_groups(groups, r_node),
        origin,
        gather_groups(groups, xy),
        valid[:, None] & (groups >= 0),
        thresholds,
        options,
    )
    return GroupTable(
        jnp.where(member, groups, -1), jnp.sum(member, dtype=jnp.int32, axis=1) >= 2
    ), capped


def iqr_stage(scene: Scene, state: State, options: IqrOptions) -> State:
    """The group table with IQR outliers removed (``Status.IQR_CAPPED`` at the bound)."""
    table, capped = iqr_table(
        scene.rig, scene.xy, state.table, scene.blocks, scene.thresholds, options
    )
    return state._replace(table=table, fit=None).flag(capped, Status.IQR_CAPPED)


IQR = Stage(
    "iqr",
    iqr_stage,
    IqrOptions,
    Switch("iqr", True, "remove IQR outliers from groups (Alg. 3)"),
    thresholds=(
        Threshold("iqr_alpha", 2.0, doc="IQR fence multiplier (Alg. 3)"),
        Threshold(
            "iqr_floor_px", 1.0, doc="an outlier's score must also exceed this (pixels)", unit="px"
        ),
        Threshold(
            "iqr_min_px",
            10.0,
            doc="reference guard: no outlier if the max score is below this (pixels)",
            unit="px",
        ),
        Threshold(
            "iqr_force_px",
            50.0,
            doc="reference guard: drop the max if above this (pixels)",
            unit="px",
        ),
    ),
)
