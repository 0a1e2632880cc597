"""The benchmark sweep (docs/BENCHMARK.md §1–2): a noise × density grid generated, associated and
scored in one compiled program per capacity bucket, sharded over devices, saved to NPZ/CSV/JSON, summarised; the named
configurations it compares. Its figures are in :mod:`cdog_jax.viz`."""

from ._grid import DRAW_CAPACITY as DRAW_CAPACITY
from ._grid import Grid as Grid
from ._grid import GridIndex as GridIndex
from ._grid import bucket_of as bucket_of
from ._grid import compact_scene as compact_scene
from ._grid import scene_keys as scene_keys
from ._io import load_results as load_results
from ._methods import DEFAULT_METHODS as DEFAULT_METHODS
from ._methods import METHODS as METHODS
from ._methods import ablation_stages as ablation_stages
from ._io import save_results as save_results
from ._io import summary_table as summary_table
from ._sweep import SweepProgress as SweepProgress
from ._sweep import SweepResult as SweepResult
from ._cpu_cores import use_cpu_cores as use_cpu_cores
from ._sweep import default_mesh as default_mesh
from ._sweep import metric_fields as metric_fields
from ._sweep import print_progress as print_progress
from ._sweep import sweep as sweep
from ._host_sweep import sweep_host as sweep_host
