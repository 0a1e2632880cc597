"""The σ estimators, ``sigma_mode="auto"`` (graph/_sigma.py) and ``"robust"``
(graph/_sigma_robust.py): finite on noise-free data, a flagged fallback when the evidence is
too thin, unmoved by clutter, and the same numbers as the NumPy oracle."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import random_scene, ring_rig, run_with_xla_defaults
from oracle import (
    _log_q as oracle_log_q,
    epipolar_distance_table,
    estimate_sigma as oracle_auto,
    estimate_sigma_robust as oracle_robust,
    focal_scale as oracle_focal,
)

from cdog_jax.geometry import epipolar_distances
from cdog_jax.graph._sigma import (
    FALLBACK_SIGMA_PX,
    SERIES_FROM,
    estimate_sigma,
    focal_scale,
    log_half_normal_tail,
)
from cdog_jax.graph._sigma_robust import GAUSS_COVERAGE, estimate_noise, estimate_sigma_robust

ESTIMATORS = {
    "auto": (estimate_sigma, oracle_auto),
    "robust": (estimate_sigma_robust, oracle_robust),
}
# The robust fit with its gate (the 95.4 % quantile of the true-pair distance) beside σ.
_JITTED = {
    "auto": jax.jit(estimate_sigma),
    "robust": jax.jit(lambda d, mask, focal: estimate_noise(d, mask, focal, GAUSS_COVERAGE)),
}

RIG = ring_rig(5)
FOCAL = 1000.0


def _table(value, M, P=1):
    """A distance table with every cross-view entry ``value`` and all slots valid."""
    d = np.full((M, P, M, P), value, np.float32)
    for m in range(M):
        d[m, :, m, :] = np.inf
    return jnp.asarray(d), jnp.ones((M, P), bool)


@pytest.fixture(params=tuple(ESTIMATORS))
def estimator(request):
    return request.param


def _estimate(d, mask, focal=FOCAL, estimator="auto", with_gate=False):
    out = _JITTED[estimator](d, mask, jnp.asarray(focal, d.dtype))
    sigma, gate, fallback = out if estimator == "robust" else (out[0], np.nan, out[1])
    if with_gate:
        return float(sigma), float(gate), bool(fallback)
    return float(sigma), bool(fallback)


def test_noise_free_one_point_is_finite_and_small(estimator):
    # One point seen by three views without noise: every distance is exactly 0 (the
    # previous estimator returned NaN here).
    sigma, fallback = _estimate(*_table(0.0, 3), estimator=estimator)
    assert np.isfinite(sigma) and sigma < 0.01 and not fallback


@pytest.mark.parametrize("distance", [0.0, 30.0])
def test_one_pair_is_too_little_evidence(distance, estimator):
    # Two views, one detection each (of different points 30 px apart, or a noise-free
    # point): one pair cannot tell the noise from an unrelated match (previously σ̂ = 21 px).
    assert _estimate(*_table(distance, 2), estimator=estimator) == (FALLBACK_SIGMA_PX, True)


def test_nothing_to_fit_falls_back(estimator):
    d, mask = _table(np.inf, 3)
    assert _estimate(d, mask & False, estimator=estimator) == (FALLBACK_SIGMA_PX, True)


@pytest.mark.parametrize("estimator, low, high", [("auto", 15.0, 25.0), ("robust", 28.0, 35.0)])
def test_implausibly_large_sigma_is_capped(estimator, low, high):
    # Many consistent pairs, every distance 30 px: σ̂ ≈ 21 px (auto: the half-normal's RMS
    # scale / √2) or 31 px (robust: the median / (√2 · 0.674)), above 1 % of a 1000 px focal
    # length: capped there and flagged, not replaced by the 1 px fallback (the data say the
    # noise is large: one joint type of real pose detections lost 8 points of recall to it).
    d, mask = _table(30.0, 4, 3)
    sigma, fallback = _estimate(d, mask, estimator=estimator)
    assert fallback and sigma == pytest.approx(10.0, rel=1e-6)
    sigma, fallback = _estimate(d, mask, focal=1e4, estimator=estimator)
    assert not fallback and low < sigma < high


def _with_clutter(xy, mask, per_view, rng):
    """The scene with ``per_view`` uniform clutter detections added in free slots."""
    xy, mask = xy.copy(), mask.copy()
    for m in range(mask.shape[0]):
        free = np.flatnonzero(~mask[m])[:per_view]
        xy[m, free] = rng.uniform([0, 0], [640, 480], (len(free), 2))
        mask[m, free] = True
    return xy, mask


def test_clutter_does_not_move_the_estimate(estimator):
    # 1–2 points at σ = 1 px, then 3 clutter detections per view (the previous estimator:
    # 12 and 15 px on two of these scenes).
    fit = ESTIMATORS[estimator][0]
    estimates = jax.jit(
        jax.vmap(lambda xy, mask: fit(epipolar_distances(RIG, xy, mask), mask, focal_scale(RIG.K)))
    )
    clean, cluttered = [], []
    for seed in range(8):
        xy, mask, _, _ = random_scene(RIG, 1 + seed % 2, 12, sigma=1.0, seed=seed)
        clean.append((xy, mask))
        cluttered.append(_with_clutter(xy, mask, 3, np.random.default_rng(seed)))
    (s0, f0), (s1, f1) = (
        estimates(
            jnp.asarray(np.stack([a for a, _ in s]), jnp.float32),
            jnp.asarray(np.stack([b for _, b in s])),
        )
        for s in (clean, cluttered)
    )
    s0, s1 = np.asarray(s0), np.asarray(s1)
    assert not np.any(f0) and not np.any(f1)
    np.testing.assert_allclose(s1, s0, rtol=0.3)
    assert 0.7 < np.median(s1) < 1.3


def _oracle_cases():
    rng = np.random.default_rng(2)
    K, R, t = (np.asarray(a, np.float64) for a in (RIG.K, RIG.R, RIG.t))
    cases = []
    for seed, (n, sigma, clutter) in enumerate(
        [(6, 1.0, 0), (2, 1.0, 3), (8, 2.0, 2), (1, 0.0, 0), (3, 0.5, 4)]
    ):
        xy, mask, _, _ = random_scene(RIG, n, 12, sigma=sigma, seed=10 + seed, clutter=clutter)
        cases.append((epipolar_distance_table(K, R, t, xy, mask), mask))
    far = rng.uniform(0, 200, (5, 12, 5, 12))  # unrelated points only
    for m in range(5):
        far[m, :, m, :] = np.inf
    cases.append((far, np.ones((5, 12), bool)))
    return cases, oracle_focal(K)


def test_matches_oracle(estimator):
    cases, focal = _oracle_cases()
    with jax.enable_x64(True):
        for d, mask in cases:
            if estimator == "robust":  # σ, the gate and the fallback
                got = _estimate(
                    jnp.asarray(d, jnp.float64), jnp.asarray(mask), focal, estimator, with_gate=True
                )
                want = oracle_robust(d, mask, focal, with_gate=True)
                assert got[1] == pytest.approx(want[1], rel=1e-6, nan_ok=True)
                got, want = (got[0], got[2]), (want[0], want[2])
            else:
                got = _estimate(jnp.asarray(d, jnp.float64), jnp.asarray(mask), focal, estimator)
                want = oracle_auto(d, mask, focal)
            assert got[1] == want[1]
            assert got[0] == pytest.approx(want[0], rel=1e-6)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_log_half_normal_tail_matches_oracle(dtype):
    """log Q(a) on both sides of the switch to the series, far into the tail and at the
    edges (0, where float32's a² overflows, ∞), against the oracle's float64 erfc."""
    a = np.concatenate(
        [
            np.linspace(0.0, 40.0, 4001),
            *(s + np.array([-1e-3, 0.0, 1e-3]) for s in SERIES_FROM.values()),
            [1e3, 1e6],
        ]
    )
    with jax.enable_x64(dtype == np.float64):
        got = np.asarray(jax.jit(log_half_normal_tail)(jnp.asarray(a, dtype)), np.float64)
        edge = np.asarray(log_half_normal_tail(jnp.asarray([0.0, 1e20, np.inf], dtype)))
    want = oracle_log_q(a.astype(dtype))
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got, want, rtol=2e-6 if dtype == np.float32 else 1e-12)
    assert edge[0] == pytest.approx(np.log(0.5)) and edge[2] == -np.inf
    assert edge[1] < 0 and not np.isnan(edge[1])


def test_most_likely_takes_the_first_of_near_ties_and_never_nan():
    from cdog_jax.graph._sigma import most_likely

    lik = jnp.asarray([-100.0, -99.1, np.nan, -99.0])
    assert int(most_likely(lik)) == 3
    # Within 1e-5 (1 + |top|) = 1e-3 of the top: a tie, the first of them wins.
    assert int(most_likely(lik.at[1].set(-99.0005))) == 1
    assert int(most_likely(jnp.asarray([np.nan, -5.0]))) == 1


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_sorted_at_reads_the_sorted_values_without_a_sort(dtype):
    """The EM's start quantiles, bisected on the values' bits, are ``np.sort``'s entries at
    those ranks: ties, zeros (``-0`` as ``+0``), ``+inf`` (unused samples), NaN; the first,
    the last and every rank between."""
    from cdog_jax.graph._sigma import sorted_at

    with jax.enable_x64(dtype == np.float64):
        _check_sorted_at(jax.jit(sorted_at), dtype)


def _check_sorted_at(at, dtype):
    rng = np.random.default_rng(0)
    for case in range(12):
        S = int(rng.integers(1, 200))
        v = rng.exponential(rng.uniform(0.1, 100.0), S).astype(dtype)
        v[rng.random(S) < 0.2] = np.inf
        v[rng.random(S) < 0.1] = 0.0
        v[rng.random(S) < 0.05] = -0.0
        if case % 3 == 0:
            v = np.round(v)  # many ties
        if case % 4 == 1:
            v[rng.random(S) < 0.1] = np.nan
        ranks = np.unique(np.r_[0, S - 1, rng.integers(0, S, 6)]).astype(np.int32)
        want = np.sort(np.where(v == 0, 0.0, v).astype(dtype))[ranks]
        got = np.asarray(at(v, ranks))
        assert got.dtype == dtype
        np.testing.assert_array_equal(got.view(f"u{v.itemsize}"), want.view(f"u{v.itemsize}"))


def sigma_is_bitwise_the_same_at_every_table_width():
    """The pooled fit (``associate_classes``' σ per frame) on tables of every width the
    library picks for one frame's samples: what a live frame gets (its narrowest table) is
    what the offline call gets (the fullest frame's table, among the other frames' rows).
    With the shape ladder's widths (1,024 and 1,536 here) σ at 1,536 differed in its
    last bits (its sums were 1,536 long), and a row fitted alone differed from the same row
    among others; a table whose sums are padded to a power of two (1,536 entries here) is
    that power of two's."""
    from cdog_jax.people import _classes as classes

    rng = np.random.default_rng(0)
    n = 900  # samples of a Shelf-like frame: some true pairs, the rest farther off
    x = np.where(
        rng.random(n) < 0.6, np.abs(rng.normal(0.0, 2.8, n)), rng.exponential(40.0, n)
    ).astype(np.float32)
    count = rng.integers(2, 6, n).astype(np.float32)
    values = [x, np.full(n, 0.5, np.float32), count]
    samples = classes._UsedSamples(values, np.array([n]), np.array([count.max()]))
    sigmas, widths = set(), set()
    for least in (0, 1100, 1600):
        tables = classes._sample_tables(samples, np.zeros(1, np.int64), 1, least)
        widths.add(tables[0].shape[1])
        sigma, _ = classes._chunked_fit(classes._pooled_fit, tables, np.float32(FOCAL))
        sigmas.add(sigma.tobytes())
        # The same row among others (3 rows; 70 rows: chunks of 64 at 1,024 entries).
        for rows in (3, 70) if least == 0 else (3,):
            others = [
                np.concatenate([np.roll(t, k + 1, axis=1) for k in range(rows - 1)]) for t in tables
            ]
            stacked = [
                np.concatenate([o[: rows // 2], t, o[rows // 2 :]]) for t, o in zip(tables, others)
            ]
            sigma, _ = classes._chunked_fit(classes._pooled_fit, stacked, np.float32(FOCAL))
            sigmas.add(sigma[rows // 2 : rows // 2 + 1].tobytes())
    assert widths == {1024, 1536, 2048} and len(sigmas) == 1


def test_sigma_is_bitwise_the_same_at_every_table_width():
    """Under XLA's defaults (the code users run): the suite's switches compile sums that do
    not depend on the width either way."""
    run_with_xla_defaults(__file__, "sigma_is_bitwise_the_same_at_every_table_width")
