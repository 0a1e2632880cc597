"""Paper metrics (docs/BENCHMARK.md §2): G-, mP-, PG- scores, 3DErr and BPE per scene, and their means."""

from ._scores import (
    Metrics as Metrics,
    mean_metrics as mean_metrics,
    scene_metrics as scene_metrics,
)
