"""Paper metrics (docs/BENCHMARK.md §2): G-, mP-, PG- scores, 3DErr and BPE per scene, and their means."""

from ._scores import Metrics as Metrics
from ._scores import mean_metrics as mean_metrics
from ._scores import scene_metrics as scene_metrics
