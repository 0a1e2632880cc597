"""C-DOG's first stage (paper Alg. 1–2, ALGORITHM.md §1–5): the epipolar graph of the valid
nodes, δ-overlap pruning, and view-unique components, as the group table."""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp

from .._status import Status
from .._types import Array, Bool, Float, Int
from ..cdog._config import Adjacency, PruneScope, Range, Threshold, ThresholdsBase
from ..cdog._stage import GroupTable, Scene, Stage, State, always, raise_flag
from ._adjacency import adjacency_from_edges, alive_edges, nearest_neighbour_edges
from ._components import component_view_counts, connected_components_capped
from ._groups import groups_from_labels
from ._overlap import edge_overlap, remove_edges
from ._split import split_conflicts


class GraphOptions(NamedTuple):
    """Mutual or union adjacency, which components δ-pruning may touch, and the bound of the
    splitting loop. Its number: ``thresholds.delta`` (and the gate τ of the scene)."""

    adjacency: Adjacency = "mutual"
    prune_scope: PruneScope = "all"
    max_split_iters: int = 64


# The graph stage runs twice in extended() (regroup): as a nested jit it is traced and
# lowered once and the second call reuses it.
@partial(jax.jit, static_argnames=("options",))
def graph_groups(
    d: Float[Array, "M P M P"],
    valid: Bool[Array, " N"],
    tau: Float[Array, ""],
    thresholds: ThresholdsBase,
    options: GraphOptions,
) -> tuple[Int[Array, "G M"], Bool[Array, " G"], Int[Array, ""]]:
    """Alg. 1–2 on the valid nodes: epipolar graph, δ-pruning, view-unique components;
    returns the group table ``(G, M)``, its validity ``(G,)`` and an int32 status ``()``."""
    M, P = d.shape[:2]
    N = M * P
    d = jnp.where(valid.reshape(M, P, 1, 1) & valid.reshape(1, 1, M, P), d, jnp.inf)
    node_view = jnp.arange(N, dtype=jnp.int32) // P
    edges = nearest_neighbour_edges(d, tau)
    A = adjacency_from_edges(edges, N, options.adjacency)
    theta = edge_overlap(edges, A, dtype=d.dtype)
    d_nodes = d.reshape(N, N)
    edge_dist = 0.5 * (d_nodes[edges.src, edges.dst] + d_nodes[edges.dst, edges.src])
    weak = alive_edges(edges, A) & (theta < thresholds.delta)
    status = jnp.int32(0)
    if options.prune_scope == "conflicts":
        labels0, capped = connected_components_capped(edges, alive_edges(edges, A), N, per_node=M)
        status = raise_flag(capped, Status.COMPONENTS_CAPPED)
        counts = component_view_counts(labels0, node_view, valid, M)
        weak = weak & jnp.any(counts >= 2, axis=1)[labels0[edges.src]]
    elif options.prune_scope == "none":
        weak = jnp.zeros_like(weak)
    A = remove_edges(A, edges, weak)
    _, labels, split_status = split_conflicts(
        A, edges, theta, edge_dist, node_view, valid, M, options.max_split_iters, per_node=M
    )
    return (*groups_from_labels(labels, valid, M, P), status | split_status)


def graph_stage(scene: Scene, state: State, options: GraphOptions) -> State:
    """The group table of the scene's valid nodes (``scene.node_valid``); the incoming
    table is replaced."""
    groups, valid, status = graph_groups(
        scene.d, scene.node_valid, scene.tau, scene.thresholds, options
    )
    return state._replace(table=GroupTable(groups, valid), fit=None, status=state.status | status)


GRAPH = Stage(
    "graph",
    graph_stage,
    GraphOptions,
    always,
    # θ ≥ δ keeps an edge; δ = 0 would keep all.
    thresholds=(
        Threshold("delta", 0.5, Range(0.0, 1.0, low_open=True), "δ-overlap threshold (Alg. 2)"),
    ),
)
