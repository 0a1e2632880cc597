"""The association graph: epipolar edges, δ-overlap pruning, components, view-uniqueness
(paper Alg. 1–2)."""

from ._adjacency import (
    EdgeTable as EdgeTable,
    adjacency_from_edges as adjacency_from_edges,
    alive_edges as alive_edges,
    nearest_neighbour_edges as nearest_neighbour_edges,
)
from ._components import (
    connected_components as connected_components,
    connected_components_capped as connected_components_capped,
)
from ._groups import (
    groups_from_labels as groups_from_labels,
    labels_from_groups as labels_from_groups,
)
from ._overlap import edge_overlap as edge_overlap, remove_edges as remove_edges
from ._sigma import estimate_sigma as estimate_sigma, focal_scale as focal_scale
from ._sigma_robust import estimate_sigma_robust as estimate_sigma_robust
from ._split import split_conflicts as split_conflicts
