"""The field's other methods, each a registered :class:`cdog_jax.Method` built on
:class:`cdog_jax.GroupTableMethod` (the same σ, gate, triangulation and validity gate as
every group-table method), so that they compare with C-DOG on equal terms."""

from ._greedy import Greedy as Greedy, GreedyOptions as GreedyOptions, greedy_groups as greedy_groups
from ._components import Components as Components, ComponentsOptions as ComponentsOptions, components_groups as components_groups
from ._voting import Voting as Voting, VotingOptions as VotingOptions, voting_groups as voting_groups
from ._spectral_sync import SpectralSync as SpectralSync, SpectralSyncOptions as SpectralSyncOptions, spectral_sync_groups as spectral_sync_groups
from ._svt import MatchSVT as MatchSVT, MatchSVTOptions as MatchSVTOptions, match_svt_groups as match_svt_groups
from ._spectral_clustering import SpectralClustering as SpectralClustering, SpectralClusteringOptions as SpectralClusteringOptions, spectral_clustering_groups as spectral_clustering_groups
from ._soft_ba import SoftBA as SoftBA, SoftBAOptions as SoftBAOptions, soft_ba_groups as soft_ba_groups
from ._exact import Exact as Exact, exact_groups as exact_groups
from ._st_cut import StCut as StCut, StCutOptions as StCutOptions, st_cut_groups as st_cut_groups
