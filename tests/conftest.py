import os
import shutil
import tempfile

# Compiled programs persist for this run only: a fresh folder, removed at the end. Programs
# dropped by _release_compiled_programs, built by new jit wrappers of the same function, or
# compiled in child processes (command-line tests) are then loaded instead of compiled.
_COMPILE_CACHE = tempfile.mkdtemp(prefix="cdog_jax_test_cache_")
os.environ["CDOG_JAX_CACHE_DIR"] = _COMPILE_CACHE
os.environ.pop("CDOG_JAX_CACHE", None)

import jax  # noqa: E402
import pytest  # noqa: E402

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


import sys  # noqa: E402

# Test modules live in sub-folders without __init__.py; make tests/helpers.py importable.
sys.path.insert(0, os.path.dirname(__file__))


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


def pytest_sessionfinish(session, exitstatus):
    shutil.rmtree(_COMPILE_CACHE, ignore_errors=True)
