"""The reference code's "second association" (docs/BENCHMARK.md §5, ALGORITHM.md §7).

Each leftover valid node joins the group (lacking its view) whose members' epipolar lines
pass closest to it on average, distances ≥ τ counted three times, if that mean is below
``second_frac · τ``. One pass; when nodes of one view pick the same group, the cheapest wins.
"""

import jax.numpy as jnp

from .._expect import ARRAY, expect_args
from .._types import Array, Bool, Float, Int
from ..cdog._config import Switch, Threshold, ThresholdsBase
from ..cdog._stage import Scene, Stage, State
from ._attach import attach_cheapest, leftover_nodes


def second_association(
    d: Float[Array, "N N"],
    groups: Int[Array, "G M"],
    valid: Bool[Array, " G"],
    node_valid: Bool[Array, " N"],
    tau_px: Float[Array, ""],
    thresholds: ThresholdsBase,
) -> Int[Array, "G M"]:
    """The group table ``(G, M)`` with leftover nodes attached. ``d (N, N)``: ``d[v, u]`` is
    the distance in u's image from u to the epipolar line of v (pixels)."""
    expect_args(
        "second_association",
        d=(d, ARRAY),
        groups=(groups, ARRAY),
        valid=(valid, ARRAY),
        node_valid=(node_valid, ARRAY),
        thresholds=(thresholds, ThresholdsBase),
    )
    G, M = groups.shape
    N = d.shape[0]
    P = N // M
    member = valid[:, None] & (groups >= 0)  # (G, M)
    member_node = jnp.where(
        member, jnp.arange(M, dtype=jnp.int32)[None, :] * P + groups, 0
    )  # (G, M)
    leftover = leftover_nodes(groups, valid, node_valid.reshape(M, P))
    node_view = jnp.arange(N, dtype=jnp.int32) // P

    dist = d[member_node]  # (G, M, N): from member (g, m) to every node
    w = jnp.where(dist < tau_px, dist, 3.0 * dist)
    w = jnp.where(member[:, :, None], w, 0.0)
    n_mem = jnp.sum(member.astype(d.dtype), axis=1)  # (G,)
    cost = jnp.sum(w, axis=1) / jnp.maximum(n_mem, 1.0)[:, None]  # (G, N)
    lacks_view = ~member[:, node_view]  # (G, N)
    allowed = valid[:, None] & lacks_view & leftover[None, :]
    cost = jnp.where(allowed, cost, jnp.inf)

    return attach_cheapest(groups, cost, thresholds.second_frac * tau_px)


def second_association_stage(scene: Scene, state: State, options: None) -> State:
    """The group table with leftover nodes attached by their epipolar cost."""
    M, P = scene.mask.shape
    groups = second_association(
        scene.d.reshape(M * P, M * P), *state.table, scene.node_valid, scene.tau, scene.thresholds
    )
    return state._replace(table=state.table._replace(groups=groups), fit=None)


SECOND_ASSOCIATION = Stage(
    "second_association",
    second_association_stage,
    None,
    Switch(
        "second_association",
        False,
        "attach leftover nodes by their epipolar cost (the reference's)",
    ),
    thresholds=(
        Threshold(
            "second_frac", 0.5, doc="second association: attach if the mean cost < second_frac · τ"
        ),
    ),
)
