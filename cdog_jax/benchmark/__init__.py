"""The benchmark sweep (docs/BENCHMARK.md §1–2): a noise × density grid generated, associated and
scored in one compiled program per capacity bucket, sharded over devices, saved to NPZ/CSV/JSON, summarised; the named
configurations it compares. Its figures are in :mod:`cdog_jax.viz`."""

from .._runtime.lazy_names import load_on_first_use as _load_on_first_use
from ._methods import (
    DEFAULT_METHODS as DEFAULT_METHODS,
    METHODS as METHODS,
    ablation_stages as ablation_stages,
)

# The rest loads on first use: the command line lists the named methods in its help (above)
# without loading the sweep, the grid and the file writers for every command.
_LATER = {
    "Grid": "._grid",
    "load_results": "._io",
    "save_results": "._io",
    "summary_table": "._io",
    "SweepProgress": "._sweep",
    "SweepResult": "._sweep",
    "print_progress": "._sweep",
    "sweep": "._sweep",
    "use_cpu_cores": "._cpu_cores",
    "sweep_host": "._host_sweep",
}

__getattr__, __dir__, __all__ = _load_on_first_use(globals(), _LATER)
