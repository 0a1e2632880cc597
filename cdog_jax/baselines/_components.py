"""CCA: connected components of the gated epipolar graph, split to view-uniqueness.

After Klasing, Wollherr & Buss (2008), "A clustering method for efficient segmentation of
3D laser data" (ICRA), who cluster by the connected components of a radius-gated
neighbourhood graph; here the nodes are detections and the gate is epipolar.
"""

import dataclasses
from typing import ClassVar

import jax.numpy as jnp

from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ..graph._adjacency import adjacency_from_edges, nearest_neighbour_edges
from ..graph._groups import groups_from_labels
from ..graph._split import split_conflicts
from ._candidates import symmetric_cost


@dataclasses.dataclass(frozen=True)
class ComponentsOptions:
    """Connected components of the gated epipolar graph (Klasing et al., 2008), split.

    The graph joins two detections of different views when each is the other's cheapest
    detection in its view (mutual nearest neighbours) under the symmetric epipolar cost
    ``½ (d[m, i, n, j] + d[n, j, m, i])``, and that cost is below the shared σ-matched gate
    ``τ = max(2·√2·σ, 1 px)``. Mutual nearest neighbours keep the graph sparse (at most
    ``M − 1`` edges per detection), so a component rarely needs many cuts. Every component
    holding two detections of one view is then split: each round removes, in every such
    component, its most expensive edge (ties: smaller node pair), and the components are
    recomputed; after ``max_split_iters`` rounds, a last resort keeps per over-full view the
    detection of smallest mean edge cost and detaches the others, and the status says
    ``Status.SPLIT_CAPPED``.

    Attributes:
        max_split_iters: static bound ``≥ 1`` on the splitting rounds.
    """

    max_split_iters: int = 64
    NUMBERS: ClassVar[tuple[str, ...]] = ()

    def __post_init__(self):
        k = self.max_split_iters
        if not isinstance(k, int) or isinstance(k, bool) or k < 1:
            raise ValueError(f"ComponentsOptions.max_split_iters must be an int >= 1; got {k!r}")


def components_groups(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    d: Float[Array, "M P M P"],
    tau: Float[Array, ""],
    sigma: Float[Array, ""],
    numbers: dict[str, Float[Array, ""]],
    options: ComponentsOptions,
) -> tuple[Int[Array, "G M"], Bool[Array, " G"], Int[Array, ""]]:
    """Groups ``(G, M)`` (slot per view or -1), ``valid (G,)`` and an int32 status ``()``
    (``SPLIT_CAPPED`` / ``COMPONENTS_CAPPED`` bits) of CCA; ``d (M, P, M, P)`` epipolar
    distances (px), ``tau`` the gate (px)."""
    del rig, xy, sigma, numbers
    M, P = mask.shape
    N = M * P
    c = symmetric_cost(d, mask)
    edges = nearest_neighbour_edges(c, tau)
    A = adjacency_from_edges(edges, N, "mutual")
    edge_cost = c.reshape(N, N)[edges.src, edges.dst]
    # No overlap score: every edge ties on θ, so the split cuts the most expensive edge.
    theta = jnp.zeros_like(edge_cost)
    node_view = jnp.arange(N, dtype=jnp.int32) // P
    valid_nodes = mask.reshape(N)
    _, labels, status = split_conflicts(A, edges, theta, edge_cost, node_view, valid_nodes, M, options.max_split_iters)
    groups, valid = groups_from_labels(labels, valid_nodes, M, P)
    return groups, valid, status
