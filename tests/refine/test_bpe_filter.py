import jax.numpy as jnp
import numpy as np
import pytest

from cdog_jax import Config
from cdog_jax.refine._bpe_filter import bpe_jump_keep


def test_jump_cuts_after_sudden_increase():
    thresholds = Config.paper().thresholds(1.0)
    bpe = jnp.asarray([0.5, 0.6, 400.0, 0.7, 0.55, 0.65, 0.8, 500.0, 0.0], jnp.float32)
    valid = jnp.asarray([True] * 8 + [False])
    keep = np.asarray(bpe_jump_keep(bpe, valid, jnp.float32(1.0), thresholds, 3))
    assert keep.tolist() == [True, True, False, True, True, True, True, False, False]


def test_no_jump_keeps_everything():
    thresholds = Config.paper().thresholds(1.0)
    bpe = jnp.asarray([0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5], jnp.float32)
    keep = np.asarray(bpe_jump_keep(bpe, jnp.ones(7, bool), jnp.float32(1.0), thresholds, 3))
    assert keep.all()


def test_floor_protects_small_gaps():
    # A relative jump (0.01 → 2) below the absolute floor 4 + (3σ)² is not a cut.
    thresholds = Config.paper().thresholds(1.0)
    bpe = jnp.asarray([0.01, 0.011, 0.012, 0.013, 0.014, 2.0], jnp.float32)
    keep = np.asarray(bpe_jump_keep(bpe, jnp.ones(6, bool), jnp.float32(1.0), thresholds, 3))
    assert keep.all()


@pytest.mark.parametrize("n", [0, 1, 40, 129, 150])
def test_prefix_medians_match_numpy(n):
    from cdog_jax.refine._bpe_filter import _prefix_medians

    K = 150  # more than one chunk of prefixes, not a multiple of it
    x = np.random.default_rng(0).exponential(1.0, K)
    x[[3, 7, 100]] = x[5]  # ties
    got = np.asarray(_prefix_medians(jnp.asarray(x, jnp.float32), jnp.int32(n)))
    want = np.array([np.median(x[:i]) if 0 < i < n else np.inf for i in range(K)])
    assert np.allclose(got, want, rtol=1e-6)
