"""The association graph: epipolar edges, δ-overlap pruning, components, view-uniqueness
(paper Alg. 1–2)."""

from ._adjacency import (
    EdgeTable as EdgeTable,
    adjacency_from_edges as adjacency_from_edges,
    alive_edges as alive_edges,
    nearest_neighbour_edges as nearest_neighbour_edges,
)
from ._components import connected_components as connected_components
from ._groups import groups_from_labels as groups_from_labels
from ._sigma import estimate_sigma as estimate_sigma
from ._sigma_robust import estimate_sigma_robust as estimate_sigma_robust
