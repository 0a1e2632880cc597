import jax.numpy as jnp
import numpy as np

from cdog_jax import Config
from cdog_jax.refine import bpe_jump_keep


def test_jump_cuts_after_sudden_increase():
    th = Config.paper().thresholds(1.0)
    bpe = jnp.asarray([0.5, 0.6, 400.0, 0.7, 0.55, 0.65, 0.8, 500.0, 0.0], jnp.float32)
    valid = jnp.asarray([True] * 8 + [False])
    keep = np.asarray(bpe_jump_keep(bpe, valid, jnp.float32(1.0), th, 3))
    assert keep.tolist() == [True, True, False, True, True, True, True, False, False]


def test_no_jump_keeps_everything():
    th = Config.paper().thresholds(1.0)
    bpe = jnp.asarray([0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5], jnp.float32)
    keep = np.asarray(bpe_jump_keep(bpe, jnp.ones(7, bool), jnp.float32(1.0), th, 3))
    assert keep.all()


def test_floor_protects_small_gaps():
    # A relative jump (0.01 → 2) below the absolute floor 4 + (3σ)² is not a cut.
    th = Config.paper().thresholds(1.0)
    bpe = jnp.asarray([0.01, 0.011, 0.012, 0.013, 0.014, 2.0], jnp.float32)
    keep = np.asarray(bpe_jump_keep(bpe, jnp.ones(6, bool), jnp.float32(1.0), th, 3))
    assert keep.all()


def test_prefix_medians_match_numpy():
    from cdog_jax.refine._bpe_filter import _prefix_medians

    x = np.random.default_rng(0).exponential(1.0, 40)
    x[[3, 7]] = x[5]  # ties
    got = np.asarray(_prefix_medians(jnp.asarray(x, jnp.float32)))
    want = np.array([np.inf] + [np.median(x[:i]) for i in range(1, 40)])
    assert np.allclose(got, want, rtol=1e-6)
