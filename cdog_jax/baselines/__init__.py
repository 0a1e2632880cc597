"""The field's other methods, each a registered :class:`cdog_jax.Method` built on
:class:`cdog_jax.GroupTableMethod` (the same σ, gate, triangulation and validity gate as
every group-table method), so that they compare with C-DOG on equal terms. One public class
per method: its options are its fields, and :meth:`~cdog_jax.GroupTableMethod.group_table`
gives its groups of one scene."""

# isort: off
# The order they register in: the order every list of methods shows them.
from ._greedy import Greedy as Greedy
from ._components import Components as Components
from ._voting import Voting as Voting
from ._spectral_sync import SpectralSync as SpectralSync
from ._svt import MatchSVT as MatchSVT
from ._spectral_clustering import SpectralClustering as SpectralClustering
from ._soft_ba import SoftBA as SoftBA
from ._exact import Exact as Exact
from ._st_cut import StCut as StCut
# isort: on
