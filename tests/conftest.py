import os
import shutil
import tempfile

# Compiled programs persist for this run only: a fresh folder, removed at the end. Programs
# dropped by _release_compiled_programs, built by new jit wrappers of the same function, or
# compiled in child processes (command-line tests) or in another worker of the run (the
# workers inherit the folder from the process that starts them) are then loaded instead of
# compiled.
_RUN_CACHE_VARIABLE = "CDOG_JAX_TEST_RUN_CACHE"
_OWNS_CACHE = _RUN_CACHE_VARIABLE not in os.environ
if _OWNS_CACHE:
    os.environ[_RUN_CACHE_VARIABLE] = tempfile.mkdtemp(prefix="cdog_jax_test_cache_")
_COMPILE_CACHE = os.environ[_RUN_CACHE_VARIABLE]
os.environ["CDOG_JAX_CACHE_DIR"] = _COMPILE_CACHE
os.environ.pop("CDOG_JAX_CACHE", None)

# The suite's strict numerics (no implicit rank or dtype promotion), set through the
# environment so that child processes (command-line tests) inherit them: their programs and
# their stored programs' keys are then those of this process, and each is loaded from the
# run's cache instead of being compiled again.
os.environ["JAX_NUMPY_RANK_PROMOTION"] = "raise"
os.environ["JAX_NUMPY_DTYPE_PROMOTION"] = "strict"

import gc  # noqa: E402
import sys  # noqa: E402

import jax  # noqa: E402
import pytest  # noqa: E402

# Test modules live in sub-folders without __init__.py; make tests/helpers.py importable.
sys.path.insert(0, os.path.dirname(__file__))

from helpers import FAST_COMPILE_FLAGS, memory_mappings  # noqa: E402

import cdog_jax  # noqa: E402

cdog_jax.enable_compilation_cache()  # the run's folder (above); importing the package does not

# The suite's time is compilation, not running. Three XLA switches cut it (on x86-64;
# tests/helpers.py): XLA's older CPU code generator (one LLVM function per fusion, no MLIR
# fusion emitters), LLVM without optimisation passes, and SSE4.2 code. Together they
# compile our programs about 2.5 times faster and run them about 5 times slower; the
# library keeps XLA's defaults (the newer generator runs the benchmark grid ~40 % faster).
# SSE4.2 has no fused multiply-add, and the one thing the other two switches change in a
# result is where a multiply and an add are fused into one rounding: without it, every way
# of compiling a program gives the same bits, so the suite's bitwise comparisons hold
# whatever XLA fuses. XLA reads the flags when JAX starts its backend (no operation has run
# yet); child processes (command-line tests) inherit them. tests/test_shapes.py's batch
# test runs with XLA's defaults, the code users run. A fourth switch generates each
# program's machine code in one piece rather than split over threads (helpers.py): a
# tenth less processor time, the same code.
if "xla_cpu_use_fusion_emitters" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {FAST_COMPILE_FLAGS}".strip()

# Python's cycle collector, less often. Tracing a program makes millions of short-lived
# objects; with the default thresholds (700, 10, 10) a worker ran about 3,000 collections
# and 15 full ones over a test file's heap of traced programs, some 6 % of its time. With
# these, about 150 and one or two: cycles are still collected, later.
gc.set_threshold(10_000, 10, 10)

assert jax.config.jax_numpy_rank_promotion == "raise"  # read from the environment above
assert jax.config.jax_numpy_dtype_promotion == "strict"


@pytest.fixture
def getkey():
    """A fresh PRNG key per call, deterministic per test."""
    state = {"i": 0}

    def _getkey():
        state["i"] += 1
        return jax.random.PRNGKey(state["i"])

    return _getkey


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    """Drop JAX's compiled programs after a test module once the process holds many
    memory mappings.

    Each compiled CPU executable holds its own mappings for code; the whole suite compiles
    thousands of programs, and kept alive in one process they passed the kernel's
    ``vm.max_map_count`` (65530), after which XLA aborted or segfaulted while compiling.
    Clearing only above a third of that keeps the programs that later modules reuse.
    """
    yield
    count = memory_mappings()
    if count is None or count > 20_000:
        jax.clear_caches()
        import gc

        gc.collect()


def pytest_xdist_auto_num_workers(config):
    """``-n auto``: one worker per core this process may use, at most 4. Compilation runs
    on one core, so two workers on two cores halve the suite; each worker holds its own
    compiled programs (1–3 GB), which caps the count."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:
        cores = os.cpu_count() or 1
    return max(1, min(cores, 4))


def pytest_sessionfinish(session, exitstatus):
    if _OWNS_CACHE:  # the process that made the folder removes it, after its workers
        shutil.rmtree(_COMPILE_CACHE, ignore_errors=True)
