"""A whole method in one module, touching no other file: mutual nearest neighbours under the
σ-matched epipolar gate, connected components, and components that hold two detections of
one view dropped. Registered as ``"mutual_nn"`` when imported (the tests import it)."""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from cdog_jax import register_method
from cdog_jax._method import GroupTableMethod
from cdog_jax.graph import (
    adjacency_from_edges,
    alive_edges,
    connected_components,
    groups_from_labels,
    nearest_neighbour_edges,
)
from cdog_jax.graph._components import component_view_counts


@dataclasses.dataclass(frozen=True)
class MutualNearest(GroupTableMethod):
    """Detections that are each other's epipolar nearest neighbour (below τ) are linked; a
    component is a group when it has at most one detection per view, else it is dropped."""

    max_rounds: int = 64  # static: label-propagation rounds of the components

    def group_table(self, rig, xy, mask, d, sigma, tau, thresholds):
        M, P = mask.shape
        N = M * P
        valid = mask.reshape(-1)
        edges = nearest_neighbour_edges(d, tau)
        A = adjacency_from_edges(edges, N, "mutual")
        labels = connected_components(edges, alive_edges(edges, A), N, max_rounds=self.max_rounds)
        node_view = jnp.arange(N, dtype=jnp.int32) // P
        clash = jnp.any(component_view_counts(labels, node_view, valid, M) >= 2, axis=1)
        groups, gvalid = groups_from_labels(labels, valid & ~clash[labels], M, P)
        return groups, gvalid, jnp.int32(0)


register_method("mutual_nn", MutualNearest)
