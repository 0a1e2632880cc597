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

import jax  # noqa: E402
import pytest  # noqa: E402

import sys  # noqa: E402

# Test modules live in sub-folders without __init__.py; make tests/helpers.py importable.
sys.path.insert(0, os.path.dirname(__file__))

from helpers import FAST_COMPILE_FLAG  # noqa: E402

# The suite's time is compilation, not running: XLA's older CPU code generator (one LLVM
# function per fusion, no MLIR fusion emitters) compiles our programs about a third faster;
# the newer one runs the benchmark grid ~40 % faster, which is why the library leaves XLA's
# default alone. XLA reads the flag when JAX starts its backend (no operation has run yet);
# child processes (command-line tests) inherit it. It changes how operations are fused,
# hence possibly the last bit of a float: bitwise comparisons are between programs compiled
# alike, except tests/test_shapes.py's batch test, which runs with XLA's default.
if "xla_cpu_use_fusion_emitters" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {FAST_COMPILE_FLAG}".strip()

jax.config.update("jax_numpy_rank_promotion", "raise")
jax.config.update("jax_numpy_dtype_promotion", "strict")


@pytest.fixture
def getkey():
    """A fresh PRNG key per call, deterministic per test."""
    state = {"i": 0}

    def _getkey():
        state["i"] += 1
        return jax.random.PRNGKey(state["i"])

    return _getkey


def _memory_mappings() -> int | None:
    """Memory mappings of this process (Linux), or None where /proc is not there."""
    try:
        with open("/proc/self/maps", "rb") as f:
            return sum(1 for _ in f)
    except OSError:
        return None


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
    count = _memory_mappings()
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
