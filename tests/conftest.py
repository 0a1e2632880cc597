import jax
import pytest

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


import os  # noqa: E402
import sys  # noqa: E402

# Test modules live in sub-folders without __init__.py; make tests/helpers.py importable.
sys.path.insert(0, os.path.dirname(__file__))
