import jax.numpy as jnp
import numpy as np
import pytest
from helpers import project_np, ring_rig

from cdog_jax import Config
from cdog_jax.cdog._pipeline import stage_options
from cdog_jax.geometry import dlt_blocks
from cdog_jax.refine._outliers import IQR, iqr_outliers, percentile_linear, remove_outliers


@pytest.mark.parametrize("seed", range(5))
def test_percentile_matches_numpy(seed):
    rng = np.random.default_rng(seed)
    k = int(rng.integers(1, 10))
    vals = rng.exponential(2.0, k)
    padded = jnp.asarray(np.concatenate([vals, np.full(4, np.inf)]), jnp.float32)
    for q in (25.0, 75.0):
        got = float(percentile_linear(padded, jnp.int32(k), q))
        assert got == pytest.approx(np.percentile(vals, q), rel=1e-5)


def _iqr(config):
    """The IQR stage's own options, as the pipeline passes them."""
    return stage_options(IQR, config)


def test_iqr_fences_by_hand():
    thresholds = Config.paper().thresholds(1.0)
    score = jnp.asarray([1.0, 1.2, 0.9, 1.1, 30.0, 0.0], jnp.float32)
    member = jnp.asarray([True, True, True, True, True, False])
    out = np.asarray(iqr_outliers(score, member, thresholds, _iqr(Config.paper())))
    vals = np.array([1.0, 1.2, 0.9, 1.1, 30.0, 0.0])  # the five scores and the zero pad
    q1, q3 = np.percentile(vals, [25, 75])
    ub = q3 + 2.0 * (q3 - q1)
    assert ub < 30.0
    assert out.tolist() == [False, False, False, False, True, False]


def test_reference_guards():
    cfg = Config.reference()
    thresholds = cfg.thresholds(1.0)
    small = jnp.asarray([1.0, 1.0, 9.0], jnp.float32)  # an outlier by IQR, but all below 10 px
    assert not np.any(np.asarray(iqr_outliers(small, jnp.ones(3, bool), thresholds, _iqr(cfg))))
    flat = jnp.asarray([60.0, 61.0, 62.0, 60.5], jnp.float32)  # no IQR outlier, max > 50 px
    assert np.asarray(iqr_outliers(flat, jnp.ones(4, bool), thresholds, _iqr(cfg))).tolist() == [
        False,
        False,
        True,
        False,
    ]


def test_planted_outlier_removed_from_group():
    rig = ring_rig(6)
    X = np.array([[0.1, 0.0, -0.1]])
    xy, _ = project_np(rig, X)
    obs = xy[:, 0].copy()
    obs[3] += [25.0, -18.0]  # view 3 observed a different point
    N, r, origin = dlt_blocks(rig, jnp.asarray(obs, jnp.float32))
    member = jnp.ones((1, 6), bool)
    cfg = Config.paper()
    args = (
        rig,
        N[None],
        r[None],
        origin,
        jnp.asarray(obs, jnp.float32)[None],
        member,
        cfg.thresholds(0.5),
    )
    out, capped = remove_outliers(*args, _iqr(cfg))
    assert np.asarray(out)[0].tolist() == [True, True, True, False, True, True]
    assert not bool(capped)  # the second round changed nothing
    out, capped = remove_outliers(*args, _iqr(cfg.replace(max_iqr_iters=1)))
    assert np.asarray(out)[0].tolist() == [True, True, True, False, True, True]
    assert bool(capped)  # one round removed a member and could not check for more
