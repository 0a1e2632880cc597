"""CCA: connected components of the gated epipolar graph, split to view-uniqueness.

After Klasing, Wollherr & Buss (2008), "A clustering method for efficient segmentation of
3D laser data" (ICRA), who cluster by the connected components of a radius-gated
neighbourhood graph; here the nodes are detections and the gate is epipolar.
"""

import dataclasses
from typing import ClassVar

import jax.numpy as jnp

from .._method import GroupTableMethod, register_method
from .._types import Array, Bool, Float, Int
from ..geometry._camera import Rig
from ..graph._adjacency import nearest_neighbour_edges
from ..graph._groups import groups_from_labels
from ._candidates import symmetric_cost
from ._merge import merge_in_order


@dataclasses.dataclass(frozen=True)
class ComponentsOptions:
    """Connected components of the gated epipolar graph (Klasing et al., 2008), split.

    The graph joins two detections of different views when each is the other's cheapest
    detection in its view (mutual nearest neighbours; ties: smallest slot) under the
    symmetric epipolar cost ``½ (d[m, i, n, j] + d[n, j, m, i])``, and that cost is below
    the shared σ-matched gate ``τ = max(2·√2·σ, 1 px)``: at most ``N · (M − 1) / 2`` edges
    (``N = M · P``). Every component holding two detections of one view is split by
    cutting its most expensive edge (ties: smaller node pair first), again and again, in
    each piece that still holds two detections of one view.

    The cuts are not made one by one: cutting a component's edges from the most expensive
    down leaves, at every step, the components of its cheaper edges, so the result is the
    set of largest view-unique clusters of single-linkage clustering over the edges. That
    is computed in one pass over the edges from the cheapest up (Kruskal's order): an edge
    merges its two clusters when the union is view-unique; when it is not, both clusters
    are final (every larger cluster holding them conflicts too) and never merge again. One
    step per edge, so no bound can be reached and the status is always 0 (cutting one edge
    per round with a components pass after each took hundreds of rounds on noisy scenes of
    10 views).

    No parameters beyond the shared gate.
    """

    THRESHOLDS: ClassVar[tuple[str, ...]] = ()


def components_groups(
    rig: Rig,
    xy: Float[Array, "M P 2"],
    mask: Bool[Array, "M P"],
    d: Float[Array, "M P M P"],
    tau: Float[Array, ""],
    sigma: Float[Array, ""],
    thresholds: dict[str, Float[Array, ""]],
    options: ComponentsOptions,
) -> tuple[Int[Array, "G M"], Bool[Array, " G"], Int[Array, ""]]:
    """Groups ``(G, M)`` (slot per view or -1), ``valid (G,)`` and status ``()`` (always 0)
    of CCA; ``d (M, P, M, P)`` epipolar distances (px), ``tau`` the gate (px)."""
    del rig, xy, sigma, thresholds, options
    M, P = mask.shape
    N = M * P
    c = symmetric_cost(d, mask)
    edges = nearest_neighbour_edges(c, tau)  # (N·M,) proposals u → v
    # A mutual pair is proposed from both ends: keep it once, from its smaller node.
    back = jnp.zeros((N, N), bool).at[edges.src, edges.dst].max(edges.ok)
    keep = edges.ok & back[edges.dst, edges.src] & (edges.src < edges.dst)
    cost = jnp.where(keep, c.reshape(N, N)[edges.src, edges.dst], jnp.inf)
    # Cheapest first; among equal costs the pair that a cut would take last comes first.
    order = jnp.lexsort((-edges.dst, -edges.src, cost))
    labels = merge_in_order(
        edges.src[order],
        edges.dst[order],
        jnp.sum(keep, dtype=jnp.int32),
        mask,
        freeze_on_conflict=True,
    )
    groups, valid = groups_from_labels(labels, mask.reshape(N), M, P)
    return groups, valid, jnp.int32(0)


@dataclasses.dataclass(frozen=True)
class Components(GroupTableMethod, ComponentsOptions):
    """Connected components of the gated epipolar graph, split to view-uniqueness (CCA) as a registered method (``"components"``): the options and algorithm of
    :class:`ComponentsOptions`, with the σ, gate, triangulation and validity gate every group-table
    method shares (:class:`cdog_jax.GroupTableMethod`).
    """

    GROUPS = staticmethod(components_groups)


register_method("components", Components)
